"""Fast whitespace/delimiter tokenising of text bodies, with line-precise errors."""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Callable, Sequence

import numpy as np
import orjson

from ..errors import FormatError


def split_rows(lines: Sequence[str], sep: str | None = None
               ) -> tuple[list[list[str]], np.ndarray]:
    """Split every line into tokens.

    Returns
    -------
    rows : list of list of str
    lens : ndarray, shape (len(lines),), int64
        Tokens per line.
    """
    rows = [line.split(sep) for line in lines]
    lens = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
    return rows, lens


def numbers(rows: list[list[str]], source, line_of: Callable[[int], int]) -> np.ndarray:
    """All tokens of ``rows`` as one flat float64 array.

    Raises
    ------
    FormatError
        A token is not a number; names the token and its line (found only on this slow path).
    """
    flat = list(itertools.chain.from_iterable(rows))
    try:
        return np.array(flat, dtype=np.float64)
    except ValueError:
        pass
    for r, row in enumerate(rows):
        for tok in row:
            try:
                np.array([tok], dtype=np.float64)
            except ValueError:
                shown = tok if len(tok) <= 40 else tok[:37] + "..."
                raise FormatError(source, f"{shown!r} is not a number",
                                  line=line_of(r)) from None
    raise FormatError(source, "a value is not a number")  # pragma: no cover - defensive


def json_numbers(values: np.ndarray) -> bytes:
    """The elements of ``values`` (rows for (m, k) arrays) as JSON, without the brackets.

    orjson writes the shortest text that reads back to the same value (float32 as float32)
    and NaN/Inf as ``null``, at a few hundred MB/s instead of the tens of Python's per-number
    formatting.
    """
    if not values.dtype.isnative:  # big-endian input attributes; orjson takes native order only
        values = values.astype(values.dtype.newbyteorder("="))
    return orjson.dumps(np.ascontiguousarray(values), option=orjson.OPT_SERIALIZE_NUMPY)[1:-1]


def number_texts(values: np.ndarray) -> list[str]:
    """Shortest text per element that reads back to the same value.

    float64 and float32 get the shortest text that reads back to the same float64 or float32
    (written by orjson from the array, several times faster than Python's per-number
    ``repr``), integers and booleans print as integers. NaN and Inf come out as ``nan``,
    ``inf`` and ``-inf``.

    Parameters
    ----------
    values : ndarray, shape (n,)

    Returns
    -------
    list of str, length n
    """
    values = np.asarray(values)
    if values.dtype.kind == "b":
        values = values.astype(np.uint8)
    if values.size == 0:
        return []
    if values.dtype.kind not in "iuf" or values.dtype.itemsize < 4 and values.dtype.kind == "f":
        values = values.astype(np.float32)  # float16: read back through float32 exactly
    texts = json_numbers(values).decode("ascii").split(",")
    if values.dtype.kind == "f":
        bad = np.flatnonzero(~np.isfinite(values))  # orjson writes them as null
        for i, v in zip(bad.tolist(), values[bad].tolist(), strict=True):
            texts[i] = "nan" if v != v else ("inf" if v > 0 else "-inf")
    return texts


def block_numbers(block: bytes, line_ends: np.ndarray, source, first_line: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Token counts per line and all values of a whitespace-separated numeric block.

    Vectorized: token starts are found on the raw bytes with numpy and the numbers are
    parsed by numpy's C text parser in one call; only when that parser stops early (a
    non-numeric token) is the block split in Python, to name the offending line.

    Parameters
    ----------
    block : bytes
        The lines, ``\\n``-separated.
    line_ends : ndarray, shape (m,), int64
        Byte index in ``block`` of the end (the newline or ``len(block)``) of each line.
    first_line : int
        1-based file line number of the first line, for messages.

    Returns
    -------
    lens : ndarray, shape (m,), int64
    values : ndarray, shape (lens.sum(),), float64
    """
    raw = np.frombuffer(block, dtype=np.uint8)
    space = raw <= 32  # blanks, tabs, CR, LF (control bytes fail the parse below anyway)
    starts = ~space
    starts[1:] &= space[:-1]
    token_line = np.searchsorted(line_ends, np.flatnonzero(starts))
    lens = np.bincount(token_line, minlength=line_ends.size).astype(np.int64)
    if lens.size > line_ends.size:  # tokens after the last line end: not ours
        lens = lens[:line_ends.size]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            values = np.fromstring(block, dtype=np.float64, sep=" ")
        if values.size == int(lens.sum()):
            return lens, values
    except (ValueError, DeprecationWarning):
        pass
    rows, lens = split_rows(block.decode("latin-1").split("\n")[:line_ends.size])
    return lens, numbers(rows, source, lambda r: first_line + int(r))
