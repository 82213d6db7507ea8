"""A small k-d tree in numba for the exact k nearest neighbors inside numba kernels.

The candidate-based finders query the k nearest points of every point from inside their numba
kernels (no Python round trip, no (m, k) arrays). The answer is exactly defined, whatever the
tree's shape: the k points q != p with the smallest ``(d2, index)`` pairs, where
``d2 = x0*x0 + x1*x1 + x2*x2`` and ``x = points[q] - points[p]`` in float64, in that order. The
bounding-box distance used for pruning never exceeds the ``d2`` of a point inside the box, also
in floating point, so pruning loses nothing.

The tree splits the widest side of each node's bounding box at its midpoint (a node whose
points coincide stays a leaf, so duplicates are harmless). Queries are best run in tree order
(:func:`query_order`): neighboring queries then touch the same memory.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

LEAF_SIZE = 12
# Up to this many neighbors, branch-free rank counting sorts the result fastest.
RANK_SORT_MAX = 48
# Queries per parallel task of knn_parallel (each task allocates its own scratch).
KNN_BLOCK = 64


@njit(cache=True)
def _grow_nodes(cap, nn, start, stop, left, right, level, bmin, bmax, stack):
    """Copies of the node arrays with room for ``cap`` nodes (the first ``nn`` kept)."""
    start2 = np.empty(cap, np.int64)
    stop2 = np.empty(cap, np.int64)
    left2 = np.full(cap, -1, np.int64)
    right2 = np.full(cap, -1, np.int64)
    level2 = np.zeros(cap, np.int64)
    bmin2 = np.empty((cap, 3))
    bmax2 = np.empty((cap, 3))
    stack2 = np.empty(cap, np.int64)
    start2[:nn] = start[:nn]
    stop2[:nn] = stop[:nn]
    left2[:nn] = left[:nn]
    right2[:nn] = right[:nn]
    level2[:nn] = level[:nn]
    bmin2[:nn] = bmin[:nn]
    bmax2[:nn] = bmax[:nn]
    stack2[:nn] = stack[:nn]
    return start2, stop2, left2, right2, level2, bmin2, bmax2, stack2


@njit(cache=True)
def _build(points, leaf_size):
    n = points.shape[0]
    perm = np.arange(n)
    cap = 64 + (4 * n) // max(1, leaf_size)
    start = np.empty(cap, np.int64)
    stop = np.empty(cap, np.int64)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    level = np.zeros(cap, np.int64)
    bmin = np.empty((cap, 3))
    bmax = np.empty((cap, 3))
    stack = np.empty(cap, np.int64)
    start[0] = 0
    stop[0] = n
    nn = 1
    top = 1
    stack[0] = 0
    depth = 0
    while top > 0:
        top -= 1
        node = stack[top]
        s = start[node]
        e = stop[node]
        for d in range(3):
            bmin[node, d] = np.inf
            bmax[node, d] = -np.inf
        for t in range(s, e):
            c = perm[t]
            for d in range(3):
                v = points[c, d]
                if v < bmin[node, d]:
                    bmin[node, d] = v
                if v > bmax[node, d]:
                    bmax[node, d] = v
        if level[node] > depth:
            depth = level[node]
        if e - s <= leaf_size:
            continue
        dim = 0
        ext = bmax[node, 0] - bmin[node, 0]
        for d in range(1, 3):
            if bmax[node, d] - bmin[node, d] > ext:
                ext = bmax[node, d] - bmin[node, d]
                dim = d
        if not ext > 0.0:
            continue  # all points coincide
        mid = 0.5 * (bmin[node, dim] + bmax[node, dim])
        i = s
        j = e - 1
        while i <= j:
            if points[perm[i], dim] < mid:
                i += 1
            else:
                tmp = perm[i]
                perm[i] = perm[j]
                perm[j] = tmp
                j -= 1
        if i == s or i == e:
            continue  # no split possible at this precision
        if nn + 2 > cap:
            cap = 2 * cap
            start, stop, left, right, level, bmin, bmax, stack = _grow_nodes(
                cap, nn, start, stop, left, right, level, bmin, bmax, stack)
        left[node] = nn
        right[node] = nn + 1
        start[nn] = s
        stop[nn] = i
        start[nn + 1] = i
        stop[nn + 1] = e
        level[nn] = level[node] + 1
        level[nn + 1] = level[node] + 1
        stack[top] = nn
        stack[top + 1] = nn + 1
        top += 2
        nn += 2
    rank = np.empty(n, np.int64)
    tpts = np.empty((n, 3))
    for t in range(n):
        rank[perm[t]] = t
        tpts[t, 0] = points[perm[t], 0]
        tpts[t, 1] = points[perm[t], 1]
        tpts[t, 2] = points[perm[t], 2]
    return (perm, rank, tpts, start[:nn].copy(), stop[:nn].copy(), left[:nn].copy(),
            right[:nn].copy(), bmin[:nn].copy(), bmax[:nn].copy(), depth)


def build_tree(points: np.ndarray, leaf_size: int = LEAF_SIZE) -> tuple:
    """Build the tree over ``points``.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    leaf_size : int
        Largest number of points in a leaf.

    Returns
    -------
    tuple
        ``(perm, rank, tpts, start, stop, left, right, bmin, bmax, depth)``: point order
        (n,), its inverse (n,), the points in that order (n, 3), node ranges into ``perm``
        (nodes,), children (-1 for leaves), bounding boxes (nodes, 3) and the depth of the
        tree. Pass it unchanged to :func:`knn_point`.
    """
    return _build(np.ascontiguousarray(points, dtype=np.float64), leaf_size)


@njit(cache=True, inline="always")
def _box_d2(bmin, bmax, node, px, py, pz):
    d = 0.0
    v = bmin[node, 0] - px
    if v > 0.0:
        d += v * v
    else:
        v = px - bmax[node, 0]
        if v > 0.0:
            d += v * v
    v = bmin[node, 1] - py
    if v > 0.0:
        d += v * v
    else:
        v = py - bmax[node, 1]
        if v > 0.0:
            d += v * v
    v = bmin[node, 2] - pz
    if v > 0.0:
        d += v * v
    else:
        v = pz - bmax[node, 2]
        if v > 0.0:
            d += v * v
    return d


@njit(cache=True, inline="always")
def _before(d1, i1, d2, i2):
    return d1 < d2 or (d1 == d2 and i1 < i2)


@njit(cache=True, inline="always")
def _sift_down(hd, hi, root, size):
    d = hd[root]
    c = hi[root]
    i = root
    while True:
        ch = 2 * i + 1
        if ch >= size:
            break
        if ch + 1 < size and _before(hd[ch], hi[ch], hd[ch + 1], hi[ch + 1]):
            ch += 1
        if _before(d, c, hd[ch], hi[ch]):
            hd[i] = hd[ch]
            hi[i] = hi[ch]
            i = ch
        else:
            break
    hd[i] = d
    hi[i] = c


@njit(cache=True)
def knn_point(points, tree, p, k, ds, ids, snode, sdist, bufd, bufi):
    """The k nearest points of ``points[p]`` other than p, sorted by ``(d2, index)``.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        From :func:`build_tree` over ``points``.
    p : int
        Query point index.
    k : int
        Neighbors wanted, ``1 <= k <= n - 1``.
    ds : ndarray, shape (>= k,), float64
        Output: squared distances, increasing.
    ids : ndarray, shape (>= k,), int64
        Output: indices.
    snode : ndarray, shape (>= depth + 2,), int64
        Scratch stack.
    sdist : ndarray, shape (>= depth + 2,), float64
        Scratch stack.
    bufd : ndarray, shape (>= k,), float64
        Scratch.
    bufi : ndarray, shape (>= k,), int64
        Scratch.

    Returns
    -------
    int
        ``k`` (fewer only if the cloud holds fewer other points).
    """
    perm, _, tpts, start, stop, left, right, bmin, bmax, _ = tree
    px = points[p, 0]
    py = points[p, 1]
    pz = points[p, 2]
    # ds/ids hold a max-heap on (d2, index) while searching
    size = 0
    bound = np.inf
    snode[0] = 0
    sdist[0] = _box_d2(bmin, bmax, 0, px, py, pz)
    top = 1
    while top > 0:
        top -= 1
        node = snode[top]
        if sdist[top] > bound:
            continue
        l = left[node]
        if l < 0:
            for t in range(start[node], stop[node]):
                c = perm[t]
                if c == p:
                    continue
                x0 = tpts[t, 0] - px
                x1 = tpts[t, 1] - py
                x2 = tpts[t, 2] - pz
                d = x0 * x0 + x1 * x1 + x2 * x2
                if size < k:
                    j = size
                    size += 1
                    while j > 0:
                        par = (j - 1) >> 1
                        if _before(ds[par], ids[par], d, c):
                            ds[j] = ds[par]
                            ids[j] = ids[par]
                            j = par
                        else:
                            break
                    ds[j] = d
                    ids[j] = c
                    if size == k:
                        bound = ds[0]
                elif _before(d, c, ds[0], ids[0]):
                    ds[0] = d
                    ids[0] = c
                    _sift_down(ds, ids, 0, k)
                    bound = ds[0]
        else:
            r = right[node]
            dl = _box_d2(bmin, bmax, l, px, py, pz)
            dr = _box_d2(bmin, bmax, r, px, py, pz)
            if dl <= dr:
                if dr <= bound:
                    snode[top] = r
                    sdist[top] = dr
                    top += 1
                if dl <= bound:
                    snode[top] = l
                    sdist[top] = dl
                    top += 1
            else:
                if dl <= bound:
                    snode[top] = l
                    sdist[top] = dl
                    top += 1
                if dr <= bound:
                    snode[top] = r
                    sdist[top] = dr
                    top += 1
    if size > RANK_SORT_MAX:
        # heapsort in place: O(k log k) where rank counting's O(k^2) would dominate
        for end in range(size - 1, 0, -1):
            d = ds[0]
            c = ids[0]
            ds[0] = ds[end]
            ids[0] = ids[end]
            ds[end] = d
            ids[end] = c
            _sift_down(ds, ids, 0, end)
        return size
    # sort by rank counting (branch free): increasing (d2, index)
    for i in range(size):
        bufd[i] = ds[i]
        bufi[i] = ids[i]
    for i in range(size):
        di = bufd[i]
        ii = bufi[i]
        rank = 0
        for j in range(size):
            rank += (bufd[j] < di) | ((bufd[j] == di) & (bufi[j] < ii))
        ds[rank] = di
        ids[rank] = ii
    return size


@njit(cache=True)
def knn_scratch(tree, k):
    """Scratch arrays ``(snode, sdist, bufd, bufi)`` for :func:`knn_point`."""
    depth = tree[9]
    return (np.empty(depth + 2, np.int64), np.empty(depth + 2), np.empty(k),
            np.empty(k, np.int64))


def query_order(tree: tuple, idx: np.ndarray) -> np.ndarray:
    """Order in which to process ``idx`` so that neighboring queries run together.

    Returns
    -------
    ndarray, shape (m,), int64
        A permutation of ``range(len(idx))`` (tree order); results never depend on it.
    """
    return np.argsort(tree[1][idx], kind="stable")


@njit(cache=True)
def knn_rows(points, tree, idx, k):
    """Exact k nearest neighbors of ``points[idx]`` (serial), rows sorted by ``(d2, index)``.

    Returns
    -------
    nbr : ndarray, shape (m, k), int64
    d2 : ndarray, shape (m, k), float64
    """
    m = idx.shape[0]
    nbr = np.empty((m, k), np.int64)
    d2 = np.empty((m, k))
    snode, sdist, bufd, bufi = knn_scratch(tree, k)
    for t in range(m):
        knn_point(points, tree, idx[t], k, d2[t], nbr[t], snode, sdist, bufd, bufi)
    return nbr, d2



@njit(parallel=True, cache=True)
def knn_parallel(points, tree, idx, k, nbr, d2):
    """Exact k nearest neighbors of ``points[idx]`` in parallel; rows as in :func:`knn_rows`.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        From :func:`build_tree` over ``points``.
    idx : ndarray, shape (m,), int64
        Query indices (best in a spatially coherent order, e.g. Morton order).
    k : int
        Neighbors wanted, ``1 <= k <= n - 1``.
    nbr : ndarray, shape (m, k), int32 or int64
        Output: neighbor indices sorted by ``(d2, index)``.
    d2 : ndarray, shape (m, k), float64
        Output: their squared distances.
    """
    m = idx.shape[0]
    for b in prange((m + KNN_BLOCK - 1) // KNN_BLOCK):
        snode, sdist, bufd, bufi = knn_scratch(tree, k)
        ds = np.empty(k)
        ids = np.empty(k, np.int64)
        for t in range(b * KNN_BLOCK, min(m, (b + 1) * KNN_BLOCK)):
            knn_point(points, tree, idx[t], k, ds, ids, snode, sdist, bufd, bufi)
            for i in range(k):
                nbr[t, i] = ids[i]
                d2[t, i] = ds[i]
