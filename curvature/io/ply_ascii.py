"""ASCII PLY bodies: one row per line, decoded a whole element at a time."""

from __future__ import annotations

import numpy as np

from ..errors import FormatError
from .faces import ragged_take
from .ply_header import Element, ElementData, Header
from .tokens import block_numbers


def read_ascii_elements(data: bytes, header: Header, source, wanted: set[str]
                        ) -> dict[str, ElementData]:
    """Decode the elements named in ``wanted``; others are skipped by line count.

    Line boundaries are located once with numpy, so skipped elements cost nothing and each
    wanted element is parsed as one block.

    Raises
    ------
    FormatError
        Truncated body, wrong number of values in a row, non-numeric value, bad list length;
        each names the line.
    """
    body = data[header.body_offset:]
    ends = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    tail = ends[-1] + 1 if ends.size else 0
    if body[tail:].strip():  # a last line without a newline
        ends = np.append(ends, len(body))
    first_body_line = header.n_lines + 1
    pos = 0
    out = {}
    for element in header.elements:
        if pos + element.count > ends.size:
            raise FormatError(
                source, f"header says {element.count} {element.name} rows, but the file ends "
                        f"after {ends.size - pos} of them", line=first_body_line + ends.size)
        if element.name in wanted:
            lo = 0 if pos == 0 else int(ends[pos - 1]) + 1
            line_ends = ends[pos:pos + element.count] - lo
            hi = lo + (int(line_ends[-1]) if element.count else 0)
            lens, flat = block_numbers(body[lo:hi], line_ends, source, first_body_line + pos)
            out[element.name] = _decode(element, lens, flat, source, first_body_line + pos)
        pos += element.count
    return out


def _decode(element: Element, lens: np.ndarray, flat: np.ndarray, source, first_line: int
            ) -> ElementData:
    """Split the values of one element into properties, checking every row's length."""
    props = element.properties

    def line_of(row: int) -> int:
        return first_line + int(row)

    def where(row: int) -> dict:
        return {"line": line_of(row)}

    def fail(row, message):
        raise FormatError(source, f"{element.name} row {int(row)}: {message}",
                          line=line_of(row))

    names = " ".join(p.name for p in props)
    if not any(p.is_list for p in props):
        bad = np.flatnonzero(lens != len(props))
        if bad.size:
            r = bad[0]
            fail(r, f"{lens[r]} values, expected {len(props)} ({names})")
        table = flat.reshape(lens.size, len(props))
        with np.errstate(all="ignore"):
            scalars = {p.name: _cast(table[:, i], p.dtype) for i, p in enumerate(props)}
        return ElementData(scalars, {}, where)

    # Rows of varying length: walk all rows at once with a per-row cursor.
    starts = np.cumsum(lens) - lens
    cursor = np.zeros(lens.size, dtype=np.int64)
    scalars, lists = {}, {}
    for p in props:
        short = np.flatnonzero(cursor >= lens)
        if short.size:
            fail(short[0], f"too few values: {p.name!r} is missing (expected {names})")
        values = flat[starts + cursor]
        cursor += 1
        if not p.is_list:
            with np.errstate(all="ignore"):
                scalars[p.name] = _cast(values, p.dtype)
            continue
        bad = np.flatnonzero((values < 0) | (values != np.floor(values)))
        if bad.size:
            fail(bad[0], f"list length {float(values[bad[0]]):g} of {p.name!r} is not a "
                         "non-negative integer")
        counts = values.astype(np.int64)
        over = np.flatnonzero(cursor + counts > lens)
        if over.size:
            r = over[0]
            fail(r, f"list {p.name!r} says {counts[r]} items but only "
                    f"{lens[r] - cursor[r]} values follow")
        items = flat[ragged_take(starts + cursor, counts)]
        if p.dtype.kind in "iu":
            frac = np.flatnonzero(items != np.floor(items))
            if frac.size:
                row = int(np.searchsorted(np.cumsum(counts), frac[0], side="right"))
                fail(row, f"{p.name!r} holds {float(items[frac[0]]):g}, expected integers")
        with np.errstate(all="ignore"):
            lists[p.name] = (counts, _cast(items, p.dtype))
        cursor += counts
    extra = np.flatnonzero(cursor != lens)
    if extra.size:
        r = extra[0]
        fail(r, f"{lens[r]} values, but its properties ({names}) take {cursor[r]}")
    return ElementData(scalars, lists, where)


def _cast(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    # Keep the declared type so an ascii file and its binary twin give identical values.
    if dtype.kind == "f":
        return values if dtype.itemsize == 8 else values.astype(dtype)
    return values.astype(dtype)
