"""E57 (ASTM E2807) scanner files through pye57 (libE57Format), optional (``formats`` extra).

Every scan of the file is read, its points put into the file's common frame by the scan's
pose; invalid points (``cartesianInvalidState``) are left out and ``index`` keeps every
point's position in the file (scans one after another). Kept per point: ``intensity``,
colours as ``red green blue``, ``scan`` (which scan), the scanner grid as ``scan_row`` and
``scan_col``, normals from the ``nor:normalX/Y/Z`` extension (turned by the pose). Each
scan's pose records where its scanner stood (the pose's translation): the cloud's viewpoint,
one position for a single scan, one row per point (its own scan's origin) for several, which
orients the normals by default.
"""

from __future__ import annotations

import os
import struct
import tempfile

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud

SIGNATURE = b"ASTM-E57"
HEADER_BYTES = 48
# Points a scan may claim per byte of file: far above any real compression ratio, low enough
# that a lying record count is refused before pye57 allocates for it.
MAX_POINTS_PER_BYTE = 8
NORMAL_FIELDS = ("nor:normalX", "nor:normalY", "nor:normalZ")
RENAMED = {"colorRed": "red", "colorGreen": "green", "colorBlue": "blue",
           "rowIndex": "scan_row", "columnIndex": "scan_col"}
_SKIP = {"cartesianX", "cartesianY", "cartesianZ", "sphericalRange", "sphericalAzimuth",
         "sphericalElevation", "cartesianInvalidState", "sphericalInvalidState"}


def _pye57(source):
    try:
        import pye57
    except ImportError:
        raise FormatError(source, "reading E57 needs pye57 (pip install "
                                  "'curvature[formats]')") from None
    return pye57


def check_e57_header(data: bytes, source) -> None:
    """Check the 48-byte file header: signature, major version 1, physical length.

    Raises
    ------
    FormatError
        Not E57, or a length field that disagrees with the file's size.
    """
    if not data.startswith(SIGNATURE):
        raise FormatError(source, "not an E57 file: it must start with 'ASTM-E57'", offset=0)
    if len(data) < HEADER_BYTES:
        raise FormatError(source, f"the E57 header needs {HEADER_BYTES} bytes, the file has "
                                  f"{len(data)}", offset=len(data))
    major, _minor, length, xml_offset, xml_length, _page = struct.unpack_from(
        "<IIQQQQ", data, 8)
    if major != 1:
        raise FormatError(source, f"E57 major version {major}; only version 1 is known",
                          offset=8)
    if length != len(data):
        raise FormatError(source, f"the E57 header says the file has {length} bytes but it "
                                  f"has {len(data)}: truncated or padded", offset=16)
    if xml_offset + xml_length > len(data):
        raise FormatError(source, f"the XML section ({xml_length} bytes at {xml_offset}) "
                                  "runs past the end of the file", offset=24)


def read_e57(data: bytes, source=None) -> PointCloud:
    """Decode an E57 file (all scans).

    Returns
    -------
    PointCloud
        ``points`` (n, 3) float64 in the file's frame, ``normals`` when every scan has them,
        ``properties`` (n,), ``index`` (n,), ``viewpoint`` (3,) for a single scan or
        (n, 3) for several (each point's scan origin).

    Raises
    ------
    FormatError
        A bad header, no scans, a scan claiming more points than the file can hold, or an
        error of libE57Format (with its message).
    """
    check_e57_header(data, source)
    pye57 = _pye57(source)
    # libE57Format reads from a path only; the bytes go to a private temporary file.
    fd, tmp = tempfile.mkstemp(suffix=".e57")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        try:
            e57 = pye57.E57(tmp)
        except Exception as exc:
            raise FormatError(source, f"could not open as E57: {exc}") from None
        try:
            scans = [_read_scan(e57, i, len(data), source) for i in range(e57.scan_count)]
        finally:
            e57.close()
    finally:
        os.unlink(tmp)
    if not scans:
        raise FormatError(source, "the E57 file holds no scans (data3D is empty)")
    return _merge(scans, source)


