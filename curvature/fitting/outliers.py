"""Points that lie off the surface their neighbors describe (scanner outliers).

A scan's outliers (mixed pixels, reflections, dust) sit far from the surface compared with how
thick the surface's own sample is. For every point p with unit normal n (stage-1 PCA) and
neighbors q_i, the offset of p from the neighbors' centroid c along n is compared with the
neighbors' own spread along n (their RMS offset from c): p is an outlier when

    |(p - c) . n| > OUTLIER_SIGMAS * thickness + OUTLIER_FLOOR * spacing  (4 and 0.2).

The floor keeps noise-free clouds (thickness 0) from flagging rounding. Curvature sag raises the
thickness and the offset alike, so fillets are not flagged. So does another outlier among the
neighbors: the default tests the points whose neighbors held a flagged outlier again without
it (``AutoRun._normals_without_outliers``).

An outlier inside a thin wall, between its two faces, is not off that plane: the neighbors'
centroid lies in the wall's middle and their spread is half the wall's thickness. Nor is one
just past a thin wedge's rounded tip. Both lie on no sheet of their own (:func:`off_sheets`):
fewer than 3 of their 8 nearest neighbors have them within ``OWN_SHEET_NOISE * noise +
OWN_SHEET_FLOOR * spacing`` of their tangent planes, while a point on a face has most of its
nearest neighbors on its own face. A neighbor counts only up to OWN_SHEET_REACH times its own
8th neighbor's distance from the point: a face's plane, carried farther, runs on past the
wedge's tip. The test needs the cloud's noise, so clean clouds keep the other two, and it runs
where the stage-1 neighborhood is far from flat (OWN_SHEET_CANDIDATE), as a wall's is.

The sheet test's limit holds a floor for curved surfaces' sag, so a point inside a wall a
few noise off one face passes it. Where a point's nearest neighbors lie on the wall's two
parallel faces (their heights split at a wide gap) it is judged against planes fitted to
the faces themselves (:func:`between_faces`): more than FACE_SIGMAS times their RMS distance
off both, it is an outlier. The planes are fitted twice, the second time without the points
farther than FACE_TRIM robust spreads from the first: another outlier among the neighbors
tilts the first fit, and past a wall's open border the tilt, carried out to the point, hid
it (docs/accuracy.md, section 9, step 47). A wall's rounded end or a wedge's tip also lies
between its faces' planes: a point with its neighbors behind it is judged only where nearly
all their normals agree or the two faces' own planes are parallel (parallel faces cut open),
not where half are the other face's and the planes part (a tip).

An outlier far from every surface (inside a part's volume, say) has no plane to be off: its
neighbors come from several faces and their spread is wide. It is *isolated* instead: the
distance to its 8th nearest neighbor exceeds ISOLATION (2.5) times the median of that distance
over its 8 nearest neighbors (:func:`isolated`). Comparing with the neighbors, not with the
whole cloud, keeps sparse but genuine regions of a scan (far from the scanner, say) unflagged.

Outliers' normals are left out of every normal fit and their positions out of the positional
fits, so they cannot drag a fit; they still get a result of their own.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import jacobi3
from .parallel_sheets import at_an_end, faces_parallel, sheet_gap, sheet_heights

__all__ = ["FACE_K", "FACE_SIGMAS", "FACE_TRIM", "FACE_TRIM_RMS", "ISOLATION", "ISOLATION_K",
           "OUTLIER_FLOOR", "OUTLIER_SIGMAS", "OWN_SHEET_CANDIDATE", "OWN_SHEET_FLOOR",
           "OWN_SHEET_K", "OWN_SHEET_NOISE", "OWN_SHEET_RANK", "OWN_SHEET_REACH", "between_faces",
           "isolated", "off_sheets", "off_surface", "sheet_limit"]

#: Offsets beyond this many neighbor thicknesses are outliers.
OUTLIER_SIGMAS = 4.0
#: Plus this share of the point spacing (noise-free clouds have no thickness).
OUTLIER_FLOOR = 0.2
#: The test of :func:`off_sheets` (module docstring). A point lies on a sheet of its own where
#: at least OWN_SHEET_RANK of its OWN_SHEET_K nearest neighbors have it within
#: ``OWN_SHEET_NOISE * noise + OWN_SHEET_FLOOR * spacing`` of their tangent planes: 4 standard
#: deviations of the difference of two noisy heights, plus a share of the plan's spacing (its
#: 24th neighbor's distance) for the sag of curved surfaces (with 0.1 instead of 0.3, 18
#: points of the Stanford bunny's mesh, whose noise is 1.4 % of that spacing, were flagged;
#: with 0.3 none). It is tested where the stage-1 neighborhood's flatness exceeds
#: OWN_SHEET_CANDIDATE (a noisy plane reads 0.001, fillets 0.006 to 0.02, a slab 0.1); a
#: neighbor counts up to OWN_SHEET_REACH times its own ISOLATION_K-th neighbor's distance
#: from the point.
OWN_SHEET_K = 8
OWN_SHEET_RANK = 3
OWN_SHEET_NOISE = 4.0 * np.sqrt(2.0)
OWN_SHEET_FLOOR = 0.3
OWN_SHEET_CANDIDATE = 0.02
OWN_SHEET_REACH = 1.5
#: The test of :func:`between_faces`: a point whose FACE_K nearest neighbors lie on two
#: faces is an outlier where it lies more than FACE_SIGMAS times their RMS distance from two
#: parallel planes fitted to them off both planes (4.5 until stop 63: the thin plate's seed 2
#: rose 20 % instead of 17 % with 1 % outliers; a noisy face's own point exceeds 4 of its
#: standard deviations about once in 16,000 tested, and only a wall's points are tested).
FACE_K = 48
FACE_SIGMAS = 4.0
#: The second fit keeps the points within FACE_TRIM robust spreads (1.4826 times the median
#: distance, at least the noise) of the first. Its RMS distance is taken as at least
#: FACE_TRIM_RMS of the first's: where the faces are curved, not flat, dropping the farthest
#: points shrinks it (a vertex of the Stanford bunny's mesh, in a fold of its base, was
#: flagged), while one outlier among 48 points doubles it only from 11.5 noise off the faces
#: (the square of the RMS distance grows by the square of its distance over 44).
FACE_TRIM = 3.0
FACE_TRIM_RMS = 0.5
#: Fewest points of a face (the farther face may show only a few at the list's edge).
FACE_LEAST = 3
#: Normals within 10 degrees of each other agree (:func:`_consensus_normal`); at an end a
#: point is judged only where at least FACE_END_AGREE of its neighbors' normals agree or its
#: faces' planes are parallel (:func:`~.parallel_sheets.faces_parallel`).
FACE_END_AGREE = 0.75
FACE_AGREE = np.cos(np.radians(10.0))
#: Normals tried as the one the others agree on (the nearest neighbors'): trying all 48
#: took the test about twice as long on PCL's table, a third of whose points are tested.
FACE_CHOICES = 12
#: Neighbors of the isolation test, and how much farther than its neighbors' a point's
#: ISOLATION_K-th neighbor must be for the point to count as isolated.
ISOLATION_K = 8
ISOLATION = 2.5


@njit(parallel=True, cache=True)
def off_surface(points, query, nbr, normals, spacing, out):
    """Flag the query points that lie off their neighbors' surface (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Neighbors of each query point (the point itself not listed).
    normals : ndarray, shape (m, 3)
        Unit normal of each query point (NaN: never flagged).
    spacing : float
        Point spacing of the cloud.
    out : ndarray, shape (m,), bool
        Output flags.
    """
    k = nbr.shape[1]
    for j in prange(query.shape[0]):
        n0, n1, n2 = normals[j, 0], normals[j, 1], normals[j, 2]
        out[j] = False
        if not (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)) or k < 3:
            continue
        # Heights of the neighbors and of p along n; offsets are taken from their mean.
        mean = 0.0
        for i in range(k):
            q = nbr[j, i]
            mean += points[q, 0] * n0 + points[q, 1] * n1 + points[q, 2] * n2
        mean /= k
        ss = 0.0
        for i in range(k):
            q = nbr[j, i]
            d = points[q, 0] * n0 + points[q, 1] * n1 + points[q, 2] * n2 - mean
            ss += d * d
        p = query[j]
        off = abs(points[p, 0] * n0 + points[p, 1] * n1 + points[p, 2] * n2 - mean)
        out[j] = off > OUTLIER_SIGMAS * np.sqrt(ss / k) + OUTLIER_FLOOR * spacing


def sheet_limit(noise: float, spacing: float) -> float:
    """The ``limit`` of :func:`off_sheets` for a cloud's ``noise`` (standard deviation across
    the surface) and plan ``spacing`` (length unit); inf where the noise is not finite or
    zero (no test)."""
    if not np.isfinite(noise) or noise <= 0.0:
        return np.inf
    return OWN_SHEET_NOISE * noise + OWN_SHEET_FLOOR * spacing


@njit(parallel=True, cache=True)
def off_sheets(points, query, nbr, normals, reach, excluded, limit, out):
    """Flag the query points that lie on no sheet of their nearest neighbors (module
    docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Nearest neighbors of each query point, nearest first (the point itself not listed).
    normals : ndarray, shape (n, 3)
        Unit normal of every point (NaN: its plane does not count; a point with fewer than
        OWN_SHEET_RANK neighbors that have one is not flagged).
    reach : ndarray, shape (n,)
        Distance of every point to its ISOLATION_K-th nearest neighbor: a neighbor farther
        from p than OWN_SHEET_REACH times its own does not count.
    excluded : ndarray, shape (n,), bool
        Points whose planes do not count (outliers already found).
    limit : float
        Largest distance of p from a neighbor's tangent plane for p to lie on its sheet.
    out : ndarray, shape (m,), bool
        Output flags.
    """
    k = min(OWN_SHEET_K, nbr.shape[1])
    for j in prange(query.shape[0]):
        p = query[j]
        near = 0
        planes = 0  # neighbors with a plane to judge by
        for i in range(k):
            q = nbr[j, i]
            if excluded[q] or not np.isfinite(normals[q, 0]):
                continue
            planes += 1
            h = 0.0
            r2 = 0.0
            for d in range(3):
                u = points[p, d] - points[q, d]
                h += u * normals[q, d]
                r2 += u * u
            if abs(h) <= limit and r2 <= (OWN_SHEET_REACH * reach[q]) ** 2:
                near += 1
        # Too few planes (degenerate neighborhoods around) say nothing: not flagged.
        out[j] = planes >= OWN_SHEET_RANK and near < OWN_SHEET_RANK


def isolated(points: np.ndarray, tree: tuple, reach: np.ndarray, out: np.ndarray,
             rows: np.ndarray | None = None) -> None:
    """Flag the points whose ISOLATION_K-th neighbor is far farther than their neighbors' are.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    reach : ndarray, shape (m,)
        Distance of every tested point to its ISOLATION_K-th nearest neighbor.
    out : ndarray, shape (m,), bool
        Set True (in place) where a tested point is isolated; never cleared.
    rows : ndarray, shape (m,), int64, optional
        The tested points (default: all, m = n). The neighbors' own reach is then measured
        where it is needed, for the few points that pass the filter below.
    """
    from ..neighborhoods.kdtree import knn_parallel

    # Only points beyond half the threshold of the tested points' median can pass it against
    # their neighbors' unless those are denser than the cloud by more than 2: a cheap filter.
    cand = np.flatnonzero(reach > 0.5 * ISOLATION * np.median(reach)).astype(np.int64)
    k = min(ISOLATION_K, points.shape[0] - 1)
    if cand.size == 0 or k < 1:
        return
    ids = cand if rows is None else rows[cand]
    nbr = np.empty((cand.size, k), np.int64)
    knn_parallel(points, tree, ids, k, nbr, np.empty((cand.size, k)))
    if rows is None:
        near = reach[nbr]
    else:
        uniq, inv = np.unique(nbr, return_inverse=True)
        d2 = np.empty((uniq.size, k))
        knn_parallel(points, tree, uniq, k, np.empty((uniq.size, k), np.int64), d2)
        near = np.sqrt(d2[:, k - 1])[inv.reshape(nbr.shape)]
    local = np.median(near, axis=1)
    out[cand[reach[cand] > ISOLATION * local]] = True


@njit(cache=True)
def _parallel_planes(h, u, v, order, split):
    """Two parallel planes ``h = a_g + b u + c v`` fitted to the groups ``order[:split]``
    and ``order[split:]`` (one slope, one height each): returns their heights at the origin,
    their common slope and the points' RMS distance from them, (a_low, a_high, b, c, rms);
    NaN where the points span no plane."""
    m = order.shape[0]
    mean = np.zeros((2, 3))  # per group: u, v, h
    for c in range(m):
        g = 0 if c < split else 1
        i = order[c]
        mean[g, 0] += u[i]
        mean[g, 1] += v[i]
        mean[g, 2] += h[i]
    mean[0] /= split
    mean[1] /= m - split
    cuu = cuv = cvv = cuh = cvh = 0.0
    for c in range(m):
        g = 0 if c < split else 1
        i = order[c]
        du, dv, dh = u[i] - mean[g, 0], v[i] - mean[g, 1], h[i] - mean[g, 2]
        cuu += du * du
        cuv += du * dv
        cvv += dv * dv
        cuh += du * dh
        cvh += dv * dh
    det = cuu * cvv - cuv * cuv
    if not det > 1e-12 * max(cuu * cvv, 1e-300):
        return np.nan, np.nan, np.nan, np.nan, np.nan
    b = (cvv * cuh - cuv * cvh) / det
    c2 = (cuu * cvh - cuv * cuh) / det
    ss = 0.0
    for c in range(m):
        g = 0 if c < split else 1
        i = order[c]
        r = h[i] - mean[g, 2] - b * (u[i] - mean[g, 0]) - c2 * (v[i] - mean[g, 1])
        ss += r * r
    rms = np.sqrt(ss / max(m - 4, 1))
    return (mean[0, 2] - b * mean[0, 0] - c2 * mean[0, 1],
            mean[1, 2] - b * mean[1, 0] - c2 * mean[1, 1], b, c2, rms)


@njit(cache=True)
def _on_their_faces(h, u, v, order, split, noise):
    """The points of ``order`` (groups ``[:split]`` and ``[split:]``) within FACE_TRIM times
    the robust spread (1.4826 times the median distance, at least ``noise``) of the parallel
    planes fitted to them: (order, split, rms) of those, the groups kept, and the first
    fit's RMS distance; ``split = -1`` where the planes span nothing."""
    a_low, a_high, b, c, rms = _parallel_planes(h, u, v, order, split)
    m = order.shape[0]
    if not np.isfinite(b):
        return order, -1, rms
    dist = np.empty(m)
    for k in range(m):
        i = order[k]
        dist[k] = abs(h[i] - (a_low if k < split else a_high) - b * u[i] - c * v[i])
    limit = FACE_TRIM * max(1.4826 * np.median(dist), noise)
    kept = np.empty(m, np.int64)
    n, low = 0, 0
    for k in range(m):
        if dist[k] <= limit:
            kept[n] = order[k]
            n += 1
            if k < split:
                low += 1
    return kept[:n], low, rms


@njit(cache=True)
def _faces_normal(points, nbr, where, order, split, out):
    """Unit normal, into ``out``, of two faces: the eigenvector of the least eigenvalue of
    the covariance of the points ``nbr[where[order[:split]]]`` and ``nbr[where[order[split:]]]``
    about their own group's centroid; False (``out`` unchanged) where they span no plane."""
    m = order.shape[0]
    mean = np.zeros((2, 3))
    for c in range(m):
        g = 0 if c < split else 1
        q = nbr[where[order[c]]]
        for d in range(3):
            mean[g, d] += points[q, d]
    mean[0] /= split
    mean[1] /= m - split
    cov = np.zeros((3, 3))
    for c in range(m):
        g = 0 if c < split else 1
        q = nbr[where[order[c]]]
        for a in range(3):
            for b in range(3):
                cov[a, b] += (points[q, a] - mean[g, a]) * (points[q, b] - mean[g, b])
    vec = np.empty((3, 3))
    i0, i1, _ = jacobi3(cov, vec)
    if not cov[i1, i1] > 1e-10 * cov[i0, i0] or not cov[i1, i1] > 0.0:
        return False
    for d in range(3):
        out[d] = vec[d, i0]
    return True


@njit(cache=True)
def _consensus_normal(normals, nbr, excluded):
    """The normal most of the points ``nbr`` (not ``excluded``) agree on: the one of the
    nearest FACE_CHOICES with the most others within FACE_AGREE of it (either sign),
    averaged with those, as a unit vector (NaN where fewer than OWN_SHEET_RANK agree), and
    the share of the points with a normal that agree. Not a mean: a few of them tilt where
    an unflagged outlier was among their own neighbors, or at a border."""
    m = nbr.shape[0]
    valid = 0
    for i in range(m):
        if not excluded[nbr[i]] and np.isfinite(normals[nbr[i], 0]):
            valid += 1
    best, count = -1, 0
    for i in range(min(m, FACE_CHOICES)):
        a = nbr[i]
        if excluded[a] or not np.isfinite(normals[a, 0]):
            continue
        c = 0
        for k in range(m):
            b = nbr[k]
            if excluded[b] or not np.isfinite(normals[b, 0]):
                continue
            if abs(normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1]
                   + normals[a, 2] * normals[b, 2]) >= FACE_AGREE:
                c += 1
        if c > count:
            best, count = a, c
    out = np.full(3, np.nan)
    if count < OWN_SHEET_RANK:
        return out, 0.0
    out[:] = 0.0
    for k in range(m):
        b = nbr[k]
        if excluded[b] or not np.isfinite(normals[b, 0]):
            continue
        dot = (normals[best, 0] * normals[b, 0] + normals[best, 1] * normals[b, 1]
               + normals[best, 2] * normals[b, 2])
        if abs(dot) >= FACE_AGREE:
            s = 1.0 if dot >= 0.0 else -1.0
            for d in range(3):
                out[d] += s * normals[b, d]
    return out / np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2), count / valid


