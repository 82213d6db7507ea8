"""Consistent normal orientation (DESIGN.md 4.6).

A fitted normal's sign is arbitrary; these functions return a sign per point (+1 keeps the
fitted normal, -1 flips it) and :func:`apply_signs` flips normals, curvatures and directions.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree

# Neighbors per point in the graph the orientation propagates over (the nearest ones).
ORIENT_K = 8


def signs_from_normals(est: np.ndarray, given: np.ndarray) -> np.ndarray:
    """Signs making estimated normals agree with given ones.

    Parameters
    ----------
    est, given : ndarray, shape (n, 3)
        Estimated and reference normals; NaN rows keep the fitted sign.

    Returns
    -------
    ndarray, shape (n,), int8
    """
    dot = np.einsum("ij,ij->i", est, given)
    return np.where(dot < 0, -1, 1).astype(np.int8)


def signs_from_viewpoint(points: np.ndarray, est: np.ndarray, viewpoint) -> np.ndarray:
    """Signs making normals face ``viewpoint`` (3,), e.g. the scanner position."""
    to_view = np.asarray(viewpoint, np.float64)[None, :] - points
    return signs_from_normals(est, to_view)


def first_neighbors(nbhd, k: int = None) -> np.ndarray:
    """The first ``k`` neighbors of each query point of a CSR neighborhood, -1 padded.

    Every method lists neighbors nearest first (or ring by ring), so these make a local graph
    for orientation without a second neighbor search.

    Parameters
    ----------
    nbhd : Neighborhoods
        m query points.
    k : int
        Columns wanted (default ``ORIENT_K``).

    Returns
    -------
    ndarray, shape (m, k), int32
    """
    k = ORIENT_K if k is None else k
    sizes = nbhd.sizes()
    take = np.minimum(sizes, k)
    out = np.full((len(sizes), k), -1, np.int32)
    cols = np.arange(k)[None, :]
    mask = cols < take[:, None]
    pos = (nbhd.indptr[:-1, None] + cols)[mask]
    out[mask] = nbhd.indices[pos]
    return out


def signs_auto(points: np.ndarray, est: np.ndarray, graph: np.ndarray) -> np.ndarray:
    """Propagate a consistent orientation over a minimum spanning tree.

    The graph joins each point to its first neighbors with weight 1 - |ni . nj|, so the tree
    prefers edges between nearly parallel normals, where a flip is unambiguous (Hoppe et al.,
    SIGGRAPH 1992). Each connected component is seeded at the point farthest from its
    centroid, with the normal pointing away from the centroid (outward on closed surfaces).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    est : ndarray, shape (n, 3)
        Unit normals of arbitrary sign; NaN rows are left out of the graph.
    graph : ndarray, shape (n, k), int
        Neighbor indices per point, -1 for none (see :func:`first_neighbors`).

    Returns
    -------
    ndarray, shape (n,), int8
    """
    n = points.shape[0]
    valid = np.isfinite(est).all(axis=1)
    indptr, indices, weights = weighted_graph(graph, est, valid)
    # The graph need not be symmetric: the spanning tree treats i->j and j->i as one undirected
    # edge, and their weights are equal, so the result does not depend on the point order.
    graph_csr = csr_matrix((weights, indices, indptr), shape=(n, n))
    tree_graph = minimum_spanning_tree(graph_csr)
    sym = (tree_graph + tree_graph.T).tocsr()
    n_comp, labels = connected_components(sym, directed=False)
    seeds = component_seeds(points, labels, n_comp, valid)
    centroids = component_centroids(points, labels, n_comp, valid)
    return propagate_signs(sym.indptr.astype(np.int64), sym.indices.astype(np.int64), est,
                           seeds, centroids[labels[seeds]], points)


@njit(cache=True)
def weighted_graph(graph, est, valid):
    """CSR arrays of the orientation graph with weights 1 - |ni . nj| (kept above zero).

    Parameters
    ----------
    graph : ndarray, shape (n, k), int
        Neighbor indices, -1 for none.
    est : ndarray, shape (n, 3)
        Unit normals.
    valid : ndarray, shape (n,), bool
        Points with a normal; edges touching others are left out.

    Returns
    -------
    indptr : ndarray, shape (n + 1,), int64
    indices : ndarray, shape (nnz,), int32
    weights : ndarray, shape (nnz,), float64
    """
    n, k = graph.shape
    indptr = np.zeros(n + 1, np.int64)
    indices = np.empty(n * k, np.int32)
    weights = np.empty(n * k)
    nnz = 0
    for i in range(n):
        if valid[i]:
            for t in range(k):
                j = graph[i, t]
                if j < 0 or j == i or not valid[j]:
                    continue
                dot = est[i, 0] * est[j, 0] + est[i, 1] * est[j, 1] + est[i, 2] * est[j, 2]
                # Zero weights would read as missing edges; keep them strictly positive.
                weights[nnz] = max(1.0 - abs(dot), 0.0) + 1e-12
                indices[nnz] = j
                nnz += 1
        indptr[i + 1] = nnz
    return indptr, indices[:nnz], weights[:nnz]


def component_centroids(points, labels, n_comp, valid) -> np.ndarray:
    """Centroid of the valid points of each component, shape (n_comp, 3)."""
    w = valid.astype(np.float64)
    counts = np.maximum(np.bincount(labels, weights=w, minlength=n_comp), 1.0)
    return np.stack([np.bincount(labels, weights=points[:, d] * w, minlength=n_comp) / counts
                     for d in range(3)], axis=1)


def component_seeds(points, labels, n_comp, valid) -> np.ndarray:
    """Index of each component's valid point farthest from its centroid, shape (c,)."""
    cent = component_centroids(points, labels, n_comp, valid)
    dist = np.linalg.norm(points - cent[labels], axis=1)
    dist[~valid] = -1.0
    # Sort by (label, -distance, index): the first entry of each label is its seed.
    order = np.lexsort((np.arange(len(labels)), -dist, labels))
    first = np.ones(len(order), bool)
    first[1:] = labels[order][1:] != labels[order][:-1]
    seeds = order[first]
    return seeds[valid[seeds]]


