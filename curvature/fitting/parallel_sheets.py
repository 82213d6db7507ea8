"""Fits over both faces of a thin wall with parallel faces (the default's standard errors).

An anchored fit on a wall a few spacings thick holds both of its faces: its points lie in
two layers, the wall's thickness apart along the normal. Where the faces are parallel the fit
reads their curvature well (docs/accuracy.md, section 9, step 25), but its RMS distance to
its surface is half the wall's thickness, not the noise, and the standard errors read from
it (the calibrated sigma and the model term of :func:`curvature.uncertainty.anchored_std`)
were 15 to 500 times its errors on the thin plate (docs/accuracy.md, section 10, stop 48).

A neighborhood holds two parallel sheets when its heights over the anchor's tangent plane
split into two groups (the split of the sorted heights with the largest gap between the
groups' means over their pooled standard deviation, each group at least
:data:`SHEET_SHARE` of the points) at least :data:`SHEET_GAP` pooled deviations apart, and
the planes fitted to the two groups have slopes within :data:`SHEET_SLOPE` of each other. A
wedge (a blade's sides near its trailing edge) is two sheets but not parallel: a fit across it
tilts with the wedge, and its residual is that misfit.

The same split keeps the curvature fits of a wall's points on their own face where their
neighbor lists hold both (:func:`own_sheet_lists`; beside a wall's open border a fit over
both faces read the border as a rounded rim; there, where the list lies behind the point
(:func:`at_an_end`), a wedge's faces are parted too), and finds the points between a wall's
faces (:func:`~curvature.fitting.outliers.between_faces`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .quadric import tangent_basis

__all__ = ["END_SIDE", "SHEET_GAP", "SHEET_K", "SHEET_SHARE", "SHEET_SLOPE", "WEDGE_ROUNDS",
           "WEDGE_SEED", "WEDGE_SEED_LEAST", "at_an_end", "faces_parallel", "own_sheet_lists",
           "parallel_sheets", "sheet_gap", "sheet_heights", "sheet_split", "wedge_split"]

#: Neighbors of the test: on the thin plate of 10,000 points (faces 3 spacings apart) the 48
#: nearest hold a fifth of the other face, the 96 nearest a third.
SHEET_K = 96
#: Smallest share of the points in each group.
SHEET_SHARE = 0.1
#: Smallest gap between the groups' mean heights, in pooled standard deviations: a single
#: noisy sheet split at its median reads about 2.7, the plate's faces 10 to 30.
SHEET_GAP = 6.0
#: Largest difference of the two groups' slopes (rise over run): 0.05 is 3 degrees; the
#: blade's wedge is 12 degrees. 0.1 let some fits near its trailing edge pass.
SHEET_SLOPE = 0.05
#: A point whose neighbors' centroid lies farther from it than this share of their RMS
#: distance is at an end of a wall, not inside it (:func:`at_an_end`).
END_SIDE = 0.45
#: A wedge's two faces (:func:`wedge_split`) are seeded on the nearest 1/WEDGE_SEED of a list,
#: at least WEDGE_SEED_LEAST points, whose heights leave a gap between the faces; over a whole
#: list of the blade's (384 points by its open ends) each face's heights slope with the
#: wedge by 2 spacings and close the gap.
WEDGE_SEED = 8
WEDGE_SEED_LEAST = 24
#: Rounds of fitting the two planes and moving every point to the nearer one.
WEDGE_ROUNDS = 3


@njit(cache=True)
def _plane_slope(h, u, v, idx, out):
    """Slope (du, dv) of the least-squares plane ``h = a + b u + c v`` over ``idx``, into
    ``out``; False where the points span no plane."""
    s1 = su = sv = suu = suv = svv = sh = suh = svh = 0.0
    for i in idx:
        s1 += 1.0
        su += u[i]
        sv += v[i]
        suu += u[i] * u[i]
        suv += u[i] * v[i]
        svv += v[i] * v[i]
        sh += h[i]
        suh += u[i] * h[i]
        svh += v[i] * h[i]
    # centred normal equations of (b, c)
    cuu = suu - su * su / s1
    cuv = suv - su * sv / s1
    cvv = svv - sv * sv / s1
    cuh = suh - su * sh / s1
    cvh = svh - sv * sh / s1
    det = cuu * cvv - cuv * cuv
    if not det > 1e-12 * max(cuu * cvv, 1e-300):
        return False
    out[0] = (cvv * cuh - cuv * cvh) / det
    out[1] = (cuu * cvh - cuv * cuh) / det
    return True


@njit(cache=True)
def _plane(h, u, v, idx, out):
    """Least-squares plane ``h = out[0] + out[1] u + out[2] v`` over ``idx``, into ``out``
    (3,); False where the points span no plane."""
    if idx.shape[0] < 3 or not _plane_slope(h, u, v, idx, out[1:]):
        return False
    mu = mv = mh = 0.0
    for i in idx:
        mu += u[i]
        mv += v[i]
        mh += h[i]
    out[0] = (mh - out[1] * mu - out[2] * mv) / idx.shape[0]
    return True


@njit(cache=True)
def sheet_heights(points, p, nrm, nbr, excluded):
    """Heights ``h`` over the plane through ``points[p]`` with unit normal ``nrm`` and
    tangent coordinates ``u, v`` of the points ``nbr`` not ``excluded`` (n,) bool (empty:
    none is); returns (h, u, v, where), ``where`` their positions in ``nbr``. Empty rather
    than n zeros: ``parallel_sheets`` runs once per chunk of a large cloud's anchors."""
    e1, e2 = tangent_basis(nrm)
    m = 0
    for i in range(nbr.shape[0]):
        if not (excluded.shape[0] and excluded[nbr[i]]):
            m += 1
    h, u, v = np.empty(m), np.empty(m), np.empty(m)
    where = np.empty(m, np.int64)
    c = 0
    for i in range(nbr.shape[0]):
        if excluded.shape[0] and excluded[nbr[i]]:
            continue
        d = points[nbr[i]] - points[p]
        h[c] = d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]
        u[c] = d[0] * e1[0] + d[1] * e1[1] + d[2] * e1[2]
        v[c] = d[0] * e2[0] + d[1] * e2[1] + d[2] * e2[2]
        where[c] = i
        c += 1
    return h, u, v, where


