"""Consistent normal orientation (DESIGN.md 4.6).

A fitted normal's sign is arbitrary; these functions return a sign per point (+1 keeps the
fitted normal, -1 flips it) and :func:`apply_signs` flips normals, curvatures and directions.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Neighbors per point in the graph the orientation propagates over (the nearest ones).
ORIENT_K = 8
#: The chord term of an edge's weight (:func:`_edge_weight`): CHORD_WEIGHT times
#: ``|u . ni| |u . nj|``, at most CHORD_CAP. On a smooth surface the term is a fixed share
#: of the normal term, so it keeps Hoppe's order there; across a thin wall it must outweigh
#: the steps around the wall's rounded edge. With weight 1 a 10,000-point blade (0.1 % noise,
#: seed 2) still joined its two sides through the trailing edge's tip, where the fits'
#: normals are 60 to 90 degrees off (term 0.13); 2, 4 and 10 orient it. The cap keeps the
#: term a preference, not a ban: in a single-view scan, surfaces one behind the other (an
#: object's border before the table) are joined by chords along their normals, which there
#: do point the same way, and a forest made to avoid them took worse edges instead (PCL's milk
#: scene thinned by 4, k-NN Monge normals: 5.2 % of the points flipped with no cap or a cap
#: of 0.3, 0.05 % with 0.2 as with Hoppe's weight; the table scene 1.3 %, 0.12 % and 0.18 %,
#: Hoppe's 0.16 %). 0.2 is the weight of a normal turn of 37 degrees.
CHORD_WEIGHT = 4.0
CHORD_CAP = 0.2
#: Below this |ni . nj| (normals more than 46 degrees apart) a tree edge's relative sign is
#: read from the normals mirrored across the plane that bisects the chord
#: (:func:`_sign_agreement`), not from ni . nj, which near 90 degrees is a coin toss: a thin
#: wedge's tip turns its normal by 170 degrees over a spacing or two, and its points joined
#: the forest from face points 70 to 125 degrees away (a 10,000-point blade at 0.1 % noise:
#: 1 to 3 of its 61 to 80 tip points, and the points hanging from them, read k = -100 for
#: 100).
MIRROR_BELOW = 0.7
#: Up to this |ni . nj| the mirror decides too where the chord is one of a circle through
#: both points (:data:`CIRCLE_TOL`); beyond it ni . nj always decides. Ungated, the mirror
#: misread surfaces one behind the other in a single-view scan: PCL's milk scene thinned by
#: 4 (k-NN Monge normals) had 787 of 15,074 points inconsistent with 0.9 (7 with 0.85 and
#: with ni . nj alone), through one edge 30 degrees wide whose chord ran within 25 degrees of
#: one normal; gated, 7.
MIRROR_CIRCLE_BELOW = 0.9
#: Largest difference between ``(u . ni)(u . nj)`` and a circle's, ``-(1 - ni . nj) / 2``
#: for consistent signs or ``(1 + ni . nj) / 2`` for opposite ones (u the unit chord), for
#: the chord to count as a circle's.
CIRCLE_TOL = 0.15
#: A tree edge whose chord runs within 37 degrees of both normals (``|u . n|`` at least this
#: at both ends) joins a thin wall's two faces or two surfaces one behind the other, and no
#: local rule tells them apart: the chord is a circle's diameter either way. The forest takes
#: such an edge where its other paths turn more (a 0.25 % noisy thin plate's rims), so the
#: subtree hanging from it is checked against the graph's other edges across the same cut
#: (:func:`repair_cuts`).
SUSPECT_ALONG = 0.8
#: Such a subtree is flipped where the other edges across its cut disagree with its sign by
#: this many times the weight of those that agree, the suspect edge itself among the latter.
#: An edge weighs ``|agreement|`` (:func:`_sign_agreement`) times ``1 - |u . ni| |u . nj|``:
#: the more its chord runs along its normals, the less it can tell a wall from surfaces one
#: behind the other.
REPAIR_MAJORITY = 3.0
#: and by at least this weight in all (a few edges' word against one).
REPAIR_MIN = 4.0
#: At most this many subtrees are flipped (the largest disagreement first, the votes counted
#: again after each).
REPAIR_ROUNDS = 4


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
    """Signs making normals face ``viewpoint``: the scanner position (3,), or one per point
    (n, 3), e.g. the origin of the scan each point belongs to."""
    to_view = np.asarray(viewpoint, np.float64) - points
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
    """Propagate a consistent orientation over a minimum spanning forest.

    The graph joins each point to its first neighbors (both ways) with weight 1 - |ni . nj|,
    so the forest prefers edges between nearly parallel normals, where a flip is unambiguous
    (Hoppe et al., SIGGRAPH 1992). Subtrees hanging from an edge across a thin wall are
    checked against the graph's other edges across the same cut (:func:`repair_cuts`). Each
    tree's overall sign is the one under which its
    normals point away from its centroid on balance (sum of n . (p - centroid) positive):
    outward on closed surfaces, towards the scanner on a single range scan bulging at it.
    The forest is grown by Prim's algorithm straight on the neighbor table, so memory stays
    near 60 bytes per point beyond ``graph`` (no weighted edge list, no edge sort).

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
    valid = np.isfinite(est).all(axis=1)
    rev_ptr, rev_idx = reverse_edges(graph, valid)
    parent, order, count = spanning_forest(points, graph, rev_ptr, rev_idx, est, valid)
    del rev_ptr, rev_idx
    order = order[:count]
    rel = relative_signs(points, est, parent, order)
    repair_cuts(points, est, graph, valid, parent, order, rel)
    return outward_signs(points, est, parent, order, rel)


