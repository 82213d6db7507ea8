"""Subsets of a cloud: grid cell keys (the default estimator's anchors, one point per cell) and
an order-independent random thinning (its fits on clouds sampled far more densely than their
noise: :class:`curvature.estimators.auto.AutoRun`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["grid_keys", "thinned"]


@njit(cache=True)
def cell_ijk(p, origin, cell, t):
    """Grid index of coordinate ``p`` along axis ``t`` (clamped at 0)."""
    return max(np.int64(np.floor((p - origin[t]) / cell)), 0)


@njit(cache=True)
def grid_keys(points, origin, cell):
    """One integer key per point naming its grid cell (21 bits an axis).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    origin : ndarray, shape (3,)
        Grid corner (no point below it on any axis).
    cell : float
        Cell size.

    Returns
    -------
    ndarray, shape (n,), int64
    """
    n = points.shape[0]
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = ((cell_ijk(points[i, 0], origin, cell, 0) << 42)
                  | (cell_ijk(points[i, 1], origin, cell, 1) << 21)
                  | cell_ijk(points[i, 2], origin, cell, 2))
    return key


@njit(cache=True)
def _mix(x):
    """splitmix64's finalizer (Steele, Lea & Flood, OOPSLA 2014): a well-spread 64-bit hash."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def thinned(points, share, keep):
    """Keep each point with probability ``share``, decided by a hash of its coordinates.

    The choice depends on a point's coordinates only (their mantissas and signs), so it is the
    same for any point order, in every tile of a cloud and after scaling by a power of two, and
    unlike a grid it thins a thick noisy layer evenly.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    share : float
        Kept fraction, in (0, 1].
    keep : ndarray, shape (n,), bool
        Candidates; set False where a point is dropped (in place).
    """
    # Mantissas and signs only: scaling by a power of two keeps the same points.
    bits = points.view(np.uint64) & np.uint64(0x800FFFFFFFFFFFFF)
    limit = np.uint64(min(share, 1.0) * 18446744073709549568.0)  # just below 2**64
    for i in range(points.shape[0]):
        h = _mix(bits[i, 0] ^ _mix(bits[i, 1] ^ _mix(bits[i, 2] + np.uint64(0x9E3779B97F4A7C15))))
        if h >= limit:
            keep[i] = False
