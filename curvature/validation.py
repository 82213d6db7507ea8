"""Checks on global input; a bad cloud raises a clear CurvatureInputError."""

from __future__ import annotations

import numpy as np

from .errors import CurvatureInputError

MIN_POINTS = 10


def as_points(points, name: str = "points", min_points: int = MIN_POINTS) -> np.ndarray:
    """Return ``points`` as a C-contiguous float64 (n, 3) array or raise.

    Raises
    ------
    CurvatureInputError
        Wrong shape, empty, fewer than ``min_points`` rows, or a non-finite coordinate (the
        message names the first bad row).
    """
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CurvatureInputError(f"{name}: not a numeric array ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise CurvatureInputError(f"{name}: expected shape (n, 3), got {arr.shape}")
    if arr.shape[0] == 0:
        raise CurvatureInputError(f"{name}: the cloud is empty")
    if arr.shape[0] < min_points:
        raise CurvatureInputError(
            f"{name}: {arr.shape[0]} points, at least {min_points} are needed")
    finite = np.isfinite(arr).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise CurvatureInputError(
            f"{name}: {bad.size} row(s) with NaN or Inf coordinates, first at row {bad[0]}")
    return np.ascontiguousarray(arr)


def as_vectors(values, n: int, name: str) -> np.ndarray:
    """Per-point 3-vectors (normals) as float64 (n, 3); rows may be NaN (then ignored)."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CurvatureInputError(f"{name}: not a numeric array ({exc})") from None
    if arr.shape != (n, 3):
        raise CurvatureInputError(f"{name}: expected shape ({n}, 3), got {arr.shape}")
    return np.ascontiguousarray(arr)


def as_faces(faces, n: int) -> np.ndarray | None:
    """Triangle indices as int64 (m, 3), checked against the number of points."""
    if faces is None:
        return None
    arr = np.asarray(faces)
    if arr.size == 0:
        return None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise CurvatureInputError(f"faces: expected shape (m, 3), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        if not np.all(np.equal(np.mod(arr, 1), 0)):
            raise CurvatureInputError("faces: indices must be whole numbers")
    arr = arr.astype(np.int64)
    bad = (arr < 0) | (arr >= n)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise CurvatureInputError(
            f"faces: row {row} refers to vertex {arr[row].tolist()} outside 0..{n - 1}")
    return arr