@njit(parallel=True, cache=True)
def between_faces(points, query, nbr, normals, excluded, noise, out):
    """Flag the query points whose neighbors lie on two parallel faces of a thin wall and
    that lie on neither (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Nearest neighbors of each query point, nearest first (the point itself not listed).
    normals : ndarray, shape (n, 3)
        Unit normals of every point, arbitrary sign (NaN: none). The wall's normal at p is
        first the one most of its neighbors agree on (:func:`_consensus_normal`), then its
        faces' own (:func:`_faces_normal`).
    excluded : ndarray, shape (n,), bool
        Points that take no part (outliers already found).
    noise : float
        The cloud's noise (standard deviation across the surface): the faces' RMS distance
        is taken as at least this (fitted over a few dozen points it can read low, and an
        inlier 3.6 noise off its face was flagged).
    out : ndarray, shape (m,), bool
        Output flags.
    """
    for j in prange(query.shape[0]):
        out[j] = False
        nrm, agree = _consensus_normal(normals, nbr[j], excluded)
        if not np.isfinite(nrm[0]):
            continue
        h, u, v, where = sheet_heights(points, query[j], nrm, nbr[j], excluded)
        order, split = sheet_gap(h, FACE_LEAST)
        if split < 0:
            continue
        # The faces' own normal: the least direction of their points' spread about their
        # own face's centroid (the neighbors' normals tilt where this point, unflagged, was
        # among their neighbors, or beside the wall's border). Then split again along it.
        if not _faces_normal(points, nbr[j], where, order, split, nrm):
            continue
        h, u, v, _ = sheet_heights(points, query[j], nrm, nbr[j], excluded)
        order, split = sheet_gap(h, FACE_LEAST)
        # At an end of the wall (its neighbors behind it) only parallel faces have a gap
        # with nothing in it: a wedge's rounded tip lies between its faces' planes too, and
        # there half the normals are the other face's and the faces' planes part. Nearly
        # all the normals agree, or the planes fitted to the faces are parallel: by a
        # wall's cut the normals of a third of the points tilt past 10 degrees where
        # outliers were among their neighbors (the thin plate's seed 2: 0.70 agreed).
        if split < 0 or (at_an_end(u, v) and agree < FACE_END_AGREE
                         and not faces_parallel(h, u, v, order, split)):
            continue
        # Again without the points off both planes: an unflagged outlier among them tilts
        # the faces, and past a border every degree counts at the point's distance.
        order, split, first = _on_their_faces(h, u, v, order, split, noise)
        if split < FACE_LEAST or order.shape[0] - split < FACE_LEAST:
            continue
        if not _faces_normal(points, nbr[j], where, order, split, nrm):
            continue
        h, u, v, _ = sheet_heights(points, query[j], nrm, nbr[j], excluded)
        # One slope for both faces: the farther face often holds only a few points at the
        # list's edge, whose own plane would tilt with their noise.
        a_low, a_high, _, _, rms = _parallel_planes(h, u, v, order, split)
        # (NaN compares False: faces that span no plane flag nothing)
        out[j] = (min(abs(a_low), abs(a_high))
                  > FACE_SIGMAS * max(rms, FACE_TRIM_RMS * first, noise))