@njit(cache=True)
def reverse_edges(graph, valid):
    """CSR lists of the points naming each point as a neighbor (the graph's other direction),
    without the points it names itself: those edges are in its own row already.

    Most neighbor relations are mutual, so the lists hold about a fifth of the graph's
    edges instead of all of them (25 bytes a point less at the orientation, where a big
    run's memory peaks); the forest is the same (a repeated edge never lowers a key).

    Returns
    -------
    indptr : ndarray, shape (n + 1,), int64
    indices : ndarray, shape (nnz,), int32
    """
    n, k = graph.shape
    if k > 32:
        raise ValueError("reverse_edges: at most 32 neighbors a point")
    indptr = np.zeros(n + 1, np.int64)
    one_way = np.zeros(n, np.uint32)  # bit t: graph[i, t] does not name i back
    for i in range(n):
        if valid[i]:
            for t in range(k):
                j = graph[i, t]
                if j >= 0 and j != i and valid[j]:
                    mutual = False
                    for u in range(k):
                        if graph[j, u] == i:
                            mutual = True
                            break
                    if not mutual:
                        one_way[i] |= np.uint32(1) << np.uint32(t)
                        indptr[j + 1] += 1
    for i in range(n):
        indptr[i + 1] += indptr[i]
    indices = np.empty(indptr[n], np.int32)
    fill = indptr[:-1].copy()
    for i in range(n):
        bits = one_way[i]
        if bits:
            for t in range(k):
                if bits & (np.uint32(1) << np.uint32(t)):
                    j = graph[i, t]
                    indices[fill[j]] = i
                    fill[j] += 1
    return indptr, indices


# pos of a point already in the spanning forest
_DONE = -2


@njit(cache=True, inline="always")
def _before(key_a, a, key_b, b):
    """Heap order: smaller key first, then smaller index (deterministic on ties)."""
    return key_a < key_b or (key_a == key_b and a < b)


@njit(cache=True, inline="always")
def _edge_weight(a0, a1, a2, b0, b1, b2, d0, d1, d2):
    """Weight of the edge between points with unit normals a and b, b's point at offset d.

    ``1 - |a . b|`` (Hoppe et al. 1992) plus :data:`CHORD_WEIGHT` times ``|u . a| |u . b|``
    (at most :data:`CHORD_CAP`), u = d / |d|: the chord between two points of one smooth
    surface lies near both tangent planes (on a circle the term is sin^2 of half the turning
    angle, half of ``1 - a . b``: the order of edges on a smooth surface stays), but across
    a thin wall it runs along both normals, which are parallel up to sign and so weighed 0
    by the first term alone: one such edge flipped a whole side of a thin plate or blade.
    """
    w = max(1.0 - abs(a0 * b0 + a1 * b1 + a2 * b2), 0.0)
    return w + min(CHORD_WEIGHT * _chord_along(a0, a1, a2, b0, b1, b2, d0, d1, d2), CHORD_CAP)


