"""Binary PLY bodies, decoded with numpy structured dtypes (no per-row Python loop).

Elements without list properties, and list elements whose lists all have the same length
(triangle meshes), are read by one ``np.frombuffer``. Lists of varying length need a
sequential walk to find where each row starts; that walk is a small numba kernel, and the
values are then gathered with vectorized indexing.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import FormatError
from .faces import ragged_take
from .ply_header import Element, ElementData, Header

_TRUNCATED, _NEGATIVE = 1, 2


def read_binary_elements(data: bytes, header: Header, source, wanted: set[str]
                         ) -> dict[str, ElementData]:
    """Decode the elements named in ``wanted``; others are only walked over.

    Raises
    ------
    FormatError
        Truncated body or negative list length, naming the byte offset.
    """
    buf = np.frombuffer(data, dtype=np.uint8)
    order = header.byte_order
    offset = header.body_offset
    out = {}
    for element in header.elements:
        decoded, offset = _element(buf, offset, element, order, source,
                                   element.name in wanted)
        if decoded is not None:
            out[element.name] = decoded
    return out


def _truncated(source, element: Element, row: int, offset: int, size: int):
    return FormatError(source, f"the file ends inside {element.name} row {row} of "
                               f"{element.count} (file size {size} bytes): truncated body "
                               "or wrong header count", offset=offset)


def _element(buf, start, element, order, source, keep):
    props = element.properties
    count = element.count
    if count == 0 or not props:
        return (ElementData({}, {}, lambda r: {"offset": start}) if keep else None), start
    size = buf.size
    if not any(p.is_list for p in props):
        dt = np.dtype([(f"p{i}", p.dtype.newbyteorder(order)) for i, p in enumerate(props)])
        end = start + count * dt.itemsize
        if end > size:
            row = (size - start) // dt.itemsize
            raise _truncated(source, element, row, start + row * dt.itemsize, size)
        if not keep:
            return None, end
        rec = np.frombuffer(buf, dtype=dt, count=count, offset=start)
        scalars = {p.name: rec[f"p{i}"].astype(p.dtype) for i, p in enumerate(props)}
        return ElementData(scalars, {}, _fixed_rows(start, dt.itemsize)), end

    fixed = _constant_lists(buf, start, element, order)
    if fixed is not None:
        rec, dt = fixed
        end = start + count * dt.itemsize
        if not keep:
            return None, end
        scalars, lists = {}, {}
        for i, p in enumerate(props):
            if p.is_list:
                items = rec[f"p{i}"].astype(p.dtype).reshape(-1)
                counts = np.full(count, rec.dtype[f"p{i}"].shape[0], dtype=np.int64)
                lists[p.name] = (counts, items)
            else:
                scalars[p.name] = rec[f"p{i}"].astype(p.dtype)
        return ElementData(scalars, lists, _fixed_rows(start, dt.itemsize)), end

    kinds = np.array([1 if p.is_list else 0 for p in props], dtype=np.int64)
    item_sizes = np.array([p.dtype.itemsize for p in props], dtype=np.int64)
    count_sizes = np.array([p.count_dtype.itemsize if p.is_list else 0 for p in props],
                           dtype=np.int64)
    signed = np.array([p.is_list and p.count_dtype.kind == "i" for p in props])
    offs, counts, end, bad_row, err = _walk_rows(buf, start, count, kinds, item_sizes,
                                                 count_sizes, signed, order == ">")
    if err == _TRUNCATED:
        raise _truncated(source, element, int(bad_row), int(offs[bad_row, 0]), size)
    if err == _NEGATIVE:
        raise FormatError(source, f"{element.name} row {int(bad_row)} has a negative list "
                                  "length", offset=int(offs[bad_row, 0]))
    if not keep:
        return None, int(end)
    scalars, lists = {}, {}
    for i, p in enumerate(props):
        dt = p.dtype.newbyteorder(order)
        if p.is_list:
            c = counts[:, i]
            item_starts = ragged_take(offs[:, i] + count_sizes[i], c, dt.itemsize)
            raw = _gather(buf, item_starts, dt.itemsize)
            lists[p.name] = (c, raw.view(dt).astype(p.dtype))
        else:
            raw = _gather(buf, offs[:, i], dt.itemsize)
            scalars[p.name] = raw.view(dt).astype(p.dtype)
    row_starts = offs[:, 0].copy()
    return ElementData(scalars, lists, lambda r: {"offset": int(row_starts[r])}), int(end)


def _fixed_rows(start: int, row_size: int):
    return lambda r: {"offset": start + int(r) * row_size}


def _gather(buf: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """Bytes ``buf[s : s + width]`` for every start, as one contiguous uint8 array."""
    idx = starts[:, None] + np.arange(width, dtype=np.int64)
    return np.ascontiguousarray(buf[idx]).reshape(-1)


def _constant_lists(buf, start, element, order):
    """Try reading a list element as fixed-size rows; None when list lengths vary.

    The lengths of the first row are assumed for every row; checking every row's length
    fields against that assumption proves it row by row (each row then starts where the
    fixed layout says), so a pass means the structured read is exact.
    """
    fields = []
    pos = start
    for i, p in enumerate(element.properties):
        if p.is_list:
            cdt = p.count_dtype.newbyteorder(order)
            if pos + cdt.itemsize > buf.size:
                return None
            k = int(np.frombuffer(buf, dtype=cdt, count=1, offset=pos)[0])
            if k < 0:
                return None
            fields.append((f"c{i}", cdt))
            fields.append((f"p{i}", p.dtype.newbyteorder(order), (k,)))
            pos += cdt.itemsize + k * p.dtype.itemsize
        else:
            fields.append((f"p{i}", p.dtype.newbyteorder(order)))
            pos += p.dtype.itemsize
    dt = np.dtype(fields)
    if start + element.count * dt.itemsize > buf.size:
        return None
    rec = np.frombuffer(buf, dtype=dt, count=element.count, offset=start)
    for i, p in enumerate(element.properties):
        if p.is_list and not np.all(rec[f"c{i}"] == dt[f"p{i}"].shape[0]):
            return None
    return rec, dt


@njit(cache=True)
def _walk_rows(buf, start, count, kinds, item_sizes, count_sizes, signed, big_endian):
    """Start offset of every property of every row, and every list length.

    Returns ``(offsets (count, nprop), lengths (count, nprop), end, bad_row, error)`` with
    error 0 (ok), 1 (file ends inside row ``bad_row``) or 2 (negative list length).
    """
    nprop = kinds.size
    offs = np.zeros((count, nprop), dtype=np.int64)
    lens = np.zeros((count, nprop), dtype=np.int64)
    size = buf.size
    pos = start
    for r in range(count):
        for p in range(nprop):
            offs[r, p] = pos
            if kinds[p] == 0:
                pos += item_sizes[p]
            else:
                cs = count_sizes[p]
                if pos + cs > size:
                    return offs, lens, pos, r, 1
                value = np.int64(0)
                for b in range(cs):
                    j = b if big_endian else cs - 1 - b
                    value = (value << 8) | np.int64(buf[pos + j])
                if signed[p] and value >= (np.int64(1) << (8 * cs - 1)):
                    value -= np.int64(1) << (8 * cs)
                if value < 0:
                    return offs, lens, pos, r, 2
                lens[r, p] = value
                pos += cs + value * item_sizes[p]
            if pos > size:
                return offs, lens, pos, r, 1
    return offs, lens, pos, -1, 0
