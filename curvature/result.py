"""The per-point curvature result."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .status import STATUS_NAMES

SCALAR_FIELDS = ("k1", "k2", "mean", "gaussian", "residual", "k1_std", "k2_std", "mean_std")
VECTOR_FIELDS = ("normals", "dir1", "dir2")
INT_FIELDS = ("neighbor_count", "status", "uncertain")
#: Standard errors, optional when a result is built (NaN when unknown, e.g. an older file).
STD_FIELDS = ("k1_std", "k2_std", "mean_std")


def shape_index(k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """Koenderink's shape index S in [-1, 1], dimensionless.

    S = (2 / pi) arctan((k1 + k2) / (k1 - k2)): +1 a convex cap, 0.5 a ridge, 0 a
    symmetric saddle, -0.5 a valley (rut), -1 a cup, with this package's sign (positive
    where the surface bends away from the oriented normal). Umbilics (k1 = k2) get +-1 by
    the sign of H; flat points (k1 = k2 = 0) have no shape and are NaN.

    Parameters
    ----------
    k1, k2 : ndarray, shape (n,)
        Principal curvatures, k1 >= k2 (NaN allowed).

    Returns
    -------
    ndarray, shape (n,), float64
    """
    k1 = np.asarray(k1, dtype=np.float64)
    k2 = np.asarray(k2, dtype=np.float64)
    with np.errstate(all="ignore"):
        s = (2.0 / np.pi) * np.arctan2(k1 + k2, k1 - k2)
    s[(k1 == 0) & (k2 == 0)] = np.nan
    return s


def curvedness(k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """Koenderink's curvedness C = sqrt((k1^2 + k2^2) / 2), shape (n,), 1/length unit."""
    k1 = np.asarray(k1, dtype=np.float64)
    k2 = np.asarray(k2, dtype=np.float64)
    return np.sqrt(0.5 * (k1 * k1 + k2 * k2))


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
    k1_std, k2_std, mean_std : ndarray, shape (n,), float64
        Standard errors of k1, k2 and H, in their unit, from the fit that produced them
        (:mod:`curvature.uncertainty`). NaN where ``status != 0``.
    uncertain : ndarray, shape (n,), uint8
        1 where the estimate is not to be trusted (:func:`curvature.uncertainty.uncertain`:
        a standard error above a share of the curvature, a thin neighborhood, or no estimate
        at all), else 0.
    faces : ndarray, shape (m, 3), int64, or None
        Input faces, kept so a result PLY keeps the mesh.
    info : dict
        Method, fit, parameters and timings.
    attributes : dict of str to ndarray, shape (n,)
        Per-point input attributes carried through unchanged (colours, intensity, user
        fields) and ``index``, each point's position in the input file (for an organized
        scan also ``row`` and ``col`` of its grid cell).
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
    k1_std: np.ndarray | None = None
    k2_std: np.ndarray | None = None
    mean_std: np.ndarray | None = None
    uncertain: np.ndarray | None = None
    faces: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        n = np.shape(self.k1)[0]
        for name in STD_FIELDS:
            if getattr(self, name) is None:
                setattr(self, name, np.full(n, np.nan))
        if self.uncertain is None:
            self.uncertain = (np.asarray(self.status) != 0).astype(np.uint8)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def fields(self) -> dict[str, np.ndarray]:
        """Per-point arrays by name: scalars (n,), vectors (n, 3), ints (n,)."""
        names = SCALAR_FIELDS + VECTOR_FIELDS + INT_FIELDS
        return {name: getattr(self, name) for name in names}

    @property
    def index(self) -> np.ndarray:
        """Each point's position in the input file, shape (n,) int64 (``0 .. n-1`` if unset)."""
        if "index" in self.attributes:
            return np.asarray(self.attributes["index"], dtype=np.int64)
        return np.arange(len(self), dtype=np.int64)

    @property
    def shape_index(self) -> np.ndarray:
        """Koenderink's shape index, shape (n,): see :func:`shape_index`."""
        return shape_index(self.k1, self.k2)

    @property
    def curvedness(self) -> np.ndarray:
        """Koenderink's curvedness, shape (n,), 1/length unit: see :func:`curvedness`."""
        return curvedness(self.k1, self.k2)

    def derived_fields(self) -> dict[str, np.ndarray]:
        """Fields computed from k1 and k2 on demand: shape index and curvedness, (n,)."""
        return {"shape_index": self.shape_index, "curvedness": self.curvedness}

    def status_counts(self) -> dict[str, int]:
        """Number of points per status name, e.g. ``{"ok": 9998, "degenerate_fit": 2}``."""
        values, counts = np.unique(self.status, return_counts=True)
        return {STATUS_NAMES.get(int(v), str(int(v))): int(c) for v, c in zip(values, counts,
                                                                               strict=True)}
