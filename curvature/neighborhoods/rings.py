"""Ring neighborhoods over a vertex graph (DESIGN.md section 4.3).

The 1-ring of p is the set of vertices adjacent to p; the (r+1)-ring adds every vertex adjacent
to the r-ring that is neither p nor in an earlier ring. Rings are added whole until at least
``min_neighbors`` vertices are gathered or the connected component is exhausted. Neighbors are
listed ring by ring, in order of discovery (frontier order, then increasing vertex index).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .base import Neighborhoods
from .candidates import index_dtype

# Parallel runs use at most this many slices, each with a marker array of n bytes.
MAX_SLICES = 64


@njit(cache=True)
def _grow(indptr, indices, p, min_nb, buf, mark):
    """Rings around p; returns ``(count, buf)`` (``buf`` grows when needed, ``mark`` is reset)."""
    total = 0
    mark[p] = True
    # Frontier buf[lo:hi]; the first frontier is p itself (slot -1), so ring 1 is its edges.
    lo = -1
    hi = 0
    while total < min_nb and hi > lo:
        for f in range(lo, hi):
            u = p if f < 0 else buf[f]
            for e in range(indptr[u], indptr[u + 1]):
                v = indices[e]
                if not mark[v]:
                    mark[v] = True
                    if total == buf.shape[0]:
                        nb = np.empty(2 * buf.shape[0] + 16, np.int64)
                        nb[:total] = buf[:total]
                        buf = nb
                    buf[total] = v
                    total += 1
        lo = hi
        hi = total
    mark[p] = False
    for i in range(total):
        mark[buf[i]] = False
    return total, buf


@njit(cache=True)
def _count_range(indptr, indices, idx, order, lo, hi, min_nb, counts):
    mark = np.zeros(indptr.shape[0] - 1, np.bool_)
    buf = np.empty(64, np.int64)
    for q in range(lo, hi):
        t = order[q]
        c, buf = _grow(indptr, indices, idx[t], min_nb, buf, mark)
        counts[t] = c


@njit(cache=True)
def _fill_range(indptr, indices, idx, order, lo, hi, min_nb, out_ptr, out):
    mark = np.zeros(indptr.shape[0] - 1, np.bool_)
    buf = np.empty(64, np.int64)
    for q in range(lo, hi):
        t = order[q]
        c, buf = _grow(indptr, indices, idx[t], min_nb, buf, mark)
        s = out_ptr[t]
        for i in range(c):
            out[s + i] = buf[i]


@njit(cache=True, parallel=True)
def _count_parallel(indptr, indices, idx, order, bounds, min_nb, counts):
    for b in prange(bounds.shape[0] - 1):
        _count_range(indptr, indices, idx, order, bounds[b], bounds[b + 1], min_nb, counts)


@njit(cache=True, parallel=True)
def _fill_parallel(indptr, indices, idx, order, bounds, min_nb, out_ptr, out):
    for b in prange(bounds.shape[0] - 1):
        _fill_range(indptr, indices, idx, order, bounds[b], bounds[b + 1], min_nb, out_ptr, out)


def ring_neighborhoods(indptr: np.ndarray, indices: np.ndarray, idx: np.ndarray,
                       min_neighbors: int, parallel: bool = False,
                       rank: np.ndarray | None = None) -> Neighborhoods:
    """Rings around each query vertex until at least ``min_neighbors`` are gathered.

    Parameters
    ----------
    indptr : ndarray, shape (n + 1,), int64
        Vertex graph in CSR (symmetric, no self loops).
    indices : ndarray, shape (nnz,), int64
    idx : ndarray, shape (m,), int64
        Query vertices.
    min_neighbors : int
    parallel : bool
        Use the threaded kernels (same result).
    rank : ndarray, shape (n,), int64, optional
        A spatial order of the vertices; queries are processed in this order for memory
        locality (same result).

    Returns
    -------
    Neighborhoods
        CSR; the query vertex itself is not listed.
    """
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    n = indptr.shape[0] - 1
    m = idx.size
    counts = np.zeros(m, np.int64)
    if rank is None:
        order = np.arange(m, dtype=np.int64)
    else:
        order = np.argsort(rank[idx], kind="stable")
    slices = min(MAX_SLICES, max(1, m // 2048)) if parallel else 1
    bounds = np.linspace(0, m, slices + 1).astype(np.int64)
    if slices > 1:
        _count_parallel(indptr, indices, idx, order, bounds, min_neighbors, counts)
    else:
        _count_range(indptr, indices, idx, order, 0, m, min_neighbors, counts)
    out_ptr = np.zeros(m + 1, np.int64)
    np.cumsum(counts, out=out_ptr[1:])
    out = np.empty(int(out_ptr[-1]), np.int64)
    if slices > 1:
        _fill_parallel(indptr, indices, idx, order, bounds, min_neighbors, out_ptr, out)
    else:
        _fill_range(indptr, indices, idx, order, 0, m, min_neighbors, out_ptr, out)
    return Neighborhoods(out_ptr, out.astype(index_dtype(n)))
