"""Reading and writing point clouds and curvature results (DESIGN.md section 6).

Read: PLY, PCD, XYZ/CSV/TXT/ASC, NPY/NPZ, OBJ/STL/OFF, GLB/glTF, 3MF, LAS/LAZ, E57.
Write: PLY, CSV, NPZ, JSON, LAS/LAZ.
Every malformed input raises :class:`~curvature.errors.FormatError` naming the file and,
where it applies, the line or byte offset; an unknown extension raises
:class:`~curvature.errors.UnknownFormatError`.
"""

from __future__ import annotations

import io
import os
import shutil
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError, UnknownFormatError
from ..result import CurvatureResult
from .arrays import read_npy, read_npz, write_npz
from .atomic import atomic_open
from .colors import expand_colors
from .columns import DERIVED, RESULT_ORDER, result_from_cloud, table_of
from .e57 import read_e57
from .json_format import write_json
from .las import read_las, write_las
from .meshes import read_obj, read_off, read_stl
from .pcd import read_pcd
from .ply import read_ply, write_ply
from .text import read_text, write_csv
from .trimesh_meshes import read_3mf, read_glb, read_gltf

_READERS: dict[str, Callable[[bytes, str | None], PointCloud]] = {
    "ply": read_ply,
    "pcd": read_pcd,
    "xyz": read_text,
    "csv": read_text,
    "txt": read_text,
    "asc": read_text,
    "npy": read_npy,
    "npz": read_npz,
    "obj": read_obj,
    "stl": read_stl,
    "off": read_off,
    "glb": read_glb,
    "gltf": read_gltf,
    "3mf": read_3mf,
    "las": read_las,
    "laz": read_las,
    "e57": read_e57,
}
FORMATS_READ: tuple[str, ...] = tuple(_READERS)
FORMATS_WRITE: tuple[str, ...] = ("ply", "csv", "npz", "json", "las", "laz")
MEDIA_TYPES = {
    "ply": "application/octet-stream",  # no registered type; text/plain for ascii is common
    "csv": "text/csv",
    "npz": "application/octet-stream",
    "json": "application/json",
    "las": "application/vnd.las",
    "laz": "application/vnd.laszip",
}

__all__ = [
    "DERIVED",
    "FORMATS_READ",
    "FORMATS_WRITE",
    "MEDIA_TYPES",
    "RESULT_ORDER",
    "expand_colors",
    "format_from_path",
    "read",
    "read_bytes",
    "read_result",
    "write",
    "write_bytes",
    "write_stream",
]


def format_from_path(path) -> str:
    """Format name from a file's extension, case-insensitive (``"scan.PLY"`` -> ``"ply"``).

    Raises
    ------
    UnknownFormatError
        The extension is not one the library reads or writes.
    """
    suffix = Path(os.fspath(path)).suffix.lower().lstrip(".")
    if suffix in FORMATS_READ or suffix in FORMATS_WRITE:
        return suffix
    known = ", ".join(sorted(set(FORMATS_READ) | set(FORMATS_WRITE)))
    shown = f"extension '.{suffix}'" if suffix else "no extension"
    raise UnknownFormatError(path, f"unknown format ({shown}); known formats: {known}")


def _format(name, path, allowed: tuple[str, ...], verb: str) -> str:
    fmt = format_from_path(path) if name is None else str(name).lower().lstrip(".")
    if fmt not in allowed:
        raise UnknownFormatError(path, f"cannot {verb} format {fmt!r}; {verb}able formats: "
                                       f"{', '.join(allowed)}")
    return fmt


def read(path, *, format: str | None = None) -> PointCloud:
    """Read a point cloud or mesh from a file.

    Parameters
    ----------
    path : str or os.PathLike
    format : str, optional
        One of :data:`FORMATS_READ`; by default taken from the extension.

    Returns
    -------
    PointCloud
        ``points`` (n, 3) float64, ``normals`` (n, 3) or None, ``faces`` (m, 3) int64 or None,
        ``properties`` of shape (n,), ``dropped`` NaN rows (PCD), ``source`` = ``path``.

    Raises
    ------
    UnknownFormatError
        Unknown extension or format name.
    FormatError
        The file is malformed, empty, or holds fewer than 10 points.
    OSError
        The file cannot be opened (missing, a directory, no permission).
    """
    fmt = _format(format, path, FORMATS_READ, "read")
    data = Path(path).read_bytes()
    return read_bytes(data, fmt, source=os.fspath(path))


