"""k nearest neighbors (DESIGN.md section 4.4)."""

from __future__ import annotations

import numpy as np

from ..params import ParamSpec
from .base import NeighborFinder, Neighborhoods


def knn_query(tree, points: np.ndarray, idx: np.ndarray, k: int,
              workers: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest other points of each query point, nearest first.

    Parameters
    ----------
    tree : scipy.spatial.cKDTree
        Tree over ``points``.
    points : ndarray, shape (n, 3)
    idx : ndarray, shape (m,)
        Query indices.
    k : int
        Neighbors wanted (clipped to n - 1).
    workers : int
        Threads for the tree query.

    Returns
    -------
    nbr : ndarray, shape (m, k), int64
        Neighbor indices; the query point itself removed even among exact duplicates.
    dist : ndarray, shape (m, k), float64
        Their distances.
    """
    n = points.shape[0]
    kk = min(k + 1, n)
    dist, nbr = tree.query(points[idx], k=kk, workers=workers)
    dist = np.asarray(dist).reshape(len(idx), kk)
    nbr = np.asarray(nbr).reshape(len(idx), kk)
    # Drop the query point itself; with duplicate coordinates it need not come first.
    is_self = nbr == idx[:, None]
    has_self = is_self.any(axis=1)
    # Rows without self (k+1 duplicates) drop their farthest entry instead.
    is_self[~has_self, -1] = True
    keep = ~is_self
    nbr = nbr[keep].reshape(len(idx), kk - 1)
    dist = dist[keep].reshape(len(idx), kk - 1)
    return nbr, dist


class KnnFinder(NeighborFinder):
    """The ``k`` nearest neighbors of each point."""

    name = "knn"
    PARAMS = (
        ParamSpec("k", int, 24, 5, 1024, "number of nearest neighbors (the paper uses 10 and 24)"),
    )

    def query(self, idx: np.ndarray, workers: int = 1) -> Neighborhoods:
        idx = np.asarray(idx, dtype=np.int64)
        nbr, _ = knn_query(self.tree, self.points, idx, self.params["k"], workers)
        m, k = nbr.shape
        indptr = np.arange(0, (m + 1) * k, k, dtype=np.int64)[: m + 1]
        return Neighborhoods(indptr, nbr.astype(np.int32).ravel())
