"""ASCII PLY bodies: one row per line, decoded a block of rows at a time."""

from __future__ import annotations

import numpy as np

from ..errors import FormatError
from . import text_blocks
from .faces import ragged_take
from .ply_header import Element, ElementData, Header
from .text_blocks import line_blocks
from .tokens import block_numbers


def read_ascii_elements(data: bytes, header: Header, source, wanted: set[str]
                        ) -> dict[str, ElementData]:
    """Decode the elements named in ``wanted``; others are skipped by line count.

    The body is walked a block of lines at a time (:mod:`curvature.io.text_blocks`), so the
    scratch memory is bounded by the block size; skipped elements cost a newline count.

    Raises
    ------
    FormatError
        Truncated body, wrong number of values in a row, non-numeric value, bad list length;
        each names the line.
    """
    start = header.body_offset
    total = data.count(b"\n", start)
    tail = data.rfind(b"\n", start) + 1 if total else start
    if data[tail:].strip():  # a last line without a newline
        total += 1
    first_body_line = header.n_lines + 1
    pos, at = 0, start  # rows (lines) and bytes consumed
    out = {}
    for element in header.elements:
        if pos + element.count > total:
            raise FormatError(
                source, f"header says {element.count} {element.name} rows, but the file ends "
                        f"after {total - pos} of them", line=first_body_line + total)
        if element.name in wanted:
            out[element.name], at = _read_element(data, at, element, source,
                                                  first_body_line + pos)
        else:
            at = _skip_lines(data, at, element.count)
        pos += element.count
    return out


def _skip_lines(data: bytes, at: int, count: int) -> int:
    """Offset just after the ``count``-th newline from ``at`` (or the end)."""
    while count > 0:
        hi = min(at + text_blocks.BLOCK_BYTES, len(data))
        found = data.count(b"\n", at, hi)
        if found < count and hi < len(data):
            at, count = hi, count - found
            continue
        if found < count:
            return len(data)
        ends = np.flatnonzero(np.frombuffer(data, dtype=np.uint8, count=hi - at,
                                            offset=at) == 10)
        return at + int(ends[count - 1]) + 1
    return at


def _read_element(data: bytes, at: int, element: Element, source, first_line: int
                  ) -> tuple[ElementData, int]:
    """The ``element.count`` rows from offset ``at``, a block at a time, and the offset
    after them."""
    scalars = {p.name: np.empty(element.count, dtype=p.dtype) for p in element.properties
               if not p.is_list}  # filled block by block: no second copy
    lists: dict[str, tuple[list, list]] = {p.name: ([], []) for p in element.properties
                                            if p.is_list}
    done = 0
    for lo, hi, line in line_blocks(data, at, first_line=first_line, source=source):
        if done == element.count:
            break
        block = data[lo:hi]
        ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10)
        if hi == len(data) and block[ends[-1] + 1 if ends.size else 0:].strip():
            ends = np.append(ends, len(block))
        ends = ends[:element.count - done]
        lens, flat = block_numbers(block[:int(ends[-1])] if ends.size else b"", ends, source,
                                   line)
        part = _decode(element, lens, flat, source, line, done)
        for name, values in part.scalars.items():
            scalars[name][done:done + ends.size] = values
        for name, (counts, items) in part.lists.items():
            lists[name][0].append(counts)
            lists[name][1].append(items)
        done += ends.size
        at = lo + (int(ends[-1]) + 1 if ends.size else 0)
    empty = _decode(element, np.zeros(0, np.int64), np.zeros(0), source, first_line)
    joined = {name: (_join(c) if c else empty.lists[name][0],
                     _join(i) if i else empty.lists[name][1])
              for name, (c, i) in lists.items()}

    def where(row: int) -> dict:
        return {"line": first_line + int(row)}

    return ElementData(scalars, joined, where), min(at, len(data))


def _join(arrays: list[np.ndarray]) -> np.ndarray:
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)


def _decode(element: Element, lens: np.ndarray, flat: np.ndarray, source, first_line: int,
            first_row: int = 0) -> ElementData:
    """Split the values of rows of one element into properties, checking every row's
    length (``first_row``: the element's row number of the first, for messages)."""
    props = element.properties

    def line_of(row: int) -> int:
        return first_line + int(row)

    def where(row: int) -> dict:
        return {"line": line_of(row)}

    def fail(row, message):
        raise FormatError(source, f"{element.name} row {first_row + int(row)}: {message}",
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
