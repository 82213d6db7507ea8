"""The per-point curvature result."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .status import STATUS_NAMES

SCALAR_FIELDS = ("k1", "k2", "mean", "gaussian", "residual")
VECTOR_FIELDS = ("normals", "dir1", "dir2")
INT_FIELDS = ("neighbor_count", "status")


@dataclass
class CurvatureResult:
    """Curvature of every input point, in input order (DESIGN.md section 5).

    Attributes
    ----------
    points : ndarray, shape (n, 3), float64
        The input coordinates (unchanged).
    k1, k2 : ndarray, shape (n,), float64
        Principal curvatures, k1 >= k2, in 1/(input length unit). Positive where the surface
        bends away from the oriented normal. NaN where ``status != 0``.
    mean, gaussian : ndarray, shape (n,), float64
        H = (k1 + k2) / 2 and K = k1 * k2. NaN where ``status != 0``.
    normals : ndarray, shape (n, 3), float64
        Oriented unit normals at the foot point. NaN where no fit was possible.
    dir1, dir2 : ndarray, shape (n, 3), float64
        Unit principal directions of k1 and k2. NaN where ``status != 0``.
    neighbor_count : ndarray, shape (n,), int32
        Number of neighbors found for the point (the point itself not counted).
    status : ndarray, shape (n,), int8
        0 ok, 1 too few neighbors, 2 degenerate fit, 3 no foot point, 4 non-finite result.
    residual : ndarray, shape (n,), float64
        RMS distance of the fitted points to the fitted surface (first-order distance).
    faces : ndarray, shape (m, 3), int64, or None
        Input faces, kept so a result PLY keeps the mesh.
    info : dict
        Method, fit, parameters and timings.
    """

    points: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    mean: np.ndarray
    gaussian: np.ndarray
    normals: np.ndarray
    dir1: np.ndarray
    dir2: np.ndarray
    neighbor_count: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    faces: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def fields(self) -> dict[str, np.ndarray]:
        """Per-point arrays by name: scalars (n,), vectors (n, 3), ints (n,)."""
        names = SCALAR_FIELDS + VECTOR_FIELDS + INT_FIELDS
        return {name: getattr(self, name) for name in names}

    def status_counts(self) -> dict[str, int]:
        """Number of points per status name, e.g. ``{"ok": 9998, "degenerate_fit": 2}``."""
        values, counts = np.unique(self.status, return_counts=True)
        return {STATUS_NAMES.get(int(v), str(int(v))): int(c) for v, c in zip(values, counts,
                                                                               strict=True)}
