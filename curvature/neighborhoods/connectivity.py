"""Vertex connectivity for the ``mesh`` method: from faces, or from the cloud alone.

Without faces every point gets the Delaunay neighbors of a local triangulation in its tangent
plane (k nearest neighbors, PCA plane, 2D Delaunay of the projected points), and the graph is
made symmetric (an edge when either end lists the other). p's Delaunay neighbors are found
without triangulating: they are exactly the points whose perpendicular bisector with p bounds
p's Voronoi cell, so the cell is cut out of a large square by the half-planes
``z . y_j <= |y_j|^2 / 2`` (p at the origin) and the labels of its edges are read off.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..fitting.linalg import jacobi_eigh
from .candidates import BLOCK
from .kdtree import knn_point, knn_scratch, query_order

# The starting square is this many times the farthest projected neighbor; cells of points on
# the hull of their neighborhood are unbounded and get cut there.
BOX_FACTOR = 1.0e3
# Voronoi edges shorter than this times the farthest projected neighbor do not count
# (cocircular neighbors, e.g. on a grid, give edges of zero length up to rounding).
EDGE_TOL = 1.0e-9


@njit(cache=True)
def _edges_to_csr(src, dst, n):
    ptr = np.zeros(n + 1, np.int64)
    for e in range(src.shape[0]):
        if src[e] != dst[e]:
            ptr[src[e] + 1] += 1
            ptr[dst[e] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:n].copy()
    tmp = np.empty(ptr[n], np.int64)
    for e in range(src.shape[0]):
        a = src[e]
        b = dst[e]
        if a != b:
            tmp[fill[a]] = b
            fill[a] += 1
            tmp[fill[b]] = a
            fill[b] += 1
    indptr = np.zeros(n + 1, np.int64)
    out = np.empty(ptr[n], np.int64)
    w = 0
    for v in range(n):
        s = ptr[v]
        e = ptr[v + 1]
        # shell sort of the row (insertion sort for the usual short rows)
        gap = 1
        while 3 * gap + 1 < e - s:
            gap = 3 * gap + 1
        while gap >= 1:
            for i in range(s + gap, e):
                x = tmp[i]
                j = i
                while j >= s + gap and tmp[j - gap] > x:
                    tmp[j] = tmp[j - gap]
                    j -= gap
                tmp[j] = x
            gap //= 3
        for i in range(s, e):
            if i == s or tmp[i] != tmp[i - 1]:
                out[w] = tmp[i]
                w += 1
        indptr[v + 1] = w
    return indptr, out[:w].copy()


def edges_to_csr(src: np.ndarray, dst: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric adjacency in CSR from an edge list (both directions kept, no self loops).

    Parameters
    ----------
    src, dst : ndarray, shape (e,), int64
        Edge ends; each edge may appear in one or both directions, repeatedly.
    n : int
        Number of vertices.

    Returns
    -------
    indptr : ndarray, shape (n + 1,), int64
    indices : ndarray, shape (nnz,), int64
        Neighbors of vertex ``v`` are ``indices[indptr[v]:indptr[v + 1]]``, increasing.
    """
    src = np.ascontiguousarray(src, dtype=np.int64)
    dst = np.ascontiguousarray(dst, dtype=np.int64)
    return _edges_to_csr(src, dst, n)


