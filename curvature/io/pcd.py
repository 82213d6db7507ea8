"""PCD v0.7 (Point Cloud Library): ascii, binary and binary_compressed bodies.

Rows whose x, y or z is not finite (the holes of organized depth-camera scans) are dropped
and counted in ``PointCloud.dropped``. ``normal_x normal_y normal_z`` become normals; every
other field is kept as a property (``rgb``/``rgba`` packed colours as uint32; fields with
COUNT > 1 split into ``name_0``, ``name_1`` ...; ``_`` padding fields skipped).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError, NonFiniteError
from .checks import finish_cloud
from .lzf import LZFError, lzf_decompress
from .text_blocks import RowScanner, rows_values

_KEYS = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
         "VIEWPOINT", "POINTS", "DATA")
_SIZES = {"F": (4, 8), "U": (1, 2, 4, 8), "I": (1, 2, 4, 8)}
_KIND = {"F": "f", "U": "u", "I": "i"}
_DATA = ("ascii", "binary", "binary_compressed")
_MAX_HEADER_LINES = 1000
NORMAL_FIELDS = ("normal_x", "normal_y", "normal_z")


@dataclass
class PCDHeader:
    fields: list[str]
    dtypes: list[np.dtype]  # little endian, one per field
    counts: list[int]
    width: int
    height: int
    points: int
    data: str
    body_offset: int
    n_lines: int
    viewpoint: np.ndarray | None = None  # (3,) sensor origin from VIEWPOINT

    @property
    def row_size(self) -> int:
        return sum(dt.itemsize * c for dt, c in zip(self.dtypes, self.counts, strict=True))


def _ints(source, key, values, lineno, minimum=0):
    try:
        out = [int(v) for v in values]
    except ValueError:
        raise FormatError(source, f"{key} values must be integers, got {' '.join(values)}",
                          line=lineno) from None
    if any(v < minimum for v in out):
        raise FormatError(source, f"{key} values must be >= {minimum}", line=lineno)
    return out


def parse_pcd_header(data: bytes, source) -> PCDHeader:
    """Parse the header lines up to and including ``DATA``.

    Raises
    ------
    FormatError
        Unknown keyword, missing or inconsistent FIELDS/SIZE/TYPE/COUNT, WIDTH x HEIGHT
        different from POINTS, no x/y/z field, unknown DATA kind, or no DATA line.
    """
    values: dict[str, tuple[list[str], int]] = {}
    pos = 0
    lineno = 0
    while "DATA" not in values:
        if pos >= len(data) or lineno >= _MAX_HEADER_LINES:
            raise FormatError(source, "garbled PCD header: no DATA line")
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        line = data[pos:end].decode("latin-1").strip()
        pos = end + 1
        lineno += 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        if key not in _KEYS:
            what = "not a PCD file" if not values else "garbled PCD header"
            raise FormatError(source, f"{what}: unknown keyword {key[:40]!r}", line=lineno)
        values[key] = (vals, lineno)
    pos = min(pos, len(data))

    def get(key, default=None):
        if key not in values:
            if default is None:
                raise FormatError(source, f"garbled PCD header: no {key} line")
            return default, None
        return values[key]

    fields, fline = values.get("FIELDS") or get("COLUMNS")
    sizes, sline = get("SIZE")
    types, tline = get("TYPE")
    sizes = _ints(source, "SIZE", sizes, sline, 1)
    counts, cline = get("COUNT", ["1"] * len(fields))
    counts = _ints(source, "COUNT", counts, cline, 1)
    for key, vals, line in (("SIZE", sizes, sline), ("TYPE", types, tline),
                            ("COUNT", counts, cline)):
        if len(vals) != len(fields):
            raise FormatError(source, f"{key} has {len(vals)} entries but FIELDS has "
                                      f"{len(fields)}", line=line)
    dtypes = []
    for name, size, kind in zip(fields, sizes, types, strict=True):
        if kind not in _SIZES or size not in _SIZES[kind]:
            raise FormatError(source, f"field {name!r}: unsupported TYPE {kind} with SIZE "
                                      f"{size}", line=tline)
        dtypes.append(np.dtype(f"<{_KIND[kind]}{size}"))
    for axis in "xyz":
        if axis not in fields:
            raise FormatError(source, f"the PCD has no {axis!r} field", line=fline)
        if counts[fields.index(axis)] != 1:
            raise FormatError(source, f"field {axis!r} must have COUNT 1", line=cline)
    width, wline = get("WIDTH")
    width = _ints(source, "WIDTH", width[:1], wline)[0] if width else 0
    height, hline = get("HEIGHT", ["1"])
    height = _ints(source, "HEIGHT", height[:1], hline)[0] if height else 1
    if "POINTS" in values:
        pvals, pline = values["POINTS"]
        if len(pvals) != 1:
            raise FormatError(source, "POINTS needs one integer", line=pline)
        points = _ints(source, "POINTS", pvals, pline)[0]
        if width * height != points:
            raise FormatError(source, f"WIDTH x HEIGHT = {width} x {height} = "
                                      f"{width * height} but POINTS = {points}", line=pline)
    else:
        points = width * height
    kind_vals, dline = values["DATA"]
    if len(kind_vals) != 1 or kind_vals[0] not in _DATA:
        raise FormatError(source, "DATA must be ascii, binary or binary_compressed",
                          line=dline)
    return PCDHeader(fields, dtypes, counts, width, height, points, kind_vals[0], pos, lineno,
                     _viewpoint(source, values.get("VIEWPOINT")))


def _viewpoint(source, entry) -> np.ndarray | None:
    """The sensor origin of ``VIEWPOINT tx ty tz qw qx qy qz``; the rotation does not move
    it, so only the translation is kept."""
    if entry is None:
        return None
    vals, line = entry
    try:
        vp = np.array([float(v) for v in vals], dtype=np.float64)
    except ValueError:
        raise FormatError(source, "VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz), got "
                                  f"{' '.join(vals)[:80]!r}", line=line) from None
    if vp.size != 7 or not np.isfinite(vp).all():
        raise FormatError(source, "VIEWPOINT needs 7 finite numbers (tx ty tz qw qx qy qz), "
                                  f"got {vp.size}", line=line)
    return vp[:3]


def read_pcd(data: bytes, source=None) -> PointCloud:
    """Decode a PCD file.

    Returns
    -------
    PointCloud
        Finite rows only: ``points`` (n, 3) float64, optional ``normals`` (n, 3) and
        ``properties`` (n,); ``dropped`` = rows removed for a non-finite coordinate.

    Raises
    ------
    FormatError
        Header problems, a body shorter than the header says, corrupt LZF data, bad rows.
    """
    h = parse_pcd_header(data, source)
    if h.data == "ascii":
        columns = _ascii_columns(data, h, source)
    elif h.data == "binary":
        columns = _binary_columns(data, h, source)
    else:
        columns = _compressed_columns(data, h, source)
    return _to_cloud(columns, h, source)


def _ascii_columns(data, h: PCDHeader, source):
    width = sum(h.counts)
    scanner = RowScanner(data, h.body_offset, h.n_lines + 1, source)
    # Fail fast on a header count the bytes cannot hold (a row takes >= 2 bytes a value),
    # before anything is allocated for it.
    fits = h.points <= (len(data) - h.body_offset + 1) // (2 * width)
    found = 0
    for block in scanner.blocks(h.points if fits else 0):  # pass 1: row widths and count
        lens = block.tokens.lens[block.rows]
        bad = np.flatnonzero(lens != width)
        if bad.size:
            r = int(bad[0])
            raise FormatError(source, f"point {found + r} has {lens[r]} values, expected "
                                      f"{width} ({' '.join(h.fields)})",
                              line=block.first_line + int(block.rows[r]))
        found += block.rows.size
    if not fits:
        found = sum(b.rows.size for b in scanner.blocks())
    if found < h.points:
        raise FormatError(source, f"header says {h.points} points but only {found} "
                                  "data lines follow", line=scanner.end_line)
    columns = {name: np.empty((h.points, c), dtype=dt)
               for name, dt, c in zip(h.fields, h.dtypes, h.counts, strict=True)}
    last = {name: i for i, name in enumerate(h.fields)}
    at = 0
    with np.errstate(all="ignore"):
        for block in scanner.blocks(h.points):  # pass 2: values into the typed columns
            rows = block.rows.size
            table = rows_values(block, source).reshape(rows, width)
            col = 0
            for i, (name, c) in enumerate(zip(h.fields, h.counts, strict=True)):
                if last[name] == i:  # a repeated name (padding '_') keeps its last field
                    columns[name][at:at + rows] = table[:, col:col + c]
                col += c
            at += rows
    return columns


def _binary_columns(data, h: PCDHeader, source):
    need = h.points * h.row_size
    available = len(data) - h.body_offset
    if need > available:
        raise FormatError(source, f"header says {h.points} points of {h.row_size} bytes "
                                  f"({need} bytes) but only {available} bytes follow",
                          offset=len(data))
    dt = np.dtype([(f"f{i}", d, (c,)) for i, (d, c) in enumerate(zip(h.dtypes, h.counts,
                                                                      strict=True))])
    rec = np.frombuffer(data, dtype=dt, count=h.points, offset=h.body_offset)
    return {name: rec[f"f{i}"].reshape(h.points, -1) for i, name in enumerate(h.fields)}


def _compressed_columns(data, h: PCDHeader, source):
    start = h.body_offset
    if len(data) < start + 8:
        raise FormatError(source, "the binary_compressed body has no size words",
                          offset=len(data))
    compressed, size = (int(v) for v in np.frombuffer(data, dtype="<u4", count=2,
                                                      offset=start))
    if start + 8 + compressed > len(data):
        raise FormatError(source, f"the compressed block claims {compressed} bytes but only "
                                  f"{len(data) - start - 8} follow", offset=start)
    expected = h.points * h.row_size
    if size != expected:
        raise FormatError(source, f"the compressed block unpacks to {size} bytes but "
                                  f"{h.points} points of {h.row_size} bytes need {expected}",
                          offset=start + 4)
    block = np.frombuffer(data, dtype=np.uint8, count=compressed, offset=start + 8)
    try:
        raw = lzf_decompress(block, size)
    except LZFError as exc:
        raise FormatError(source, f"corrupt LZF data: {exc}",
                          offset=start + 8 + exc.position) from None
    # Column-major: all values of the first field, then all of the second ...
    columns, off = {}, 0
    for name, dt, c in zip(h.fields, h.dtypes, h.counts, strict=True):
        columns[name] = np.frombuffer(raw, dtype=dt, count=h.points * c,
                                      offset=off).reshape(h.points, c)
        off += h.points * c * dt.itemsize
    return columns


def _to_cloud(columns, h: PCDHeader, source) -> PointCloud:
    points = np.concatenate([columns[a] for a in "xyz"], axis=1, dtype=np.float64)
    keep = np.isfinite(points).all(axis=1)
    dropped = int(keep.size - np.count_nonzero(keep))
    if dropped:
        points = points[keep]
    normals = None
    if all(n in columns and columns[n].shape[1] == 1 for n in NORMAL_FIELDS):
        normals = np.concatenate([columns[n] for n in NORMAL_FIELDS], axis=1)[keep]
    properties = {}
    for name, values in columns.items():
        if name in ("x", "y", "z", "_") or (normals is not None and name in NORMAL_FIELDS):
            continue
        if name in ("rgb", "rgba") and values.dtype == np.float32:
            values = values.view(np.uint32)  # PCL packs 8-bit colours into a float's bits
        values = values[keep] if dropped else values
        if values.shape[1] == 1:
            properties[name] = values[:, 0].copy()
        else:
            for j in range(values.shape[1]):
                properties[f"{name}_{j}"] = values[:, j].copy()
    if points.shape[0] == 0 and dropped:
        raise NonFiniteError(source, f"all {dropped} points have a NaN or Inf coordinate")
    cloud = finish_cloud(source, points, normals=normals, properties=properties,
                         dropped=dropped, label="point")
    # Positions in the file (row-major grid cells of an organized scan), holes included.
    cloud.index = np.flatnonzero(keep).astype(np.int64) if dropped else None
    cloud.grid = (h.width, h.height) if h.height > 1 else None
    if h.viewpoint is not None:
        cloud.viewpoint, cloud.viewpoint_source = h.viewpoint, "PCD VIEWPOINT"
    return cloud
