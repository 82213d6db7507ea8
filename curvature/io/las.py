"""LAS and LAZ 1.2 - 1.4 (ASPRS lidar format) through laspy, LAZ through its lazrs codec.

Read: scaled x y z; every other dimension (intensity, returns, classification, GPS time,
colours, extra bytes) as a property with its own dtype; ``nx ny nz`` extra dimensions become
normals. Write: LAS 1.4 point format 6 (7 with colours), standard dimensions the table
has under their LAS names, every other column (curvature, index, attributes) as an extra
dimension with its dtype. laspy and lazrs are optional (the ``formats`` extra).
"""

from __future__ import annotations

import io
import struct
from typing import BinaryIO

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud
from .columns import Table

# A LAZ body is never smaller than this share of the points it decodes to (a generous bound:
# real lidar compresses 5-10x), so a lying point count is refused before anything is
# allocated.
MAX_LAZ_RATIO = 200
# Extra dimension holding a column that the LAS field of its name cannot hold exactly (a
# float intensity); read back under the plain name when that field is all zero.
VALUE_SUFFIX = "_value"
_HEADER_MIN = 227  # bytes of a LAS 1.0 - 1.2 public header block
# Bytes of a point record per format (LAS 1.4 R15 table), extra bytes come on top.
_RECORD_BYTES = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
_MAX_BODY_RATIO = MAX_LAZ_RATIO
_LASZIP_MAX_ITEM = 14  # item types LASzip defines: 0 byte ... 14 wavepacket 1.4
_NORMALS = ("nx", "ny", "nz")
_COORDS = ("X", "Y", "Z", "x", "y", "z")


def _laspy(source):
    try:
        import laspy
    except ImportError:
        raise FormatError(source, "reading or writing LAS/LAZ needs laspy and lazrs "
                                  "(pip install 'curvature[formats]')") from None
    return laspy


def read_las(data: bytes, source=None) -> PointCloud:
    """Decode a LAS or LAZ file.

    Returns
    -------
    PointCloud
        ``points`` (n, 3) float64 (scale and offset applied), ``normals`` (n, 3) from
        ``nx ny nz`` extra dimensions, every other dimension in ``properties``.

    Raises
    ------
    FormatError
        Not LAS (no ``LASF`` signature), a truncated header, a point count the body cannot
        hold, or any decoding error of laspy / lazrs (with its message).
    """
    laspy = _laspy(source)
    if not data.startswith(b"LASF"):
        raise FormatError(source, "not a LAS/LAZ file: it must start with 'LASF'", offset=0)
    if len(data) < _HEADER_MIN:
        raise FormatError(source, f"the LAS header needs at least {_HEADER_MIN} bytes, the "
                                  f"file has {len(data)}", offset=len(data))
    check_public_header(data, source)
    try:
        with laspy.open(io.BytesIO(data)) as reader:
            header = reader.header
            _check_count(header, len(data), source)
            if header.are_points_compressed:
                check_chunk_table(data, int(header.offset_to_point_data),
                                  int(header.point_count), source)
            las = reader.read()
    except FormatError:
        raise
    except Exception as exc:  # laspy and lazrs raise their own and plain errors alike
        raise FormatError(source, f"could not read as LAS/LAZ: {type(exc).__name__}: "
                                  f"{exc}") from None
    if len(las.points) != header.point_count:
        raise FormatError(source, f"the header says {header.point_count} points but "
                                  f"{len(las.points)} could be read", offset=len(data))
    points = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    names = [n for n in las.point_format.dimension_names if n not in _COORDS]
    normals = None
    if all(n in names for n in _NORMALS):
        normals = np.stack([np.asarray(las[n], dtype=np.float64) for n in _NORMALS], axis=1)
        names = [n for n in names if n not in _NORMALS]
    properties = {name: np.array(las[name]) for name in names}
    for name in [n for n in properties if n.endswith(VALUE_SUFFIX)]:
        # write_las put a column here that LAS's own field of that name could not hold
        base = name[:-len(VALUE_SUFFIX)]
        if base in properties and not properties[base].any():
            properties[base] = properties.pop(name)
    stride = header.point_format.size
    start = header.offset_to_point_data

    def where(row):
        return {} if header.are_points_compressed else {"offset": start + row * stride}

    return finish_cloud(source, points, normals=normals, properties=properties, where=where,
                        label="point")


