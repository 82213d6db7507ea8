"""PLY header: elements, properties and their types; size checks before any allocation."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import FormatError

PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
# Headers are short; looking further for end_header only wastes time on non-PLY data.
MAX_HEADER_BYTES = 16 << 20
_COUNT = re.compile(r"[0-9]+")
_END_HEADER = re.compile(rb"(?:^|\n)end_header[ \t]*(\r?\n|\r|$)")


@dataclass
class Property:
    """One property of an element; ``count_dtype`` is set for list properties."""

    name: str
    dtype: np.dtype
    count_dtype: np.dtype | None = None

    @property
    def is_list(self) -> bool:
        return self.count_dtype is not None


@dataclass
class Element:
    """An element declaration (``element vertex 100`` and its properties)."""

    name: str
    count: int
    line: int
    properties: list[Property] = field(default_factory=list)

    def prop(self, name: str) -> Property | None:
        return next((p for p in self.properties if p.name == name), None)

    def min_binary_row(self) -> int:
        """Smallest possible row size in bytes (every list empty)."""
        return sum(p.count_dtype.itemsize if p.is_list else p.dtype.itemsize
                   for p in self.properties)


@dataclass
class Header:
    """A parsed PLY header; ``body_offset`` is the first byte after ``end_header``."""

    format: str
    elements: list[Element]
    body_offset: int
    n_lines: int
    comments: list[str]

    @property
    def byte_order(self) -> str:
        return ">" if self.format == "binary_big_endian" else "<"

    def element(self, name: str) -> Element | None:
        return next((e for e in self.elements if e.name == name), None)


def _type(source, token: str, line: int) -> np.dtype:
    code = PLY_TYPES.get(token)
    if code is None:
        raise FormatError(source, f"unknown PLY type {token!r}; expected one of "
                                  f"{', '.join(PLY_TYPES)}", line=line)
    return np.dtype(code)


def parse_header(data: bytes, source) -> Header:
    """Parse and check the header of a PLY file.

    Raises
    ------
    FormatError
        Not a PLY file, no ``end_header``, unknown keyword/type/format, bad element count,
        duplicate property, no ``vertex`` element with scalar ``x y z``, or header counts
        that cannot fit in the bytes that follow the header.
    """
    if not data.startswith(b"ply"):
        raise FormatError(source, "not a PLY file: it must start with the line 'ply'", line=1)
    match = _END_HEADER.search(data, 0, MAX_HEADER_BYTES)
    if match is None:
        raise FormatError(source, "garbled PLY header: no 'end_header' line")
    body_offset = match.end()
    lines = data[:match.start()].decode("latin-1").split("\n")
    lines = [ln.rstrip("\r") for ln in lines]
    if lines[0].strip() != "ply":
        raise FormatError(source, "not a PLY file: the first line must be 'ply'", line=1)
    fmt = None
    elements: list[Element] = []
    comments: list[str] = []
    for lineno, raw in enumerate(lines[1:], start=2):
        tok = raw.split()
        if not tok:
            continue
        key = tok[0]
        if key in ("comment", "obj_info"):
            comments.append(raw.split(None, 1)[1] if len(tok) > 1 else "")
        elif key == "format":
            if len(tok) != 3 or tok[1] not in PLY_FORMATS:
                raise FormatError(source, "bad format line; expected 'format ascii|"
                                          "binary_little_endian|binary_big_endian 1.0'",
                                  line=lineno)
            fmt = tok[1]
        elif key == "element":
            if len(tok) != 3 or not _COUNT.fullmatch(tok[2]):
                raise FormatError(source, "bad element line; expected 'element <name> "
                                          "<count>' with a non-negative count", line=lineno)
            elements.append(Element(tok[1], int(tok[2]), lineno))
        elif key == "property":
            if not elements:
                raise FormatError(source, "property before any element", line=lineno)
            if len(tok) == 5 and tok[1] == "list":
                count_dtype = _type(source, tok[2], lineno)
                if count_dtype.kind not in "iu":
                    raise FormatError(source, f"list count type {tok[2]!r} must be an "
                                              "integer type", line=lineno)
                prop = Property(tok[4], _type(source, tok[3], lineno), count_dtype)
            elif len(tok) == 3:
                prop = Property(tok[2], _type(source, tok[1], lineno))
            else:
                raise FormatError(source, "bad property line; expected 'property <type> "
                                          "<name>' or 'property list <type> <type> <name>'",
                                  line=lineno)
            if elements[-1].prop(prop.name) is not None:
                raise FormatError(source, f"property {prop.name!r} declared twice in element "
                                          f"{elements[-1].name!r}", line=lineno)
            elements[-1].properties.append(prop)
        else:
            raise FormatError(source, f"garbled PLY header: unknown keyword {key!r}",
                              line=lineno)
    if fmt is None:
        raise FormatError(source, "garbled PLY header: no 'format' line")
    header = Header(fmt, elements, body_offset, len(lines) + 1, comments)
    vertex = header.element("vertex")
    if vertex is None:
        raise FormatError(source, "the PLY header declares no 'vertex' element")
    for axis in "xyz":
        p = vertex.prop(axis)
        if p is None or p.is_list:
            raise FormatError(source, f"the vertex element has no scalar property {axis!r}",
                              line=vertex.line)
    _check_size(header, len(data), source)
    return header


def _check_size(header: Header, size: int, source) -> None:
    """Reject header counts the file cannot hold, before anything is allocated."""
    available = size - header.body_offset
    needed = 0
    for e in header.elements:
        if header.format == "ascii":
            # every value takes at least one character and one separator or newline
            tokens = len(e.properties)
            row = 2 * tokens
        else:
            row = e.min_binary_row()
        needed += e.count * row
        if needed - (1 if header.format == "ascii" else 0) > available:
            raise FormatError(
                source, f"header says {e.count} {e.name} rows (at least {row} bytes each), "
                        f"but only {available} bytes follow the header: the file is truncated "
                        "or the header count is wrong", offset=size)


@dataclass
class ElementData:
    """Decoded rows of one element.

    Attributes
    ----------
    scalars : dict of str to ndarray, shape (count,)
        Scalar properties in their declared type (native byte order).
    lists : dict of str to (ndarray, ndarray)
        List properties as ``(counts (count,) int64, items (counts.sum(),))``.
    where : callable
        Row number -> ``{"line": ...}`` or ``{"offset": ...}`` for error messages.
    """

    scalars: dict
    lists: dict
    where: object
