"""Checks of NPY/NPZ uploads by what they declare, before anything is decompressed or loaded.

An NPZ member is a zip entry holding an NPY file: its uncompressed size is in the zip
directory and its array shape in the NPY header, both readable for a few hundred bytes. A
deflate bomb (a 1.5 MB file expanding to 1.5 GB of zeros) or a header claiming more points
than the service accepts is refused from those numbers, without inflating a byte of data.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from .problem_types import ProblemError

# Real point data (float coordinates) deflates by a factor of 1 to 3; zeros by about 1000.
MAX_COMPRESSION_RATIO = 50
# Members smaller than this are never refused for their ratio (small, regular arrays).
_RATIO_FLOOR_BYTES = 1 << 20


def _declared_shape(fh, where: str) -> tuple[tuple[int, ...], np.dtype]:
    try:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=10_000)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=10_000)
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise ProblemError("malformed-file", f"{where}: not a readable NPY header ({exc})") \
            from None
    return shape, dtype


def _check_shape(shape: tuple[int, ...], where: str, max_points: int | None) -> None:
    n = shape[0] if shape else 1
    if max_points is not None and (n > max_points or math.prod(shape) > 64 * max_points):
        raise ProblemError("cloud-too-large", f"{where} declares shape {shape}, more than the "
                           f"{max_points} points this service accepts (CURVATURE_MAX_POINTS)")


def check_numpy_file(path: Path, display_name: str, max_points: int | None) -> None:
    """Refuse an ``.npy``/``.npz`` file whose declared shape or compression gives it away.

    Raises
    ------
    ProblemError
        ``cloud-too-large`` for a declared shape above ``max_points`` points,
        ``malformed-file`` for a member that expands more than ``MAX_COMPRESSION_RATIO``
        times or an unreadable header.
    """
    ext = path.suffix.lower()
    if ext == ".npy":
        with open(path, "rb") as fh:
            shape, _ = _declared_shape(fh, display_name)
        _check_shape(shape, display_name, max_points)
        return
    if ext != ".npz":
        return
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ProblemError("malformed-file", f"{display_name}: not a readable NPZ archive "
                           f"({exc})") from None
    with archive:
        for info in archive.infolist():
            where = f"{display_name}: member {info.filename!r}"
            ratio = info.file_size / max(info.compress_size, 1)
            if info.file_size > _RATIO_FLOOR_BYTES and ratio > MAX_COMPRESSION_RATIO:
                raise ProblemError("malformed-file", (
                    f"{where} expands {ratio:.0f} times ({info.compress_size} to "
                    f"{info.file_size} bytes); at most {MAX_COMPRESSION_RATIO} is accepted "
                    "(a decompression bomb?)"))
            if not info.filename.endswith(".npy"):
                continue
            try:
                with archive.open(info) as member:
                    shape, dtype = _declared_shape(member, where)
            except (zipfile.BadZipFile, OSError, EOFError) as exc:  # e.g. a bad deflate stream
                raise ProblemError("malformed-file", f"{where}: unreadable ({exc})") from None
            _check_shape(shape, where, max_points)
            if math.prod(shape) * dtype.itemsize > info.file_size:
                raise ProblemError("malformed-file", f"{where} declares shape {shape} of "
                                   f"{dtype}, more than its {info.file_size} bytes hold")
