"""Final checks shared by every reader: enough points, finite coordinates, sound faces.

Readers hand over raw arrays plus a *locator* that turns a row number into the place in the
file (``{"line": 12}`` for text, ``{"offset": 4096}`` for binary), so an error can say where.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..cloud import PointCloud
from ..errors import NonFiniteError, TooFewPointsError
from ..validation import MIN_POINTS

Locator = Callable[[int], dict]


def no_location(row: int) -> dict:
    """Locator for arrays that have no line or byte position worth naming."""
    return {}


def finish_cloud(source, points, *, normals=None, faces=None, properties=None, dropped=0,
                 where: Locator = no_location, label: str = "row") -> PointCloud:
    """Check the decoded arrays and wrap them in a :class:`PointCloud`.

    Parameters
    ----------
    source : str or None
        File name for messages.
    points : array_like, shape (n, 3)
        Coordinates; converted to C-contiguous float64.
    normals : array_like, shape (n, 3), optional
    faces : ndarray, shape (m, 3), int64, optional
        Already triangulated and range-checked (see :func:`curvature.io.faces.triangulate`).
    properties : dict of str to ndarray, shape (n,), optional
    dropped : int
        Rows the reader dropped (NaN rows of organized PCD scans).
    where : callable
        Maps a point row to ``line=``/``offset=`` keyword arguments for :class:`FormatError`.
    label : str
        What a row is called in messages ("row", "vertex", "point").

    Raises
    ------
    FormatError
        No points, fewer than ``MIN_POINTS``, or a NaN/Inf coordinate (names the first one).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n = pts.shape[0]
    if n == 0:
        raise TooFewPointsError(source, "the file holds no points")
    if n < MIN_POINTS:
        raise TooFewPointsError(source, f"only {n} points, at least {MIN_POINTS} are needed")
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        row = int(bad[0])
        raise NonFiniteError(
            source, f"{label} {row} has a NaN or Inf coordinate {pts[row].tolist()} "
                    f"({bad.size} of {n} {label} rows are non-finite)", **where(row))
    if normals is not None:
        normals = np.ascontiguousarray(normals, dtype=np.float64)
    props = {}
    for name, values in (properties or {}).items():
        props[name] = np.ascontiguousarray(values)
    return PointCloud(points=pts, normals=normals, faces=faces, properties=props,
                      dropped=int(dropped), source=source)