@njit(cache=True)
def propagate_signs(indptr, indices, normals, seeds, seed_centroids, points):
    """Breadth-first sign propagation over a spanning forest (CSR, symmetric).

    Returns
    -------
    ndarray, shape (n,), int8
        +1 or -1 per point; unreached points keep +1.
    """
    n = normals.shape[0]
    sign = np.ones(n, np.int8)
    seen = np.zeros(n, np.bool_)
    queue = np.empty(n, np.int64)
    for s in range(seeds.shape[0]):
        root = seeds[s]
        if seen[root]:
            continue
        out = 0.0
        for d in range(3):
            out += normals[root, d] * (points[root, d] - seed_centroids[s, d])
        sign[root] = 1 if out >= 0.0 else -1
        seen[root] = True
        head = 0
        tail = 0
        queue[tail] = root
        tail += 1
        while head < tail:
            i = queue[head]
            head += 1
            for e in range(indptr[i], indptr[i + 1]):
                j = indices[e]
                if seen[j]:
                    continue
                dot = 0.0
                for d in range(3):
                    dot += normals[i, d] * normals[j, d]
                sign[j] = sign[i] if dot >= 0.0 else -sign[i]
                seen[j] = True
                queue[tail] = j
                tail += 1
    return sign


def apply_signs(signs, k1, k2, normals, dir1, dir2) -> None:
    """Flip in place where ``signs`` is -1.

    Flipping the normal negates the curvatures and swaps their order (k1 >= k2 kept), so the
    directions swap too; d2 = n x d1 still holds afterwards.
    """
    flip = signs < 0
    old_k1 = k1[flip].copy()
    k1[flip] = -k2[flip]
    k2[flip] = -old_k1
    normals[flip] *= -1.0
    old_d1 = dir1[flip].copy()
    dir1[flip] = dir2[flip]
    dir2[flip] = old_d1