@njit(cache=True, inline="always")
def _chord_along(a0, a1, a2, b0, b1, b2, d0, d1, d2):
    """``|u . a| |u . b|`` of the unit chord u = d / |d| (0 where d is 0)."""
    dd = d0 * d0 + d1 * d1 + d2 * d2
    if not dd > 0.0:
        return 0.0
    return abs(d0 * a0 + d1 * a1 + d2 * a2) * abs(d0 * b0 + d1 * b1 + d2 * b2) / dd


@njit(cache=True, inline="always")
def _sign_agreement(a0, a1, a2, b0, b1, b2, d0, d1, d2):
    """Whether normals a and b, b's point at offset d, point to the same side of the surface:
    positive if they do.

    ``a . b'``, b' = b mirrored across the plane bisecting the chord (``b - 2 (b . u) u``,
    u = d / |d|), where the normals are more than 46 degrees apart (:data:`MIRROR_BELOW`),
    or up to :data:`MIRROR_CIRCLE_BELOW` where the chord is a circle's; else ``a . b``.
    Two points of a circle or a sphere are mirror images across that plane, normals
    included, so ``a . b'`` is 1 for consistent signs and -1 for opposite ones however far
    the normals turn between them. Where the surface bends one way between the points (a
    convex or concave edge, rounded or sharp) each lies on the same side of the other's
    tangent plane, so the mirror only adds agreement: normals up to 90 degrees apart are
    never read as opposite; beyond 90 degrees the sign holds while the points lie about
    equally far from the turn, as neighbors on a rounded tip do.
    """
    dot = a0 * b0 + a1 * b1 + a2 * b2
    dd = d0 * d0 + d1 * d1 + d2 * d2
    if abs(dot) >= MIRROR_CIRCLE_BELOW or dd == 0.0:
        return dot
    along = (a0 * d0 + a1 * d1 + a2 * d2) * (b0 * d0 + b1 * d1 + b2 * d2) / dd
    if abs(dot) >= MIRROR_BELOW:
        off_circle = min(abs(along + 0.5 * (1.0 - dot)), abs(along - 0.5 * (1.0 + dot)))
        if off_circle >= CIRCLE_TOL:
            return dot
    return dot - 2.0 * along