@njit(cache=True)
def sheet_gap(h, least):
    """The split of heights ``h`` into two sheets of at least ``least`` points each (module
    docstring), slopes not compared: returns ``(order, split)``, the heights' ascending order
    and the size of the lower group, or ``split = -1`` where no split reaches
    :data:`SHEET_GAP`."""
    m = h.shape[0]
    order = np.argsort(h)
    if m < 2 * least:
        return order, -1
    total = total2 = 0.0
    for i in range(m):
        total += h[i]
        total2 += h[i] * h[i]
    best, split = 0.0, -1
    low = low2 = 0.0
    for c in range(1, m):
        x = h[order[c - 1]]
        low += x
        low2 += x * x
        if c < least or m - c < least:
            continue
        lm = low / c
        hm = (total - low) / (m - c)
        within = (low2 - low * lm) + ((total2 - low2) - (total - low) * hm)
        if not within > 0.0:
            continue
        gap = (hm - lm) / np.sqrt(within / (m - 2))
        if gap > best:
            best, split = gap, c
    if best < SHEET_GAP:
        return order, -1
    return order, split


@njit(cache=True)
def faces_parallel(h, u, v, order, split):
    """Whether the planes fitted to the lower ``split`` and the other heights ``h`` (in
    ascending ``order``, at tangent coordinates ``u, v``) have slopes within
    :data:`SHEET_SLOPE`."""
    s_low, s_high = np.empty(2), np.empty(2)
    if not (_plane_slope(h, u, v, order[:split], s_low)
            and _plane_slope(h, u, v, order[split:], s_high)):
        return False
    return np.hypot(s_low[0] - s_high[0], s_low[1] - s_high[1]) < SHEET_SLOPE