def _read_scan(e57, i: int, size: int, source) -> dict:
    header = e57.get_header(i)
    count = int(header.point_count)
    fields = list(header.point_fields)
    if count * len(fields) > MAX_POINTS_PER_BYTE * size:
        raise FormatError(source, f"scan {i} claims {count} points of {len(fields)} fields, "
                                  f"more than the {size}-byte file can hold")
    try:
        raw = e57.read_scan_raw(i, ignore_unsupported_fields=True)
        normals = _read_normals(e57, header, count) if all(f in fields for f in
                                                           NORMAL_FIELDS) else None
    except Exception as exc:
        raise FormatError(source, f"scan {i}: could not read its points: {exc}") from None
    if "cartesianX" in raw:
        xyz = np.stack([raw[c] for c in ("cartesianX", "cartesianY", "cartesianZ")], axis=1)
        invalid = raw.get("cartesianInvalidState")
    elif "sphericalRange" in raw:
        r, az, el = (raw[c] for c in ("sphericalRange", "sphericalAzimuth",
                                       "sphericalElevation"))
        xyz = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az),
                        r * np.sin(el)], axis=1)
        invalid = raw.get("sphericalInvalidState")
    else:
        raise FormatError(source, f"scan {i} has neither cartesian nor spherical coordinates")
    rotation, origin = np.eye(3), np.zeros(3)
    if header.has_pose():
        rotation = np.asarray(header.rotation_matrix, dtype=np.float64)
        origin = np.asarray(header.translation, dtype=np.float64).reshape(3)
    keep = np.ones(count, bool) if invalid is None else np.asarray(invalid) == 0
    props = {RENAMED.get(k, k): np.asarray(v)[keep] for k, v in raw.items() if k not in _SKIP}
    props["scan"] = np.full(int(keep.sum()), i, np.int32)
    return {"points": xyz[keep] @ rotation.T + origin, "props": props, "keep": keep,
            "normals": None if normals is None else normals[keep] @ rotation.T,
            "origin": origin, "count": count}


def _read_normals(e57, header, count: int) -> np.ndarray:
    """The ``nor:normalX/Y/Z`` extension fields (pye57 reads only the standard ones)."""
    from pye57 import libe57

    arrays = [np.empty(count, np.float64) for _ in NORMAL_FIELDS]
    buffers = libe57.VectorSourceDestBuffer()
    for name, arr in zip(NORMAL_FIELDS, arrays, strict=True):
        buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, count, True, True))
    header.points.reader(buffers).read()
    return np.stack(arrays, axis=1)


def _merge(scans: list[dict], source) -> PointCloud:
    names = set.intersection(*(set(s["props"]) for s in scans))
    props = {k: np.concatenate([s["props"][k] for s in scans]) for k in scans[0]["props"]
             if k in names}
    with_normals = all(s["normals"] is not None for s in scans)
    normals = np.concatenate([s["normals"] for s in scans]) if with_normals else None
    start = np.cumsum([0] + [s["count"] for s in scans[:-1]])
    index = np.concatenate([np.flatnonzero(s["keep"]) + o for s, o in
                            zip(scans, start, strict=True)]).astype(np.int64)
    cloud = finish_cloud(source, np.concatenate([s["points"] for s in scans]),
                         normals=normals, properties=props, dropped=int(
                             sum(s["count"] for s in scans) - index.size), label="point")
    cloud.index = index
    if len(scans) == 1:
        cloud.viewpoint, cloud.viewpoint_source = scans[0]["origin"], "E57 scan pose"
    else:
        origins = np.stack([s["origin"] for s in scans])
        cloud.viewpoint = origins[props["scan"]]
        cloud.viewpoint_source = (f"E57 scan poses: each point faces its own scan's origin, "
                                  f"{len(scans)} scans")
    return cloud