@njit(cache=True)
def spanning_forest(points, graph, rev_ptr, rev_idx, est, valid):
    """Minimum spanning forest of the symmetric neighbor graph by Prim's algorithm.

    Trees start at the lowest-index point not yet reached, so the forest depends only on the
    (Z-ordered) input. The heap holds each entry's key beside its index (no indirection
    through a key array on every comparison), and an edge's weight 1 - |ni . nj| is computed
    only towards points not yet in the forest: 2.3 times faster than a heap of indices on a
    1M-point cloud, the same forest. A point's key is read from its heap entry (a point not
    in the heap and not in the forest has none yet), and ``pos`` marks the points in the
    forest: no key or done array (9 bytes a point less where a big run's memory peaks).

    Returns
    -------
    parent : ndarray, shape (n,), int32
        Tree parent of each point, -1 for roots and invalid points.
    order : ndarray, shape (n,), int32
        Points in the order they joined the forest (parents before children); the first
        ``count`` entries are used.
    count : int
    """
    n, k = graph.shape
    parent = np.full(n, -1, np.int32)
    heap_key = np.empty(n)
    heap_idx = np.empty(n, np.int32)
    pos = np.full(n, -1, np.int32)  # heap slot; -1: not reached, _DONE: in the forest
    order = np.empty(n, np.int32)
    count = 0
    for start in range(n):
        if pos[start] == _DONE or not valid[start]:
            continue
        heap_key[0], heap_idx[0] = 0.0, start
        pos[start] = 0
        size = 1
        while size > 0:
            i = heap_idx[0]
            size -= 1
            pos[i] = _DONE
            if size > 0:  # the last entry sifts down from the root
                vk, vi = heap_key[size], heap_idx[size]
                h = 0
                while True:
                    c = 2 * h + 1
                    if c >= size:
                        break
                    if c + 1 < size and _before(heap_key[c + 1], heap_idx[c + 1],
                                                heap_key[c], heap_idx[c]):
                        c += 1
                    if not _before(heap_key[c], heap_idx[c], vk, vi):
                        break
                    heap_key[h], heap_idx[h] = heap_key[c], heap_idx[c]
                    pos[heap_idx[h]] = h
                    h = c
                heap_key[h], heap_idx[h] = vk, vi
                pos[vi] = h
            order[count] = i
            count += 1
            e0, e1, e2 = est[i, 0], est[i, 1], est[i, 2]
            p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
            first_rev = rev_ptr[i] - k
            for t in range(k + rev_ptr[i + 1] - rev_ptr[i]):
                if t < k:
                    j = graph[i, t]
                    if j < 0 or j == i or not valid[j]:
                        continue
                else:  # the points naming i as a neighbor
                    j = rev_idx[first_rev + t]
                h = pos[j]
                if h == _DONE:
                    continue
                w = _edge_weight(e0, e1, e2, est[j, 0], est[j, 1], est[j, 2],
                                 points[j, 0] - p0, points[j, 1] - p1, points[j, 2] - p2)
                if not w < (heap_key[h] if h >= 0 else np.inf):
                    continue
                parent[j] = i
                if h < 0:
                    h = size
                    size += 1
                while h > 0:  # sift up
                    up = (h - 1) // 2
                    if not _before(w, j, heap_key[up], heap_idx[up]):
                        break
                    heap_key[h], heap_idx[h] = heap_key[up], heap_idx[up]
                    pos[heap_idx[h]] = h
                    h = up
                heap_key[h], heap_idx[h] = w, j
                pos[j] = h
    return parent, order, count


def forest_signs(points, est, parent, order):
    """Signs of every point from the forest: consistent along edges, outward on balance
    (:func:`relative_signs`, then :func:`outward_signs`; no cut is repaired).

    Returns
    -------
    ndarray, shape (n,), int8
        +1 or -1 per point; invalid points keep +1.
    """
    return outward_signs(points, est, parent, order, relative_signs(points, est, parent, order))


@njit(cache=True)
def relative_signs(points, est, parent, order):
    """Each point's sign relative to its tree's root: its parent's, times the edge's flip by
    :func:`_sign_agreement` (two points keep relative signs that agree with the product of
    edge flips between them).

    Parameters
    ----------
    points, est : ndarray, shape (n, 3)
    parent, order : ndarray, shapes (n,) and (m,), int32
        The forest (:func:`spanning_forest`; ``order`` its first ``count`` entries).

    Returns
    -------
    ndarray, shape (n,), int8
        +1 or -1; +1 at the roots and the points out of the forest.
    """
    rel = np.ones(points.shape[0], np.int8)
    for t in range(order.shape[0]):
        i = order[t]
        p = parent[i]
        if p < 0:
            continue
        agree = _sign_agreement(est[i, 0], est[i, 1], est[i, 2], est[p, 0], est[p, 1],
                                est[p, 2], points[p, 0] - points[i, 0],
                                points[p, 1] - points[i, 1], points[p, 2] - points[i, 2])
        rel[i] = rel[p] if agree >= 0.0 else -rel[p]
    return rel


