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

A query may start from a squared radius (:func:`knn_point_within`): it then finds the exact
answer among the points within that radius, which is the exact answer overall whenever it
holds k points; when it holds fewer, the query runs again with a wider radius, the last time
with none. A radius is therefore only ever a guess that saves work, never a condition of
exactness. Batch queries (:func:`knn_rows`, :func:`knn_parallel`) take their radii from the
previous query (:func:`seed_bounds`).

Up to :data:`INSERT_MAX_K` neighbors are kept in a sorted list (insertion is cheaper than a
heap at that size and leaves nothing to sort); more are collected unsorted in a buffer of all
points within the radius, sorted once at the end (a bucket pass and an insertion pass), the
buffer being cut to the k best whenever it fills.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

# Measured on 1M Z-ordered torus points (benchmarks/knn.py): 32 beats 12 for k = 24 to 384.
LEAF_SIZE = 32
# Up to this many neighbors a sorted insertion list, above it the candidate buffer.
INSERT_MAX_K = 32
# Candidate buffer of BUFFER_FACTOR * k entries (cut to k when full).
BUFFER_FACTOR = 4
# The first radius tried from the previous query q: (GUESS_GROWTH * r_k(q) + GUESS_SHIFT *
# |p - q|)^2; neighboring k-th distances differ by less than 6 % for 99 % of neighboring
# anchors on the noisy torus, so a failed guess (then the safe radius) is rare.
GUESS_GROWTH = 1.05
GUESS_SHIFT = 0.1
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
    # branch free: of the two gaps per axis at most one is positive, so the sum is exact
    a = max(bmin[node, 0] - px, 0.0)
    b = max(px - bmax[node, 0], 0.0)
    d = a * a + b * b
    a = max(bmin[node, 1] - py, 0.0)
    b = max(py - bmax[node, 1], 0.0)
    d += a * a + b * b
    a = max(bmin[node, 2] - pz, 0.0)
    b = max(pz - bmax[node, 2], 0.0)
    return d + (a * a + b * b)


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
def _heapsort_pairs(d, c, m):
    """Sort ``d[:m], c[:m]`` by ``(d, c)`` in place, O(m log m) whatever the input."""
    for root in range(m // 2 - 1, -1, -1):
        _sift_down(d, c, root, m)
    for end in range(m - 1, 0, -1):
        x = d[0]
        y = c[0]
        d[0] = d[end]
        c[0] = c[end]
        d[end] = x
        c[end] = y
        _sift_down(d, c, 0, end)


@njit(cache=True)
def _sort_pairs(d, c, m, td, tc, work):
    """``d[:m], c[:m]`` sorted by ``(d, c)`` into ``td[:m], tc[:m]``.

    A counting pass into m buckets of equal width in d (squared distances of points on a
    surface are close to uniform in ``[0, max]``), then insertion sort with the exact order,
    near linear after that pass; heapsort takes over if the insertions grow beyond a few per
    entry (many equal distances). ``work`` holds >= 2 m int64.
    """
    hi = 0.0
    for i in range(m):
        if d[i] > hi:
            hi = d[i]
    hist = work[:m]
    keys = work[m:2 * m]
    hist[:] = 0
    scale = m / hi if 0.0 < hi < np.inf else 0.0
    for i in range(m):
        q = d[i] * scale
        key = np.int64(q) if q > 0.0 else 0
        if key >= m:
            key = m - 1
        keys[i] = key
        hist[key] += 1
    acc = 0
    for b in range(m):
        h = hist[b]
        hist[b] = acc
        acc += h
    for i in range(m):
        key = keys[i]
        td[hist[key]] = d[i]
        tc[hist[key]] = c[i]
        hist[key] += 1
    budget = 8 * m + 64
    for i in range(1, m):
        x = td[i]
        y = tc[i]
        j = i
        while j > 0 and _before(x, y, td[j - 1], tc[j - 1]):
            td[j] = td[j - 1]
            tc[j] = tc[j - 1]
            j -= 1
        td[j] = x
        tc[j] = y
        budget -= i - j
        if budget < 0:
            _heapsort_pairs(td, tc, m)
            return


@njit(cache=True)
def _search_sorted(points, tree, p, k, bound, ds, ids, snode, sdist):
    """The k nearest of p within squared distance ``bound``, kept sorted in ``ds, ids``.

    Returns how many were found (fewer than k only if fewer lie within ``bound``).
    """
    perm, _, tpts, start, stop, left, _, bmin, bmax, _ = tree
    px = points[p, 0]
    py = points[p, 1]
    pz = points[p, 2]
    size = 0
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
                x0 = tpts[t, 0] - px
                x1 = tpts[t, 1] - py
                x2 = tpts[t, 2] - pz
                d = x0 * x0 + x1 * x1 + x2 * x2
                if not d <= bound:
                    continue
                c = perm[t]
                if c == p:
                    continue
                # insert into the sorted prefix, dropping the last entry when full
                if size < k:
                    j = size
                    size += 1
                elif _before(d, c, ds[k - 1], ids[k - 1]):
                    j = k - 1
                else:
                    continue
                while j > 0 and _before(d, c, ds[j - 1], ids[j - 1]):
                    ds[j] = ds[j - 1]
                    ids[j] = ids[j - 1]
                    j -= 1
                ds[j] = d
                ids[j] = c
                if size == k:
                    bound = ds[k - 1]
        else:
            r = l + 1  # children are allocated in pairs
            dl = _box_d2(bmin, bmax, l, px, py, pz)
            dr = _box_d2(bmin, bmax, r, px, py, pz)
            # push the nearer child last, so it is searched first
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
    return size


@njit(cache=True)
def _search_buffer(points, tree, p, k, bound, bufd, bufi, cap, td, tc, work, snode, sdist):
    """All points within squared distance ``bound`` of p (cut to the k best whenever
    ``cap`` are held), sorted into ``td, tc``; returns how many (keep the first k)."""
    perm, _, tpts, start, stop, left, _, bmin, bmax, _ = tree
    px = points[p, 0]
    py = points[p, 1]
    pz = points[p, 2]
    m = 0
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
                x0 = tpts[t, 0] - px
                x1 = tpts[t, 1] - py
                x2 = tpts[t, 2] - pz
                d = x0 * x0 + x1 * x1 + x2 * x2
                if not d <= bound:
                    continue
                c = perm[t]
                if c == p:
                    continue
                bufd[m] = d
                bufi[m] = c
                m += 1
                if m == cap:
                    # keep the k best; none beyond the k-th can enter the answer
                    _sort_pairs(bufd, bufi, m, td, tc, work)
                    bufd[:k] = td[:k]
                    bufi[:k] = tc[:k]
                    m = k
                    bound = bufd[k - 1]
        else:
            r = l + 1
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
    _sort_pairs(bufd, bufi, m, td, tc, work)
    return m


@njit(cache=True)
def _buffered(points, tree, p, k, bound, ds, ids, snode, sdist, bufd, bufi):
    cap = bufd.shape[0] // 2
    m = _search_buffer(points, tree, p, k, bound, bufd[:cap], bufi[:cap], cap, bufd[cap:],
                       bufi[cap:], snode[tree[9] + 2:], snode, sdist)
    size = min(m, k)
    ds[:size] = bufd[cap:cap + size]
    ids[:size] = bufi[cap:cap + size]
    return size


@njit(cache=True)
def knn_point_within(points, tree, p, k, guess, safe, ds, ids, snode, sdist, bufd, bufi):
    """:func:`knn_point`, searched within squared radius ``guess``, then ``safe``, then all.

    Each radius is tried only if it is smaller than the next; a search whose radius holds
    fewer than k other points is repeated with the next one, so the answer is exact
    whatever the radii (wrong radii cost time only).

    Parameters
    ----------
    guess, safe : float
        Squared radii, e.g. from :func:`seed_bounds`; ``np.inf`` for none.
    points, tree, p, k, ds, ids, snode, sdist, bufd, bufi
        As in :func:`knn_point`.

    Returns
    -------
    int
        ``k`` (fewer only if the cloud holds fewer other points).
    """
    cap = bufd.shape[0] // 2
    if k <= INSERT_MAX_K or cap < 2 * k or snode.shape[0] < tree[9] + 2 + 2 * cap:
        if safe < np.inf:
            size = _search_sorted(points, tree, p, k, safe, ds, ids, snode, sdist)
            if size == k:
                return size
        return _search_sorted(points, tree, p, k, np.inf, ds, ids, snode, sdist)
    if guess < safe:
        size = _buffered(points, tree, p, k, guess, ds, ids, snode, sdist, bufd, bufi)
        if size == k:
            return size
    if safe < np.inf:
        size = _buffered(points, tree, p, k, safe, ds, ids, snode, sdist, bufd, bufi)
        if size == k:
            return size
    return _buffered(points, tree, p, k, np.inf, ds, ids, snode, sdist, bufd, bufi)


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
    snode, sdist, bufd, bufi : ndarray
        Scratch from :func:`knn_scratch` for at least this k.

    Returns
    -------
    int
        ``k`` (fewer only if the cloud holds fewer other points).
    """
    return knn_point_within(points, tree, p, k, np.inf, np.inf, ds, ids, snode, sdist, bufd,
                            bufi)


@njit(cache=True)
def knn_scratch(tree, k):
    """Scratch arrays ``(snode, sdist, bufd, bufi)`` for :func:`knn_point` with up to k
    neighbors: the search stack (its int64 part followed by the sort's work space of 2 cap
    entries) and the candidate buffer with its sorted copy (2 cap entries each), where
    ``cap = BUFFER_FACTOR * k`` above :data:`INSERT_MAX_K` (else none is needed)."""
    depth = tree[9]
    cap = BUFFER_FACTOR * k if k > INSERT_MAX_K else 1
    return (np.empty(depth + 2 + 2 * cap, np.int64), np.empty(depth + 2), np.empty(2 * cap),
            np.empty(2 * cap, np.int64))


@njit(cache=True, inline="always")
def seed_bounds(points, p, q, dq):
    """Squared radii for the query at p from a finished query at q (k-th squared distance
    ``dq``): a guess, and a bound that holds k other points of p.

    The k neighbors of q and q itself are k + 1 points within ``sqrt(dq) + |p - q|`` of p; at
    least k of them are not p. The bound is widened by 1e-9 for rounding (it need not hold:
    :func:`knn_point_within` checks).

    Returns
    -------
    guess, safe : float
    """
    x0 = points[p, 0] - points[q, 0]
    x1 = points[p, 1] - points[q, 1]
    x2 = points[p, 2] - points[q, 2]
    rq = np.sqrt(dq)
    dpq = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    g = GUESS_GROWTH * rq + GUESS_SHIFT * dpq
    r = rq + dpq
    return g * g, r * r * (1.0 + 1e-9)


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

    Each query starts from the radii of the previous one (:func:`seed_bounds`); the rows do
    not depend on the order of ``idx``, only the time does.

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
        guess = safe = np.inf
        if t > 0:
            guess, safe = seed_bounds(points, idx[t], idx[t - 1], d2[t - 1, k - 1])
        knn_point_within(points, tree, idx[t], k, guess, safe, d2[t], nbr[t], snode, sdist,
                         bufd, bufi)
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
        Query indices (best in a spatially coherent order, e.g. Morton order: each query
        starts from the previous one's radius, see :func:`seed_bounds`).
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
        lo = b * KNN_BLOCK
        for t in range(lo, min(m, lo + KNN_BLOCK)):
            guess = safe = np.inf
            if t > lo:
                guess, safe = seed_bounds(points, idx[t], idx[t - 1], ds[k - 1])
            knn_point_within(points, tree, idx[t], k, guess, safe, ds, ids, snode, sdist, bufd,
                             bufi)
            for i in range(k):
                nbr[t, i] = ids[i]
                d2[t, i] = ds[i]
