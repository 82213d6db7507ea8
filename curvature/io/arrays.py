"""NumPy files: ``.npy`` (one (n, 3) or (n, 6) array) and ``.npz`` (named arrays).

Array headers are read and checked against the bytes actually present before any array is
allocated, so a header claiming a huge shape fails at once.
"""

from __future__ import annotations

import io
import zipfile
import zlib
from typing import BinaryIO

import numpy as np
from numpy.lib import format as npformat

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud
from .columns import Table, split_vectors
from .faces import triangulate


def _read_array(fh, available: int, source, what: str) -> np.ndarray:
    """Read one .npy stream whose payload may be at most ``available`` bytes."""
    try:
        version = npformat.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = npformat.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = npformat.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except Exception as exc:  # numpy parses the header with ast/tokenize: many error types
        raise FormatError(source, f"{what}: garbled .npy header ({type(exc).__name__}: "
                                  f"{exc})") from None
    if dtype.hasobject:
        raise FormatError(source, f"{what}: arrays of Python objects are not read")
    need = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    header_size = fh.tell()
    if need > available - header_size:
        raise FormatError(source, f"{what}: the header announces shape {shape} "
                                  f"({need} bytes) but only {available - header_size} bytes "
                                  "follow", offset=header_size)
    raw = fh.read(need)
    if len(raw) != need:
        raise FormatError(source, f"{what}: truncated array data",
                          offset=header_size + len(raw))
    arr = np.frombuffer(raw, dtype=dtype)
    return arr.reshape(shape, order="F" if fortran else "C")


def read_npy(data: bytes, source=None) -> PointCloud:
    """Decode a ``.npy`` holding an (n, 3) or (n, 6) array (``x y z [nx ny nz]``).

    A structured array with fields ``x y z`` (and optional ``nx ny nz`` and others) is
    accepted too.
    """
    arr = _read_array(io.BytesIO(data), len(data), source, "array")
    if arr.dtype.names:
        return _from_fields({n: arr[n] for n in arr.dtype.names}, source)
    if arr.dtype.kind not in "biuf":
        raise FormatError(source, f"the array has dtype {arr.dtype}, expected numbers")
    if arr.ndim != 2 or arr.shape[1] not in (3, 6):
        raise FormatError(source, f"the array has shape {arr.shape}, expected (n, 3) or (n, 6)")
    normals = arr[:, 3:6] if arr.shape[1] == 6 else None
    return finish_cloud(source, arr[:, :3], normals=normals)


def _from_fields(fields: dict, source) -> PointCloud:
    if not all(a in fields for a in "xyz"):
        raise FormatError(source, "the structured array has no x, y and z fields")
    points = np.stack([fields[a] for a in "xyz"], axis=1)
    normals = None
    if all(n in fields for n in ("nx", "ny", "nz")):
        normals = np.stack([fields[n] for n in ("nx", "ny", "nz")], axis=1)
    skip = {"x", "y", "z"} | ({"nx", "ny", "nz"} if normals is not None else set())
    props = {k: np.asarray(v) for k, v in fields.items() if k not in skip and np.ndim(v) == 1}
    return finish_cloud(source, points, normals=normals, properties=props)


def read_npz(data: bytes, source=None) -> PointCloud:
    """Decode a ``.npz`` archive with ``points`` (n, 3) and optional ``normals`` (n, 3),
    ``faces`` (m, 3); other arrays of length n become properties ((n, k) arrays split into
    columns, e.g. ``dir1`` -> ``d1x d1y d1z``).
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = {info.filename: info for info in archive.infolist()}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, NotImplementedError) as exc:
        raise FormatError(source, f"not a valid .npz (zip) archive: {exc}") from None
    arrays = {}
    for filename, info in members.items():
        if not filename.endswith(".npy"):
            continue
        name = filename[:-4]
        try:
            with archive.open(info) as fh:
                arrays[name] = _read_array(fh, info.file_size, source, f"array {name!r}")
        except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, RuntimeError,
                zlib.error) as exc:
            raise FormatError(source, f"array {name!r}: corrupt archive member ({exc})") \
                from None
    if "points" not in arrays:
        raise FormatError(source, f"the archive has no 'points' array (found: "
                                  f"{sorted(arrays) or 'none'})")
    points = arrays.pop("points")
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype.kind not in "biuf":
        raise FormatError(source, f"'points' has shape {points.shape} and dtype "
                                  f"{points.dtype}, expected numbers of shape (n, 3)")
    n = points.shape[0]
    normals = arrays.pop("normals", None)
    if normals is not None and normals.shape != (n, 3):
        raise FormatError(source, f"'normals' has shape {normals.shape}, expected ({n}, 3)")
    faces = arrays.pop("faces", None)
    props = {}
    for name, arr in arrays.items():
        if arr.ndim in (1, 2) and arr.shape[0] == n and arr.dtype.kind in "biuf":
            props.update(split_vectors({name: arr}))
    cloud = finish_cloud(source, points, normals=normals, properties=props)
    if faces is not None and faces.size:
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
            raise FormatError(source, f"'faces' has shape {faces.shape} and dtype "
                                      f"{faces.dtype}, expected integers of shape (m, 3)")
        cloud.faces = triangulate(source, np.full(len(faces), 3), faces.reshape(-1), n)
    return cloud


# A member is deflated when its first bytes deflate below this share of their size. Curvature,
# coordinates and directions in float64 deflate by 3 to 14 % only, at about 30 MB/s (two
# thirds of a 1M-point run's writing time); codes, counts and indices shrink 5- to 1000-fold.
DEFLATE_BELOW = 0.8
_PROBE_BYTES = 1 << 16


def _pays_to_deflate(arr: np.ndarray) -> bool:
    probe = np.ascontiguousarray(arr.reshape(-1)[:max(1, _PROBE_BYTES // max(arr.itemsize, 1))])
    raw = probe.tobytes()
    return len(raw) == 0 or len(zlib.compress(raw, 1)) < DEFLATE_BELOW * len(raw)


def write_npz(fh: BinaryIO, table: Table) -> None:
    """Write one array per field (vectors as (n, 3)), plus ``faces``, as ``np.savez`` does.

    Members that compress (status codes, neighbor counts, indices) are deflated; float fields,
    which barely do, are stored, so writing costs little more than the bytes. ``np.load``
    reads both kinds.
    """
    arrays = dict(table.fields)
    if table.faces is not None:
        arrays["faces"] = table.faces
    with zipfile.ZipFile(fh, mode="w", allowZip64=True) as archive:
        for name, values in arrays.items():
            values = np.asanyarray(values)
            member = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            member.compress_type = (zipfile.ZIP_DEFLATED if _pays_to_deflate(values)
                                    else zipfile.ZIP_STORED)
            with archive.open(member, mode="w", force_zip64=True) as out:
                npformat.write_array(out, values, allow_pickle=False)