@njit(cache=True)
def outward_signs(points, est, parent, order, rel):
    """Signs from the relative signs ``rel`` (n,), each tree flipped as a whole where the
    sum of rel n . (p - centroid) over its points is negative: outward on balance.

    Returns
    -------
    ndarray, shape (n,), int8
        +1 or -1 per point; invalid points keep +1.
    """
    n = points.shape[0]
    m = order.shape[0]
    tree = np.full(n, -1, np.int32)
    n_trees = 0
    for t in range(m):
        i = order[t]
        p = parent[i]
        if p < 0:
            tree[i] = n_trees
            n_trees += 1
        else:
            tree[i] = tree[p]
    cent = np.zeros((n_trees, 3))
    size = np.zeros(n_trees)
    for t in range(m):
        i = order[t]
        size[tree[i]] += 1.0
        for d in range(3):
            cent[tree[i], d] += points[i, d]
    for c in range(n_trees):
        for d in range(3):
            cent[c, d] /= size[c]
    # Vote over the whole tree rather than trusting one seed point: the farthest point of an
    # open single-view scan lies on its rim, where normals graze and the sign is a coin toss.
    vote = np.zeros(n_trees)
    for t in range(m):
        i = order[t]
        c = tree[i]
        out = 0.0
        for d in range(3):
            out += est[i, d] * (points[i, d] - cent[c, d])
        vote[c] += rel[i] * out
    flip = np.ones(n_trees, np.int8)
    for c in range(n_trees):
        flip[c] = 1 if vote[c] >= 0.0 else -1
    sign = np.ones(n, np.int8)
    for t in range(m):
        i = order[t]
        sign[i] = rel[i] * flip[tree[i]]
    return sign


@njit(cache=True)
def _suspects(points, est, parent, order):
    """Whether each point's tree edge to its parent runs along both normals
    (:data:`SUSPECT_ALONG`), shape (n,), bool."""
    out = np.zeros(points.shape[0], np.bool_)
    for t in range(order.shape[0]):
        i = order[t]
        p = parent[i]
        if p < 0:
            continue
        dd = 0.0
        ai = ap = 0.0
        for c in range(3):
            d = points[p, c] - points[i, c]
            dd += d * d
            ai += d * est[i, c]
            ap += d * est[p, c]
        if dd > 0.0:
            lim = SUSPECT_ALONG * SUSPECT_ALONG * dd
            out[i] = ai * ai >= lim and ap * ap >= lim
    return out


@njit(cache=True)
def _find(root, i):
    """Union-find root of ``i``, halving the path on the way."""
    while root[i] != i:
        root[i] = root[root[i]]
        i = root[i]
    return i


def _children(parent, order):
    """CSR lists of each point's children in the forest, in the order they joined it:
    (kid_ptr (n + 1,), kids), both int32."""
    child = order[parent[order] >= 0]
    kids = child[np.argsort(parent[child], kind="stable")].astype(np.int32)
    kid_ptr = np.zeros(parent.shape[0] + 1, np.int32)
    np.cumsum(np.bincount(parent[child], minlength=parent.shape[0]), out=kid_ptr[1:])
    return kid_ptr, kids


