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
from .tokens import decode_text, number_texts, numbers, split_rows

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
    """Decode an xyz/csv/txt/asc point list.

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
    text = decode_text(data, source)
    lines = text.splitlines()
    numbered = [(i, ln) for i, ln in enumerate(lines, start=1)
                if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise FormatError(source, "the file holds no points")
    names = None
    first = numbered[0][1]
    head_sep = _separator(first)
    first_tokens = (first.replace(",", ".") if head_sep == ";" else first).split(head_sep)
    if _is_header(first_tokens):
        names = [t.strip().strip('"').strip("'").lower() for t in first.split(head_sep)]
        header_line = numbered[0][0]
        numbered = numbered[1:]
        if not numbered:
            raise FormatError(source, "the file holds a header line but no points")
    sep = _separator(numbered[0][1])
    if sep == ";":  # semicolon files (spreadsheet exports) may use decimal commas
        numbered = [(i, ln.replace(",", ".")) for i, ln in numbered]
    body = [ln for _, ln in numbered]

    def line_of(r):
        return numbered[int(r)][0]

    rows, lens = split_rows(body, sep)
    width = int(lens[0])
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
                                  "(x y z nx ny nz)", line=line_of(0))
    bad = np.flatnonzero(lens != width)
    if bad.size:
        r = bad[0]
        raise FormatError(source, f"{lens[r]} columns, expected {width} like the first row",
                          line=line_of(r))
    table = numbers(rows, source, line_of).reshape(len(rows), width)
    if names is None:
        names = ["x", "y", "z", "nx", "ny", "nz"][:width]
    index = {n: i for i, n in enumerate(names)}
    points = table[:, [index[a] for a in "xyz"]]
    normals = None
    if all(n in index for n in ("nx", "ny", "nz")):
        normals = table[:, [index[n] for n in ("nx", "ny", "nz")]]
    used = {"x", "y", "z"} | ({"nx", "ny", "nz"} if normals is not None else set())
    properties = {n: table[:, i].copy() for n, i in index.items() if n not in used}
    return finish_cloud(source, points, normals=normals, properties=properties,
                        where=lambda r: {"line": line_of(r)})


def write_csv(fh: BinaryIO, table: Table) -> None:
    """Write one header line of column names, then one comma-separated row per point.

    NaN is written as ``nan``; numbers use the shortest text that reads back exactly.
    """
    columns = table.columns()
    fh.write((",".join(name for name, _ in columns) + "\n").encode("ascii"))
    for lo in range(0, table.n, _CHUNK_ROWS):
        texts = [number_texts(np.asarray(arr[lo:lo + _CHUNK_ROWS])) for _, arr in columns]
        fh.write(("\n".join(map(",".join, zip(*texts, strict=True))) + "\n").encode("ascii"))