def read_bytes(data: bytes, format: str, *, source: str | None = None
               ) -> PointCloud:
    """Decode the bytes of a file in ``format`` (for uploads that are not on disk)."""
    fmt = _format(format, source or "", FORMATS_READ, "read")
    if len(data) == 0:
        raise FormatError(source, "the file is empty")
    try:
        with np.errstate(all="ignore"):
            return _READERS[fmt](bytes(data), source)
    except FormatError:
        raise
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, struct.error,
            UnicodeError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
        # Safety net: a case the readers do not check for explicitly still ends as a
        # FormatError naming the file rather than a raw numpy/struct error.
        raise FormatError(source, f"could not read as {fmt}: {type(exc).__name__}: {exc}") \
            from exc


def read_result(path, *, format: str | None = None) -> CurvatureResult:
    """Read a result file written by :func:`write` (PLY, CSV or NPZ) back as a result."""
    return result_from_cloud(read(path, format=format))


def write_stream(fileobj: BinaryIO, obj, format: str, *, binary: bool = True,
                 source: str | None = None) -> None:
    """Write a cloud, result or (n, 3) array to an open binary file object.

    Parameters
    ----------
    fileobj : binary file-like
        Receives the encoded bytes (``write`` is the only method used, except for ``npz``
        which also needs ``seek``/``tell`` or writes through a buffer).
    obj : PointCloud, CurvatureResult or array_like, shape (n, 3)
    format : str
        One of :data:`FORMATS_WRITE`.
    binary : bool
        PLY only: binary little endian (default) or ascii.
    """
    fmt = _format(format, source or "", FORMATS_WRITE, "write")
    _write_table(fileobj, table_of(obj, source), fmt, binary)


def _write_table(fileobj: BinaryIO, table, fmt: str, binary: bool) -> None:
    if fmt == "ply":
        write_ply(fileobj, table, binary=binary)
    elif fmt == "csv":
        write_csv(fileobj, table)
    elif fmt == "json":
        write_json(fileobj, table)
    elif fmt in ("las", "laz"):
        write_las(fileobj, table, compress=fmt == "laz")
    elif _seekable(fileobj):
        write_npz(fileobj, table)
    else:
        # zip needs a seekable target and web streams are not: build it in a spooled file
        # (on disk beyond a few MiB, so a big result is never held twice in memory)
        with tempfile.SpooledTemporaryFile(max_size=NPZ_SPOOL_BYTES) as spool:
            write_npz(spool, table)
            spool.seek(0)
            shutil.copyfileobj(spool, fileobj, 1 << 20)


# NPZ results for non-seekable targets are built in memory up to this size, then on disk.
NPZ_SPOOL_BYTES = 16 << 20


def _seekable(fileobj) -> bool:
    try:
        return bool(fileobj.seekable()) and fileobj.tell() >= 0
    except (AttributeError, OSError, ValueError):
        return False


def write_bytes(obj, format: str, *, binary: bool = True) -> bytes:
    """Encode a cloud, result or (n, 3) array in ``format`` and return the bytes."""
    buffer = io.BytesIO()
    write_stream(buffer, obj, format, binary=binary)
    return buffer.getvalue()


def write(path, obj, *, format: str | None = None, binary: bool = True
          ) -> Path:
    """Write a cloud, result or (n, 3) array to ``path`` atomically.

    The data goes to a temporary file in the same directory, which is renamed over ``path``
    only once complete, so no reader ever sees a half-written file.

    Parameters
    ----------
    path : str or os.PathLike
    obj : PointCloud, CurvatureResult or array_like, shape (n, 3)
    format : str, optional
        One of :data:`FORMATS_WRITE`; by default taken from the extension.
    binary : bool
        PLY only: binary little endian (default) or ascii.

    Returns
    -------
    Path
        The path written.
    """
    fmt = _format(format, path, FORMATS_WRITE, "write")
    table = table_of(obj, os.fspath(path))  # validate before creating any file
    with atomic_open(path) as fh:
        _write_table(fh, table, fmt, binary)
    return Path(path)