@njit(cache=True)
def _cut_votes(points, est, graph, valid, parent, order, kid_ptr, kids, rel):
    """Weight of the graph's edges across each tree edge's cut that agree and that disagree
    with the signs ``rel``.

    Every edge (i, j) lies on one tree, and crosses exactly the tree edges on the tree path
    from i to j: its weight goes to i and j and twice off their lowest common ancestor, so
    that the sum over a point's subtree is the weight across the cut above it. The ancestors
    come from Tarjan's offline algorithm: in a depth-first walk, a point done is joined to
    its parent's set, so the set of a point done earlier is named by the lowest ancestor not
    yet done. An edge is read at its later end from that end's row, so a one-way edge whose
    row's point is done first is left out: no reverse lists (the votes need not be complete,
    and a big run's memory peaks at the orientation).

    Parameters
    ----------
    points, est, graph, valid, parent, order
        As for :func:`repair_cuts`.
    kid_ptr, kids : ndarray, int32
        Each point's children (:func:`_children`).
    rel : ndarray, shape (n,), int8
        The signs the edges are weighed against.

    Returns
    -------
    agree, disagree : ndarray, shape (n,)
        At each point, the weight across the cut between its subtree and the rest.
    """
    n, k = graph.shape
    m = order.shape[0]
    root = np.arange(n).astype(np.int32)  # union-find
    done = np.zeros(n, np.bool_)
    agree = np.zeros(n)
    disagree = np.zeros(n)
    stack = np.empty(m, np.int32)
    nxt = kid_ptr[:-1].copy()  # each point's next child to visit
    for t in range(m):
        r = order[t]
        if parent[r] >= 0:
            continue
        top = 0
        stack[0] = r
        while top >= 0:
            u = stack[top]
            if nxt[u] < kid_ptr[u + 1]:
                top += 1
                stack[top] = kids[nxt[u]]
                nxt[u] += 1
                continue
            top -= 1
            done[u] = True
            for e in range(k):
                v = graph[u, e]
                if v < 0 or v == u or not valid[v] or not done[v]:
                    continue
                a = _find(root, v)
                d0 = points[v, 0] - points[u, 0]
                d1 = points[v, 1] - points[u, 1]
                d2 = points[v, 2] - points[u, 2]
                val = _sign_agreement(est[u, 0], est[u, 1], est[u, 2], est[v, 0], est[v, 1],
                                      est[v, 2], d0, d1, d2)
                along = _chord_along(est[u, 0], est[u, 1], est[u, 2], est[v, 0], est[v, 1],
                                     est[v, 2], d0, d1, d2)
                w = min(abs(val), 1.0) * (1.0 - min(along, 1.0))
                if (val >= 0.0) == (rel[u] == rel[v]):
                    agree[u] += w
                    agree[v] += w
                    agree[a] -= 2.0 * w
                else:
                    disagree[u] += w
                    disagree[v] += w
                    disagree[a] -= 2.0 * w
            if parent[u] >= 0:
                root[u] = parent[u]  # u's set was named u: its children were joined to it
    for t in range(m - 1, -1, -1):
        i = order[t]
        p = parent[i]
        if p >= 0:
            agree[p] += agree[i]
            disagree[p] += disagree[i]
    return agree, disagree


@njit(cache=True)
def _flip_subtree(parent, order, rel, top):
    """Negate ``rel`` over the subtree of ``top`` (``order``: parents before children)."""
    inside = np.zeros(parent.shape[0], np.bool_)
    inside[top] = True
    rel[top] = -rel[top]
    for t in range(order.shape[0]):
        i = order[t]
        p = parent[i]
        if p >= 0 and inside[p] and i != top:
            inside[i] = True
            rel[i] = -rel[i]


def repair_cuts(points, est, graph, valid, parent, order, rel) -> int:
    """Flip, in ``rel`` (n,), the subtrees hanging from a suspect tree edge
    (:data:`SUSPECT_ALONG`) whose cut the graph's other edges disagree with
    (:data:`REPAIR_MAJORITY`, :data:`REPAIR_MIN`), at most :data:`REPAIR_ROUNDS` of them.

    A thin wall's two faces are joined by the rim's edges and, where noise brings them within
    a few nearest neighbors, across the wall; surfaces one behind the other in a single view
    by edges along the view alone, which agree with the suspect edge, so they keep its sign.

    Parameters
    ----------
    points, est : ndarray, shape (n, 3)
    graph, valid
        As for :func:`spanning_forest`.
    parent, order : ndarray, int32
        The forest (``order`` its first ``count`` entries).
    rel : ndarray, shape (n,), int8
        Signs relative to each tree's root (:func:`relative_signs`), changed in place.

    Returns
    -------
    int
        How many subtrees were flipped.
    """
    suspect = _suspects(points, est, parent, order)
    if not suspect.any():
        return 0
    kids = _children(parent, order)
    flipped = 0
    for _ in range(REPAIR_ROUNDS):
        agree, disagree = _cut_votes(points, est, graph, valid, parent, order, *kids, rel)
        wrong = suspect & (disagree >= REPAIR_MAJORITY * agree) & (disagree >= REPAIR_MIN)
        if not wrong.any():
            break
        at = np.flatnonzero(wrong)
        _flip_subtree(parent, order, rel, at[np.argmax(disagree[at] - agree[at])])
        flipped += 1
    return flipped


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