def face_graph(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Edge graph of a triangle mesh: vertices are adjacent when they share an edge.

    Parameters
    ----------
    faces : ndarray, shape (f, 3), int64
    n : int
        Number of vertices.

    Returns
    -------
    indptr : ndarray, shape (n + 1,), int64
    indices : ndarray, shape (nnz,), int64
    """
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    src = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    dst = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    return edges_to_csr(src, dst, n)


@njit(cache=True)
def voronoi_neighbors(yx, yy, flags, vx, vy, vl, s, wx, wy, wl):
    """Which neighbors are Delaunay neighbors of a point at the origin, in the plane.

    Parameters
    ----------
    yx, yy : ndarray, shape (k,), float64
        Neighbor coordinates relative to the point.
    flags : ndarray, shape (k,), bool
        Output: True for the Delaunay neighbors (of the triangulation of the point and the k
        neighbors).
    vx, vy, s, wx, wy : ndarray, shape (>= k + 5,), float64
        Scratch.
    vl, wl : ndarray, shape (>= k + 5,), int64
        Scratch.

    Returns
    -------
    int
        Number of Delaunay neighbors found.
    """
    k = yx.shape[0]
    rmax = 0.0
    for j in range(k):
        flags[j] = False
        r = np.sqrt(yx[j] * yx[j] + yy[j] * yy[j])
        if r > rmax:
            rmax = r
    if not rmax > 0.0:
        return 0
    big = BOX_FACTOR * rmax
    # the cell, counter-clockwise; vl[i] labels the edge from vertex i to vertex i + 1
    vx[0] = -big
    vy[0] = -big
    vx[1] = big
    vy[1] = -big
    vx[2] = big
    vy[2] = big
    vx[3] = -big
    vy[3] = big
    for i in range(4):
        vl[i] = -1
    nv = 4
    for j in range(k):
        ax = yx[j]
        ay = yy[j]
        h = 0.5 * (ax * ax + ay * ay)
        if not h > 0.0:
            continue  # a duplicate of the point bounds nothing
        cut = False
        for i in range(nv):
            s[i] = vx[i] * ax + vy[i] * ay - h
            if s[i] > 0.0:
                cut = True
        if not cut:
            continue
        nw = 0
        for i in range(nv):
            i2 = i + 1 if i + 1 < nv else 0
            sa = s[i]
            sb = s[i2]
            if sa <= 0.0:
                wx[nw] = vx[i]
                wy[nw] = vy[i]
                wl[nw] = vl[i]
                nw += 1
                if sb > 0.0:
                    tp = sa / (sa - sb)
                    wx[nw] = vx[i] + tp * (vx[i2] - vx[i])
                    wy[nw] = vy[i] + tp * (vy[i2] - vy[i])
                    wl[nw] = j
                    nw += 1
            elif sb <= 0.0:
                tp = sa / (sa - sb)
                wx[nw] = vx[i] + tp * (vx[i2] - vx[i])
                wy[nw] = vy[i] + tp * (vy[i2] - vy[i])
                wl[nw] = vl[i]
                nw += 1
        for i in range(nw):
            vx[i] = wx[i]
            vy[i] = wy[i]
            vl[i] = wl[i]
        nv = nw
    tol = EDGE_TOL * rmax
    found = 0
    for i in range(nv):
        lab = vl[i]
        if lab < 0:
            continue
        i2 = i + 1 if i + 1 < nv else 0
        dx = vx[i2] - vx[i]
        dy = vy[i2] - vy[i]
        if np.sqrt(dx * dx + dy * dy) > tol and not flags[lab]:
            flags[lab] = True
            found += 1
    return found


@njit(cache=True)
def tangent_frame(points, p, ids, k):
    """Unit tangent vectors of the PCA plane of ``points[p]`` and ``points[ids[:k]]``.

    Returns
    -------
    t1, t2 : ndarray, shape (3,), float64
        Eigenvectors of the two largest eigenvalues of the neighborhood's covariance.
    """
    c = np.zeros(3)
    for d in range(3):
        c[d] = points[p, d]
    for i in range(k):
        for d in range(3):
            c[d] += points[ids[i], d]
    c /= k + 1
    cov = np.zeros((3, 3))
    for i in range(-1, k):
        q = p if i < 0 else ids[i]
        x0 = points[q, 0] - c[0]
        x1 = points[q, 1] - c[1]
        x2 = points[q, 2] - c[2]
        cov[0, 0] += x0 * x0
        cov[0, 1] += x0 * x1
        cov[0, 2] += x0 * x2
        cov[1, 1] += x1 * x1
        cov[1, 2] += x1 * x2
        cov[2, 2] += x2 * x2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    _, vecs = jacobi_eigh(cov)
    return vecs[:, 2].copy(), vecs[:, 1].copy()


@njit(cache=True)
def _delaunay_range(points, tree, idx, order, lo, hi, k, nbr, flags):
    """Local tangent-plane Delaunay neighbors of ``idx[order[lo:hi]]`` into ``nbr``/``flags``.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        :func:`.kdtree.build_tree` over ``points``.
    idx : ndarray, shape (m,), int64
    order : ndarray, shape (m,), int64
        Processing order (results do not depend on it).
    lo, hi : int
    k : int
        Neighbors triangulated with each point, ``1 <= k <= n - 1``.
    nbr : ndarray, shape (m, k), int64
        Output: the k nearest neighbors, nearest first.
    flags : ndarray, shape (m, k), bool
        Output: True for the Delaunay neighbors.
    """
    snode, sdist, bufd, bufi = knn_scratch(tree, k)
    ds = np.empty(k)
    ids = np.empty(k, np.int64)
    yx = np.empty(k)
    yy = np.empty(k)
    f = np.empty(k, np.bool_)
    vx = np.empty(k + 5)
    vy = np.empty(k + 5)
    s = np.empty(k + 5)
    wx = np.empty(k + 5)
    wy = np.empty(k + 5)
    vl = np.empty(k + 5, np.int64)
    wl = np.empty(k + 5, np.int64)
    for q in range(lo, hi):
        t = order[q]
        p = idx[t]
        knn_point(points, tree, p, k, ds, ids, snode, sdist, bufd, bufi)
        t1, t2 = tangent_frame(points, p, ids, k)
        for i in range(k):
            c = ids[i]
            x0 = points[c, 0] - points[p, 0]
            x1 = points[c, 1] - points[p, 1]
            x2 = points[c, 2] - points[p, 2]
            yx[i] = x0 * t1[0] + x1 * t1[1] + x2 * t1[2]
            yy[i] = x0 * t2[0] + x1 * t2[1] + x2 * t2[2]
        voronoi_neighbors(yx, yy, f, vx, vy, vl, s, wx, wy, wl)
        for i in range(k):
            nbr[t, i] = ids[i]
            flags[t, i] = f[i]


@njit(cache=True, parallel=True)
def _delaunay_parallel(points, tree, idx, order, k, nbr, flags):
    """:func:`_delaunay_range` over all queries, blocks of :data:`BLOCK` queries in parallel."""
    m = idx.shape[0]
    nblocks = (m + BLOCK - 1) // BLOCK
    for blk in prange(nblocks):
        _delaunay_range(points, tree, idx, order, blk * BLOCK, min(m, (blk + 1) * BLOCK), k,
                        nbr, flags)


def tangent_delaunay(points: np.ndarray, tree: tuple, k: int, parallel: bool = False,
                     idx: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each point's Delaunay neighbors in its local tangent-plane triangulation (one-sided).

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        :func:`.kdtree.build_tree` over ``points``.
    k : int
        Nearest neighbors triangulated with each point (clipped to n - 1).
    parallel : bool
        Use the threaded kernel (same result).
    idx : ndarray, shape (m,), int64, optional
        Points to handle (all by default).

    Returns
    -------
    nbr : ndarray, shape (m, k), int64
        The k nearest neighbors of each point, nearest first.
    flags : ndarray, shape (m, k), bool
        True where the neighbor is a Delaunay neighbor of the point.
    """
    n = points.shape[0]
    if idx is None:
        idx = np.arange(n, dtype=np.int64)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    k = min(k, n - 1)
    nbr = np.empty((idx.size, max(k, 0)), np.int64)
    flags = np.zeros((idx.size, max(k, 0)), np.bool_)
    if k < 1:
        return nbr, flags
    order = query_order(tree, idx)
    if parallel:
        _delaunay_parallel(points, tree, idx, order, k, nbr, flags)
    else:
        _delaunay_range(points, tree, idx, order, 0, idx.size, k, nbr, flags)
    return nbr, flags


def cloud_graph(points: np.ndarray, tree: tuple, k: int,
                parallel: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric tangent-plane Delaunay graph of a cloud (edge when either end lists the other).

    Returns
    -------
    indptr : ndarray, shape (n + 1,), int64
    indices : ndarray, shape (nnz,), int64
    """
    n = points.shape[0]
    nbr, flags = tangent_delaunay(points, tree, k, parallel)
    src = np.repeat(np.arange(n, dtype=np.int64), flags.sum(axis=1))
    return edges_to_csr(src, nbr[flags], n)
