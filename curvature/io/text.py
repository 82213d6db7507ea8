"""Delimited text point lists (xyz, csv, txt, asc): read, and write CSV.

Each data line holds ``x y z`` or ``x y z nx ny nz``, separated by commas, semicolons or
whitespace (detected from the first data line). Blank lines and lines starting with ``#``
are ignored. A single header line of column names may come first; with a header naming
``x y z`` any number of columns is accepted (``nx ny nz`` become normals, other columns
properties), so a CSV written by :func:`write_csv` reads back.
"""

from __future__ import annotations

import re
from typing import BinaryIO

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud
from .columns import Table
from .text_blocks import RowScanner, blank_comments, rows_values, separator_table, tokenize
from .tokens import number_texts

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(nan|inf|infinity)",
                     re.IGNORECASE)
_CHUNK_ROWS = 65536


def _separator(line: str) -> str | None:
    if ";" in line:
        return ";"
    if "," in line:
        return ","
    return None


def _is_header(tokens: list[str]) -> bool:
    return not any(_NUMBER.fullmatch(t.strip()) for t in tokens)


def read_text(data: bytes, source=None) -> PointCloud:
    """Decode an xyz/csv/txt/asc point list, a block of lines at a time.

    Returns
    -------
    PointCloud
        ``points`` (n, 3) float64 and, with 6 columns, ``normals`` (n, 3).

    Raises
    ------
    FormatError
        Wrong column count, non-numeric value, NaN/Inf coordinate (naming the line), empty
        file or fewer than 10 points.
    """
    start = 3 if data.startswith(b"\xef\xbb\xbf") else 0
    comments = lambda buf: blank_comments(buf, anywhere=False)  # noqa: E731
    first = _first_row(data, start, 1, source, comments)
    if first is None:
        raise FormatError(source, "the file holds no points")
    lo, line_no, text = first
    names = None
    head_sep = _separator(text)
    first_tokens = (text.replace(",", ".") if head_sep == ";" else text).split(head_sep)
    if _is_header(first_tokens):
        names = [t.strip().strip('"').strip("'").lower() for t in text.split(head_sep)]
        header_line = line_no
        nl = data.find(b"\n", lo)
        first = _first_row(data, nl + 1 if nl >= 0 else len(data), line_no + 1, source,
                           comments)
        if first is None:
            raise FormatError(source, "the file holds a header line but no points")
        lo, line_no, text = first
    sep = _separator(text)
    translate = separator_table(sep)

    def prepare(buf: bytes) -> bytes:
        return comments(translate(buf) if translate is not None else buf)

    width = int(tokenize(prepare(text.encode("utf-8"))).lens.sum())
    if names is not None:
        if len(names) != width:
            raise FormatError(source, f"the header names {len(names)} columns but the first "
                                      f"row has {width}", line=header_line)
        if not all(a in names for a in "xyz"):
            if width not in (3, 6):
                raise FormatError(source, "the header does not name x, y and z, and there "
                                          f"are {width} columns (expected 3 or 6)",
                                  line=header_line)
            names = None
    elif width not in (3, 6):
        raise FormatError(source, f"{width} columns, expected 3 (x y z) or 6 "
                                  "(x y z nx ny nz)", line=line_no)
    scanner = RowScanner(data, lo, line_no, source, prepare)
    n = 0
    for block in scanner.blocks():  # pass 1: every row's width, and how many rows
        lens = block.tokens.lens[block.rows]
        bad = np.flatnonzero(lens != width)
        if bad.size:
            raise FormatError(source, f"{lens[bad[0]]} columns, expected {width} like the "
                                      "first row", line=block.first_line + int(block.rows[bad[0]]))
        n += block.rows.size
    table = np.empty((n, width), dtype=np.float64)
    at = 0
    for block in scanner.blocks():  # pass 2: the numbers, straight into the table
        rows = block.rows.size
        table[at:at + rows] = rows_values(block, source).reshape(rows, width)
        at += rows
    if names is None:
        names = ["x", "y", "z", "nx", "ny", "nz"][:width]
    index = {n: i for i, n in enumerate(names)}
    xyz = [index[a] for a in "xyz"]
    points = table if xyz == [0, 1, 2] and width == 3 else table[:, xyz]
    normals = None
    if all(n in index for n in ("nx", "ny", "nz")):
        normals = table[:, [index[n] for n in ("nx", "ny", "nz")]]
    used = {"x", "y", "z"} | ({"nx", "ny", "nz"} if normals is not None else set())
    properties = {n: table[:, i].copy() for n, i in index.items() if n not in used}
    return finish_cloud(source, points, normals=normals, properties=properties,
                        where=lambda r: {"line": scanner.line_of_row(int(r))})


def _first_row(data: bytes, start: int, first_line: int, source, prepare
               ) -> tuple[int, int, str] | None:
    """Offset, line number and text of the first line at or after ``start`` that is not
    blank or a comment; None when there is none."""
    for block in RowScanner(data, start, first_line, source, prepare).blocks(max_rows=1):
        row = int(block.rows[0])
        line_lo = int(block.tokens.line_ends[row - 1]) + 1 if row else 0
        line_hi = int(block.tokens.line_ends[row])
        text = data[block.offset + line_lo:block.offset + line_hi].decode("utf-8")
        return block.offset + line_lo, block.first_line + row, text.rstrip("\r")
    return None


def write_csv(fh: BinaryIO, table: Table) -> None:
    """Write one header line of column names, then one comma-separated row per point.

    NaN is written as ``nan``; numbers use the shortest text that reads back exactly.
    """
    columns = table.columns()
    fh.write((",".join(name for name, _ in columns) + "\n").encode("ascii"))
    for lo in range(0, table.n, _CHUNK_ROWS):
        texts = [number_texts(np.asarray(arr[lo:lo + _CHUNK_ROWS])) for _, arr in columns]
        fh.write(("\n".join(map(",".join, zip(*texts, strict=True))) + "\n").encode("ascii"))