def check_public_header(data: bytes, source) -> None:
    """Check the fixed header fields and the VLR chain by hand before laspy reads them.

    laspy loops for a very long time on some corrupt VLR counts and lazrs aborts the process
    on others, so offsets, counts and sizes are checked against the file's size first.

    Raises
    ------
    FormatError
        Naming the field and its byte offset.
    """
    size = len(data)
    major, minor = data[24], data[25]
    if major != 1 or minor > 4:
        raise FormatError(source, f"LAS version {major}.{minor}; 1.0 to 1.4 are read",
                          offset=24)
    header_size, offset, n_vlrs = struct.unpack_from("<HII", data, 94)
    fmt_id, record, legacy_count = struct.unpack_from("<BHI", data, 104)
    if not _HEADER_MIN <= header_size <= min(offset, size):
        raise FormatError(source, f"header size {header_size} must be between {_HEADER_MIN} "
                                  f"and the point data offset {offset}", offset=94)
    if offset > size:
        raise FormatError(source, f"the point data offset {offset} is past the end of the "
                                  f"{size}-byte file", offset=96)
    base = _RECORD_BYTES.get(fmt_id & 0x3F)
    if base is None:
        raise FormatError(source, f"unknown point format {fmt_id & 0x3F}; 0 to 10 are "
                                  "defined", offset=104)
    if record < base:
        raise FormatError(source, f"point records of {record} bytes are shorter than point "
                                  f"format {fmt_id & 0x3F} needs ({base})", offset=105)
    pos = header_size
    for k in range(n_vlrs):
        if pos + 54 > offset:
            raise FormatError(source, f"VLR {k} of {n_vlrs} would start at byte {pos}, past "
                                      f"the point data at {offset}", offset=100)
        pos += 54 + struct.unpack_from("<H", data, pos + 52)[0]
    if pos > offset:
        raise FormatError(source, f"the VLRs end at byte {pos}, past the point data at "
                                  f"{offset}", offset=pos)
    if minor >= 4 and header_size >= 375:
        evlr_start, n_evlrs = struct.unpack_from("<QI", data, 235)
        if n_evlrs and (evlr_start > size or n_evlrs > (size - evlr_start) // 60):
            raise FormatError(source, f"{n_evlrs} extended VLRs at byte {evlr_start} do not "
                                      f"fit the {size}-byte file", offset=235)
    elif legacy_count * record > _MAX_BODY_RATIO * max(size - offset, 1):
        raise FormatError(source, f"the header says {legacy_count} points of {record} bytes, "
                                  f"far more than the {size - offset} bytes of point data",
                          offset=107)


def _check_count(header, size: int, source) -> None:
    """Refuse point counts the file cannot hold, before laspy allocates for them."""
    count, stride = int(header.point_count), int(header.point_format.size)
    start = int(header.offset_to_point_data)
    body = size - start
    if body < 0:
        raise FormatError(source, f"the header puts the points at byte {start} but the file "
                                  f"has {size} bytes", offset=size)
    if header.are_points_compressed:
        _check_laszip(header, size, source)
        if count * stride > MAX_LAZ_RATIO * max(body, 1):
            raise FormatError(source, f"the header says {count} points but {body} compressed "
                                      "bytes cannot hold them: the file is truncated or the "
                                      "count is wrong", offset=size)
    elif count * stride > body:
        raise FormatError(source, f"the header says {count} points of {stride} bytes "
                                  f"({count * stride} bytes) but only {body} bytes follow "
                                  "the header", offset=size)


def check_chunk_table(data: bytes, start: int, count: int, source) -> None:
    """Check the LAZ chunk table's place and chunk count before lazrs allocates for it.

    The compressed points start with the 8-byte offset of the chunk table (-1 when the writer
    left it out); the table starts with its version and the number of chunks, for each of
    which lazrs allocates 16 bytes up front: a corrupt count asked it for 40 GB, and a failed
    allocation aborts the process. Every chunk holds at least one point and one byte.

    Raises
    ------
    FormatError
        A table outside the file, or more chunks than points or bytes.
    """
    if start + 8 > len(data):
        raise FormatError(source, "the compressed points end before their chunk table offset",
                          offset=start)
    table = struct.unpack_from("<q", data, start)[0]
    if table == -1:
        return
    if not start + 8 <= table <= len(data) - 8:
        raise FormatError(source, f"the LAZ chunk table offset {table} is outside the "
                                  f"compressed points (bytes {start + 8} to {len(data)})",
                          offset=start)
    chunks = struct.unpack_from("<I", data, table + 4)[0]
    if chunks > max(count, 1) or chunks > len(data) - start:
        raise FormatError(source, f"the LAZ chunk table lists {chunks} chunks for {count} "
                                  f"points in a {len(data)}-byte file", offset=table + 4)


def _check_laszip(header, size: int, source) -> None:
    """Check the LASzip VLR against the point format before lazrs sees it.

    lazrs aborts the whole process (it does not raise) on some inconsistent VLRs, so what it
    relies on is checked here: the record's length for its item count, item sizes that add
    up to the point record, a known compressor and a non-zero chunk size.
    """
    vlr = next((v for v in header.vlrs if getattr(v, "record_id", None) == 22204), None)
    if vlr is None:
        raise FormatError(source, "the points are compressed but there is no LASzip VLR "
                                  "(user 'laszip encoded', record 22204)")
    raw = bytes(vlr.record_data)
    if len(raw) < 34:
        raise FormatError(source, f"the LASzip VLR has {len(raw)} bytes, at least 34 expected")
    compressor, coder = struct.unpack_from("<HH", raw, 0)
    chunk_size = struct.unpack_from("<I", raw, 12)[0]
    n_items = struct.unpack_from("<H", raw, 32)[0]
    if len(raw) != 34 + 6 * n_items or n_items == 0:
        raise FormatError(source, f"the LASzip VLR lists {n_items} items in {len(raw)} bytes; "
                                  f"{34 + 6 * n_items} bytes expected")
    items = [struct.unpack_from("<HHH", raw, 34 + 6 * k) for k in range(n_items)]
    if compressor not in (1, 2, 3) or coder != 0 or chunk_size == 0:
        raise FormatError(source, f"the LASzip VLR names compressor {compressor}, coder "
                                  f"{coder}, chunk size {chunk_size}; expected compressor "
                                  "1-3, coder 0 and a non-zero chunk size")
    if any(t > _LASZIP_MAX_ITEM or z == 0 for t, z, _ in items) or \
            sum(z for _, z, _ in items) != header.point_format.size:
        raise FormatError(source, f"the LASzip items {[(t, z) for t, z, _ in items]} do not "
                                  f"add up to the {header.point_format.size}-byte point record")


def _las_scale(values: np.ndarray) -> tuple[float, float]:
    """Offset and power-of-ten scale so the int32 coordinates span the range finely."""
    lo, hi = float(values.min()), float(values.max())
    extent = max(hi - lo, abs(lo), abs(hi), 1e-9)
    scale = 10.0 ** np.ceil(np.log10(extent / 2.0e9))  # (v - lo) / scale <= 2e9 < 2^31
    return lo, float(scale)


def write_las(fh: BinaryIO, table: Table, *, compress: bool = False) -> None:
    """Write ``table`` as LAS 1.4 (``compress=True``: LAZ).

    Coordinates are stored as int32 with a power-of-ten scale of at most 1e-9 of the cloud's
    extent; 8-bit colour channels are scaled to LAS's 16 bits (times 257).
    """
    laspy = _laspy(None)
    cols = dict(table.columns())
    has_color = all(c in cols for c in ("red", "green", "blue"))
    header = laspy.LasHeader(point_format=7 if has_color else 6, version="1.4")
    dims = {d.name: d.dtype for d in header.point_format.dimensions}
    if has_color:
        cols.update({c: _color16(cols[c]) for c in ("red", "green", "blue")})
    # A column goes into the standard dimension of its name only when that type holds its
    # values exactly (a float intensity does not fit LAS's uint16); else into extra bytes.
    standard = {name for name, arr in cols.items()
                if name in dims and name not in _COORDS and dims[name] is not None
                and _fits(arr, dims[name])}
    cols = {(name if name in standard or name not in dims else name + VALUE_SUFFIX): arr
            for name, arr in cols.items()}
    points = np.asarray(table.fields["points"], dtype=np.float64)
    extra = [(name, arr) for name, arr in cols.items()
             if name not in _COORDS and name not in standard]
    header.add_extra_dims([laspy.ExtraBytesParams(name=name, type=_las_type(arr))
                           for name, arr in extra])
    offsets, scales = zip(*(_las_scale(points[:, j]) for j in range(3)), strict=True)
    header.offsets, header.scales = np.array(offsets), np.array(scales)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    for name, arr in cols.items():
        if name in _COORDS:
            continue
        if name in standard:
            las[name] = arr
        else:
            las[name] = arr.astype(_las_type(arr), copy=False)
    buffer = io.BytesIO()  # laspy seeks back to patch the header; web streams cannot
    las.write(buffer, do_compress=compress)
    fh.write(buffer.getbuffer())


def _color16(arr: np.ndarray) -> np.ndarray:
    """8-bit colour channels on LAS's 16-bit scale (255 -> 65535); others unchanged."""
    return arr.astype(np.uint16) * np.uint16(257) if arr.dtype == np.uint8 else arr


def _fits(arr: np.ndarray, dtype) -> bool:
    """Whether ``arr`` converts to ``dtype`` without changing a value."""
    dtype = np.dtype(dtype)
    if arr.dtype.kind == "f" and dtype.kind != "f":
        return False
    with np.errstate(all="ignore"):
        return bool(np.array_equal(arr.astype(dtype).astype(arr.dtype), arr, equal_nan=True))


def _las_type(arr: np.ndarray) -> np.dtype:
    """The extra-bytes type of a column (LAS has no bool; 64-bit kept as they are)."""
    return np.dtype(np.uint8) if arr.dtype.kind == "b" else arr.dtype.newbyteorder("=")