@njit(cache=True)
def sheet_split(h, u, v):
    """The split of heights ``h`` (at tangent coordinates ``u, v``) into two parallel sheets
    (module docstring): as :func:`sheet_gap`, with ``split = -1`` also where the planes
    fitted to the two groups are not parallel."""
    order, split = sheet_gap(h, max(int(SHEET_SHARE * h.shape[0]), 3))
    if split < 0 or not faces_parallel(h, u, v, order, split):
        return order, -1
    return order, split


@njit(cache=True)
def at_an_end(u, v):
    """Whether the neighbors at tangent coordinates ``u, v`` (the point at the origin), shape
    (m,), lie to one side of it: their centroid farther from it than :data:`END_SIDE` times
    their RMS distance (a half disc reads 0.6, a full one 0; the blade's trailing tip 0.63)."""
    m = u.shape[0]
    cu = cv = r2 = 0.0
    for i in range(m):
        cu += u[i]
        cv += v[i]
        r2 += u[i] * u[i] + v[i] * v[i]
    return (cu * cu + cv * cv) / (m * m) > END_SIDE * END_SIDE * (r2 / m)


@njit(cache=True)
def wedge_split(h, u, v):
    """Two sheets of heights ``h`` at tangent coordinates ``u, v`` (m,), in list order
    (nearest first), that need not be parallel: a wedge's faces by its end.

    The nearest points (:data:`WEDGE_SEED`) are split at their heights' gap
    (:func:`sheet_gap`); a plane is fitted to each group, every point moves to the nearer
    plane and the planes are fitted again (:data:`WEDGE_ROUNDS` times).

    Returns
    -------
    upper : ndarray, shape (m,), bool
        Points on the plane that is the higher at the origin.
    own : bool
        Whether the origin (the anchor) lies nearer the higher plane.
    ok : bool
        Whether the planes lie at least :data:`SHEET_GAP` times the points' RMS distance from
        them apart at the origin, with at least :data:`SHEET_SHARE` of the points on each.
    """
    m = h.shape[0]
    upper = np.zeros(m, np.bool_)
    seed = min(m, max(WEDGE_SEED_LEAST, m // WEDGE_SEED))
    order, split = sheet_gap(h[:seed], max(int(SHEET_SHARE * seed), 3))
    if split < 0:
        return upper, False, False
    for c in range(split, seed):
        upper[order[c]] = True
    planes = np.empty((2, 3))
    fitted = seed  # the points the planes are fitted over: the seed's first, then all
    for _ in range(WEDGE_ROUNDS):
        if not _two_planes(h, u, v, upper[:fitted], planes):
            return upper, False, False
        fitted = m
        for i in range(m):
            upper[i] = abs(_above(h, u, v, i, planes[1])) < abs(_above(h, u, v, i, planes[0]))
    if not _two_planes(h, u, v, upper, planes):
        return upper, False, False
    high = 0
    ss = 0.0
    for i in range(m):
        if upper[i]:
            high += 1
        ss += _above(h, u, v, i, planes[1 if upper[i] else 0]) ** 2
    rms = np.sqrt(ss / max(m - 6, 1))
    ok = (min(high, m - high) >= max(int(SHEET_SHARE * m), 3)
          and planes[1, 0] - planes[0, 0] >= SHEET_GAP * rms)
    # the origin (the anchor, height 0) lies on the plane nearer to it there
    return upper, abs(planes[1, 0]) < abs(planes[0, 0]), ok


@njit(cache=True)
def _above(h, u, v, i, plane):
    """Height of point ``i`` above ``plane`` (a, b, c: ``h = a + b u + c v``)."""
    return h[i] - plane[0] - plane[1] * u[i] - plane[2] * v[i]


@njit(cache=True)
def _two_planes(h, u, v, upper, planes):
    """Planes (2, 3) fitted to the points ``upper`` marks False and True, shape (f,), the
    first f of ``h, u, v``; False where either spans no plane."""
    return (_plane(h, u, v, np.flatnonzero(~upper), planes[0])
            and _plane(h, u, v, np.flatnonzero(upper), planes[1]))


@njit(parallel=True, cache=True)
def parallel_sheets(points, anchors, normals, indptr, indices, out):
    """Whether each anchor's neighbors lie on two parallel sheets (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    anchors : ndarray, shape (a,), int64
    normals : ndarray, shape (a, 3)
        Unit normals at the anchors (NaN: the test fails).
    indptr, indices : ndarray
        CSR neighbor lists of the anchors.
    out : ndarray, shape (a,), bool
        Output.
    """
    none = np.zeros(0, np.bool_)  # nothing excluded (sheet_heights)
    for j in prange(anchors.shape[0]):
        out[j] = False
        nrm = normals[j]
        if not (np.isfinite(nrm[0]) and np.isfinite(nrm[1]) and np.isfinite(nrm[2])):
            continue
        h, u, v, _ = sheet_heights(points, anchors[j], nrm, indices[indptr[j]:indptr[j + 1]], none)
        out[j] = sheet_split(h, u, v)[1] >= 0


@njit(parallel=True, cache=True)
def own_sheet_lists(points, anchors, normals, indptr, indices, test, excluded, keep):
    """Mark, in each tested anchor's neighbor list, the entries on the anchor's own sheet.

    Where the list's points (those not ``excluded``) lie on two parallel sheets, the entries
    of the sheet on the far side of the gap between them from the anchor (the wall's other
    face) are marked False; every other entry stays True. Where the list lies behind the
    anchor (:func:`at_an_end`: by a wall's open border) two sheets need not be parallel,
    and where their heights leave no gap over the whole list they are told apart as two
    planes (:func:`wedge_split`): there a wedge's fit over both faces read the border as a
    rim too (the blade's sides by its extrusion's open ends, docs/accuracy.md, section 9,
    step 42).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    anchors : ndarray, shape (a,), int64
    normals : ndarray, shape (n, 3)
        Unit normals of every point, arbitrary sign (NaN: the anchor's list is kept whole).
    indptr, indices : ndarray
        CSR neighbor lists of the anchors, nearest first.
    test : ndarray, shape (a,), bool
        Anchors whose lists are tested.
    excluded : ndarray, shape (n,), bool
        Points that take no part in the split (outliers); they stay in the lists.
    keep : ndarray, shape (indices.shape[0],), bool
        Output.
    """
    for j in prange(anchors.shape[0]):
        lo, hi = indptr[j], indptr[j + 1]
        keep[lo:hi] = True
        p = anchors[j]
        nrm = normals[p]
        if not (test[j] and np.isfinite(nrm[0]) and np.isfinite(nrm[1])
                and np.isfinite(nrm[2])):
            continue
        h, u, v, where = sheet_heights(points, p, nrm, indices[lo:hi], excluded)
        order, split = sheet_gap(h, max(int(SHEET_SHARE * h.shape[0]), 3))
        end = at_an_end(u, v)
        if split >= 0 and (end or faces_parallel(h, u, v, order, split)):
            # the anchor's height is 0: its sheet is the group on its side of the gap's middle
            low_own = 0.0 < 0.5 * (h[order[split - 1]] + h[order[split]])
            start, stop = (split, h.shape[0]) if low_own else (0, split)
            for c in range(start, stop):
                keep[lo + where[order[c]]] = False
        elif split < 0 and end:
            upper, own, ok = wedge_split(h, u, v)
            if not ok:
                continue
            for c in range(h.shape[0]):
                if upper[c] != own:
                    keep[lo + where[c]] = False
