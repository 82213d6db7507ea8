"""Circle fits at the tip of a thin wedge: a blade's sharp trailing edge.

Where the two faces of a thin wall converge at a small angle and meet in a rounded edge of a
radius below a point spacing or two, no patch of the surface resolves the edge: a handful of
points lie on its arc, each with noise of a fair share of its radius. The default's fits read
it about flat (the bench's blade, trailing edge of k = 100 at 0.7 spacings: 0 to 1.4 at 0.1 %
noise; docs/accuracy.md section 9, step 33), and so do the circles across rounded edges
(:mod:`curvature.fitting.rounded_edge`), which need the arc itself sampled.

The faces, though, are sampled well, and they fix the edge's radius: a circle of radius r
tangent to two lines that meet at half-angle alpha has its centre r / sin(alpha) from their
apex, so the tip ends r (1 / sin(alpha) - 1) short of it. The apex comes from the two faces'
lines, each fitted to many points; where the tip ends, from every point around it. Across the
edge, in the plane normal to its axis, this module fits that profile: two lines and the circle
tangent to both (a facts-only use of elementary geometry; the least-squares line fits and the
one-parameter fit of r are textbook).

A wall whose faces run parallel ends in a half circle of half their distance: its faces fix
the radius too (the thin plate's rims, 1.5 spacings; docs/accuracy.md section 9, step 36).
There only the centre's place along the mid-line is fitted, and a wall's open border (where
its faces just stop) must not read as an end: its points lie on the faces' lines run on past
it, which :data:`WALL_GAIN` and the arc's crown (:data:`CROWN_COS`) tell apart.

At a point p, over its :data:`WEDGE_K` nearest neighbors:

1. the wall's mid-plane: the smallest principal axis of the neighbors' positions splits them
   into the two faces; a plane fitted to each face, whose normals' cross product is the
   edge's axis (faces within :data:`ALPHA_MIN` degrees of parallel: a wall, where they lie
   :data:`WALL_NOISE` noise apart, whose axis lies in the mid-plane across the way back);
2. in the plane normal to the axis, the profile's direction toward the edge (p must lie
   within :data:`BACK_SHARE` of the profile's length of its end), and a line fitted to each
   face's points at least that share behind the end;
3. their apex, half-angle alpha (at most :data:`ALPHA_MAX`) and, over the points within
   :data:`WINDOW_SHARE` of that length of the end, the radius r whose profile (the lines up
   to where the circle touches them, the arc between) is nearest to the points; on a wall
   (lines within :data:`ALPHA_MIN` of parallel) r is half their distance, and the centre's
   place along the mid-line is what is fitted;
4. the fit is usable where its RMS distance is within :data:`FIT_NOISE` of the noise, each
   face's line within :data:`SIDE_NOISE`, at least :data:`MIN_ARC` points lie on the arc,
   and ``1 / r`` is at least :data:`SIGNIFICANCE` standard errors (from the radius's own fit
   and from the apex's, through r = D sin(alpha) / (1 - sin(alpha)) with D the apex's
   distance from the tip; on a wall, from the lines' distance), and on a wall at least
   :data:`MIN_ARC` points lie within 45 degrees of the arc's crown and the arc fits the
   window better than the faces' lines alone by :data:`WALL_GAIN` squared noise.

A point reads the edge where it lies on the arc within :data:`ON_ARC_NOISE` noise; a point of
a face near the tip (as near as p is to the profile's end, step 2), at least
:data:`FACE_MARGIN` noise beyond where the arc meets it, reads that face: its curvature across
the edge from a parabola over the face's own points in the profile plane, and its normal
(docs/accuracy.md section 9, step 34).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import cholesky, jacobi3, solve_lower, solve_upper_t

__all__ = ["ALPHA_MAX", "ALPHA_MIN", "BACK_SHARE", "FACE_MARGIN", "FIT_NOISE", "MIN_ARC",
           "MIN_SIDE", "ON_ARC_NOISE", "PRE_K", "SIDE_NOISE", "SIGNIFICANCE", "WALL_NOISE",
           "WEDGE_K", "WINDOW_SHARE", "wedge_tip_fits"]

#: Neighbors of a point the profile is fitted to.
WEDGE_K = 384
#: Neighbors of the first test of the faces (step 1).
PRE_K = 64
#: Smallest half-angle between the faces (degrees): nearer parallel, the apex is far off, and
#: the edge is read as a wall's rounded end instead (:data:`WALL_NOISE`).
ALPHA_MIN = 1.0
#: Faces within ALPHA_MIN of parallel are a wall's two faces where their centroids lie at least
#: this many noise apart across them (a single noisy sheet's two halves: about 1.6), and its
#: end is the half circle of half the wall's thickness.
WALL_NOISE = 4.0
#: Largest half-angle (degrees): a wider edge is no thin wall, and its arc is sampled.
ALPHA_MAX = 35.0
#: The faces' lines are fitted to the points at least this share of the profile's length
#: behind its end (the arc and its tangency points lie well inside it).
BACK_SHARE = 0.3
#: The radius is fitted to the points within this share of the profile's length of its end.
WINDOW_SHARE = 0.4
#: Least points of each face's line.
MIN_SIDE = 8
#: Least points on the arc (between its tangency points).
MIN_ARC = 3
#: Largest RMS distance of a face's points to its line, in noise.
SIDE_NOISE = 2.0
#: Largest RMS distance of the window's points to the fitted profile, in noise.
FIT_NOISE = 2.0
#: Least ratio of the curvature to its standard error.
SIGNIFICANCE = 4.0
#: A point reads the edge within this many noise of its arc.
ON_ARC_NOISE = 3.0
#: A point of a face reads the face's own curvature where it lies at least this many noise
#: beyond where the arc meets it.
FACE_MARGIN = 1.0
#: A wall's end is read where its arc lies nearer the window's points than the faces' lines
#: run on past it (an open border, where the faces just stop) by at least this many squared
#: noise in their sum.
WALL_GAIN = 50.0
#: cos(45 degrees): the share of a wall end's radius its crown's points lie beyond the centre.
CROWN_COS = np.sqrt(0.5)
_GRID = 24
_GOLDEN = 40
#: A pivot of the face's parabola below this share of the largest counts as rank deficient.
RANK_TOL = 1e-12


@njit(cache=True)
def _smallest_axis(points, nbr, side, want, centre, mean, out):
    """Smallest principal axis of the points of ``nbr`` whose ``side`` is ``want`` (all of
    them where ``want`` is -1), written to ``out``, and their mean offset from ``centre`` to
    ``mean``; returns how many points it used (nothing is written under 3)."""
    m = 0
    for c in range(3):
        mean[c] = 0.0
    for i in range(nbr.shape[0]):
        if want < 0 or side[i] == want:
            for c in range(3):
                mean[c] += points[nbr[i], c] - centre[c]
            m += 1
    if m < 3:
        return m
    for c in range(3):
        mean[c] /= m
    cov = np.zeros((3, 3))
    for i in range(nbr.shape[0]):
        if want < 0 or side[i] == want:
            for r in range(3):
                dr = points[nbr[i], r] - centre[r] - mean[r]
                for c in range(3):
                    cov[r, c] += dr * (points[nbr[i], c] - centre[c] - mean[c])
    vec = np.empty((3, 3))
    i0, _, _ = jacobi3(cov, vec)
    for c in range(3):
        out[c] = vec[c, i0]
    return m


@njit(cache=True)
def _line(u, v, use):
    """Least-squares line ``v = a + b u`` over ``use``: (a, b, rms, var_a, var_b, cov_ab, m);
    m = 0 where it is undetermined."""
    m = 0
    su = sv = suu = suv = 0.0
    for i in range(u.shape[0]):
        if use[i]:
            m += 1
            su += u[i]
            sv += v[i]
            suu += u[i] * u[i]
            suv += u[i] * v[i]
    det = m * suu - su * su
    if m < MIN_SIDE or not det > 0.0:
        return 0.0, 0.0, np.inf, np.inf, np.inf, 0.0, 0
    b = (m * suv - su * sv) / det
    a = (sv - b * su) / m
    ss = 0.0
    for i in range(u.shape[0]):
        if use[i]:
            d = v[i] - a - b * u[i]
            ss += d * d
    s2 = ss / max(m - 2, 1)
    return a, b, np.sqrt(ss / m), s2 * suu / det, s2 * m / det, -s2 * su / det, m


@njit(cache=True)
def _parabola(u, v, use):
    """Least-squares ``v = a + b u + c u^2`` over ``use``: (b, c, var_c); var_c is inf where
    it is undetermined."""
    g = np.zeros((3, 3))
    rhs = np.zeros(3)
    m = 0
    for i in range(u.shape[0]):
        if use[i]:
            m += 1
            t = np.array([1.0, u[i], u[i] * u[i]])
            for r in range(3):
                rhs[r] += t[r] * v[i]
                for c in range(3):
                    g[r, c] += t[r] * t[c]
    if m < MIN_SIDE:
        return 0.0, 0.0, np.inf
    low, ok = cholesky(g, RANK_TOL)
    if not ok:
        return 0.0, 0.0, np.inf
    coef = solve_upper_t(low, solve_lower(low, rhs))
    # (g^-1)[2, 2] = |L^-1 e_2|^2
    e2 = solve_lower(low, np.array([0.0, 0.0, 1.0]))
    ss = 0.0
    for i in range(u.shape[0]):
        if use[i]:
            d = v[i] - coef[0] - coef[1] * u[i] - coef[2] * u[i] * u[i]
            ss += d * d
    s2 = ss / max(m - 3, 1)
    return coef[1], coef[2], s2 * (e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2])


@njit(cache=True)
def _profile_distance(x, y, r, cx, half, sin_a, cos_a):
    """Signed distance of (x, y) (x along the bisector from the apex into the wedge, y across
    it) to the profile of radius r centred at (cx, 0): the arc before its tangency points,
    the faces' lines beyond (``|y| cos_a - x sin_a = half``); positive outside the material.
    A wedge has cx = r / sin_a and half 0; a wall's end sin_a 0, cos_a 1 and half r."""
    ty = abs(y)
    along = x * cos_a + ty * sin_a  # position along the face's line
    if along < cx * cos_a:  # the tangency point: the centre's foot on the line
        return np.hypot(x - cx, y) - r, True
    return ty * cos_a - x * sin_a - half, False


@njit(cache=True)
def _shape(t, wall, r_wall, sin_a, cos_a):
    """The profile fitted for parameter ``t``: (r, cx, half) of :func:`_profile_distance`,
    t the radius on a wedge, the centre's position on a wall's end of radius ``r_wall``."""
    if wall:
        return r_wall, t, r_wall
    return t, t / sin_a, 0.0


@njit(cache=True)
def _misfit(x, y, near, t, wall, r_wall, sin_a, cos_a):
    """Sum of squared distances of the ``near`` points to the profile of parameter ``t``."""
    r, cx, half = _shape(t, wall, r_wall, sin_a, cos_a)
    s = 0.0
    for i in range(x.shape[0]):
        if near[i]:
            d, _ = _profile_distance(x[i], y[i], r, cx, half, sin_a, cos_a)
            s += d * d
    return s


@njit(cache=True)
def _best(x, y, near, lo, hi, wall, r_wall, sin_a, cos_a):
    """The parameter in (lo, hi] whose profile lies nearest the ``near`` points: a grid of
    :data:`_GRID` steps, then a golden-section search about its best; returns it and
    whether it lies within half a step of ``hi`` (the window holds no better one)."""
    step = (hi - lo) / _GRID
    best_t, best_f = hi, np.inf
    for g in range(1, _GRID + 1):
        t = lo + step * g
        f = _misfit(x, y, near, t, wall, r_wall, sin_a, cos_a)
        if f < best_f:
            best_f, best_t = f, t
    a, b = max(best_t - step, lo + 1e-12 * (hi - lo)), min(best_t + step, hi)
    phi = 0.5 * (np.sqrt(5.0) - 1.0)
    c1, c2 = b - phi * (b - a), a + phi * (b - a)
    f1 = _misfit(x, y, near, c1, wall, r_wall, sin_a, cos_a)
    f2 = _misfit(x, y, near, c2, wall, r_wall, sin_a, cos_a)
    for _ in range(_GOLDEN):
        if f1 < f2:
            b, c2, f2 = c2, c1, f1
            c1 = b - phi * (b - a)
            f1 = _misfit(x, y, near, c1, wall, r_wall, sin_a, cos_a)
        else:
            a, c1, f1 = c1, c2, f2
            c2 = a + phi * (b - a)
            f2 = _misfit(x, y, near, c2, wall, r_wall, sin_a, cos_a)
    t = 0.5 * (a + b)
    return t, t >= hi - 0.5 * step


@njit(cache=True)
def _faces(points, nbr, m, centre, noise, mean, thin, side, axis):
    """The wall's two faces over ``nbr[:m]``: their mean offset from ``centre`` (``mean``),
    the mid-plane's normal (``thin``), each point's face (``side``) and the edge's unit axis,
    all written in place.

    Returns 1 where the faces' planes lie more than :data:`ALPHA_MIN` from parallel (the
    axis is their normals' cross product); 2 where they lie within it, but at least
    :data:`WALL_NOISE` noise apart (a wall's end: the axis lies in the mid-plane, across
    the way from the neighbors' mean to ``centre``); 0 where neither holds (one sheet's two
    halves) or a face has fewer than :data:`MIN_SIDE` points.
    """
    if _smallest_axis(points, nbr[:m], side[:m], -1, centre, mean, thin) < 3:
        return 0
    for i in range(m):
        s = 0.0
        for c in range(3):
            s += (points[nbr[i], c] - centre[c] - mean[c]) * thin[c]
        side[i] = 1 if s > 0.0 else 0
    n1, n0, at1, at0 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    if _smallest_axis(points, nbr[:m], side[:m], 1, centre, at1, n1) < MIN_SIDE or \
            _smallest_axis(points, nbr[:m], side[:m], 0, centre, at0, n0) < MIN_SIDE:
        return 0
    axis[0] = n1[1] * n0[2] - n1[2] * n0[1]
    axis[1] = n1[2] * n0[0] - n1[0] * n0[2]
    axis[2] = n1[0] * n0[1] - n1[1] * n0[0]
    sa = np.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    if sa >= np.sin(np.radians(2.0 * ALPHA_MIN)):
        axis /= sa
        return 1
    gap = 0.0
    for c in range(3):
        gap += (at1[c] - at0[c]) * thin[c]
    if not abs(gap) >= WALL_NOISE * noise:
        return 0
    back = mean - (mean[0] * thin[0] + mean[1] * thin[1] + mean[2] * thin[2]) * thin
    axis[0] = thin[1] * back[2] - thin[2] * back[1]
    axis[1] = thin[2] * back[0] - thin[0] * back[2]
    axis[2] = thin[0] * back[1] - thin[1] * back[0]
    sa = np.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    if not sa > 0.0:
        return 0
    axis /= sa
    return 2


@njit(cache=True)
def _fit_one(points, p, nbr, noise, out):
    """The wedge profile at ``p`` over ``nbr`` (module docstring): ``out`` = (k, standard
    error, normal (3), across direction (3), axis (3), 0 on the arc or 1 on a face);
    returns whether usable."""
    m = nbr.shape[0]
    centre = points[p]
    # 1. mid-plane and faces; on the first PRE_K neighbors first, which turns down most
    # points (one sheet's two halves lie within ALPHA_MIN of parallel) at a sixth of the cost
    mean, thin, axis = np.empty(3), np.empty(3), np.empty(3)
    side = np.empty(m, np.int8)
    if _faces(points, nbr, min(PRE_K, m), centre, noise, mean, thin, side, axis) == 0:
        return False
    if _faces(points, nbr, m, centre, noise, mean, thin, side, axis) == 0:
        return False
    # 2. the profile plane: e1 along the wall (toward its end), e2 across it
    e1 = np.array([axis[1] * thin[2] - axis[2] * thin[1], axis[2] * thin[0] - axis[0] * thin[2],
                   axis[0] * thin[1] - axis[1] * thin[0]])
    e1 /= np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    if mean[0] * e1[0] + mean[1] * e1[1] + mean[2] * e1[2] > 0.0:
        e1 = -e1  # the material lies behind p
    e2 = np.array([axis[1] * e1[2] - axis[2] * e1[1], axis[2] * e1[0] - axis[0] * e1[2],
                   axis[0] * e1[1] - axis[1] * e1[0]])
    u, v = np.empty(m), np.empty(m)
    for i in range(m):
        su = sv = 0.0
        for c in range(3):
            d = points[nbr[i], c] - centre[c]
            su += d * e1[c]
            sv += d * e2[c]
        u[i], v[i] = su, sv
    first, second, low = -np.inf, -np.inf, np.inf
    for i in range(m):
        low = min(low, u[i])
        if u[i] > first:
            first, second = u[i], first
        elif u[i] > second:
            second = u[i]
    end = second  # the second farthest: one noisy point does not set it
    length = end - low
    if not length > 0.0 or end > BACK_SHARE * length:
        return False  # p lies far from the profile's end (whether on its arc: step 4)
    back = u < end - BACK_SHARE * length
    use1, use0 = back & (side == 1), back & (side == 0)
    a1, b1, rms1, va1, vb1, cab1, m1 = _line(u, v, use1)
    a0, b0, rms0, va0, vb0, cab0, m0 = _line(u, v, use0)
    if m1 == 0 or m0 == 0 or rms1 > SIDE_NOISE * noise or rms0 > SIDE_NOISE * noise:
        return False
    # 3. apex and half-angle; the faces converge toward the end (or a wall's faces run
    # parallel: the mid-line, toward the end, from its point at u = 0)
    t1 = np.array([1.0, b1]) / np.hypot(1.0, b1)
    t0 = np.array([1.0, b0]) / np.hypot(1.0, b0)
    cos2a = min(max(t1[0] * t0[0] + t1[1] * t0[1], -1.0), 1.0)
    alpha = 0.5 * np.arccos(cos2a)
    wall = alpha < np.radians(ALPHA_MIN)
    if wall:
        ua, va = 0.0, 0.5 * (a1 + a0)
        sin_a, cos_a = 0.0, 1.0
    else:
        if not b1 != b0:
            return False
        ua = (a0 - a1) / (b1 - b0)
        va = a1 + b1 * ua
        if not ua > end or alpha > np.radians(ALPHA_MAX):
            return False
        sin_a, cos_a = np.sin(alpha), np.cos(alpha)
    bx, by = t1[0] + t0[0], t1[1] + t0[1]
    nb = np.hypot(bx, by)
    bx, by = bx / nb, by / nb  # bisector, toward the apex (the end)
    x, y = np.empty(m), np.empty(m)
    for i in range(m):
        du, dv = u[i] - ua, v[i] - va
        x[i] = -(du * bx + dv * by)
        y[i] = -du * by + dv * bx
    xmin = np.inf
    for i in range(m):
        xmin = min(xmin, x[i])
    near = x < xmin + WINDOW_SHARE * length
    if wall:
        # the radius is half the faces' distance; the centre's place along the mid-line:
        # within a radius before the nearest point to the end and three after it
        r = 0.5 * abs(a1 - a0) / np.hypot(1.0, 0.5 * (b1 + b0))
        if not 2.0 * r >= WALL_NOISE * noise:
            return False  # one sheet's two halves
        cx, edge = _best(x, y, near, xmin - r, xmin + 3.0 * r, True, r, sin_a, cos_a)
        if edge or cx <= xmin - r + 2.0 * r / _GRID:
            return False  # the window holds no end
        half = r
    else:
        # the radius: over the sizes the window can hold
        r_hi = (xmin + WINDOW_SHARE * length) * sin_a
        if not r_hi > 0.0:
            return False
        r, edge = _best(x, y, near, 0.0, r_hi, False, 0.0, sin_a, cos_a)
        if edge:
            return False  # the window holds no end of the fitted size
        cx, half = r / sin_a, 0.0
    # 4. usable?
    count = 0
    arc = 0
    crown = 0  # on a wall's end, the arc's points within 45 degrees of its crown
    open_ss = 0.0  # the window's squared distances to a wall's faces run on past its end
    jj = 0.0
    step = 1e-3 * r
    for i in range(m):
        if near[i]:
            count += 1
            d, on = _profile_distance(x[i], y[i], r, cx, half, sin_a, cos_a)
            arc += on
            if wall:
                crown += x[i] < cx - CROWN_COS * r and abs(d) <= ON_ARC_NOISE * noise
                open_ss += (abs(y[i]) - half) ** 2
            else:
                dp, _ = _profile_distance(x[i], y[i], r + step, (r + step) / sin_a, 0.0,
                                          sin_a, cos_a)
                dm, _ = _profile_distance(x[i], y[i], r - step, (r - step) / sin_a, 0.0,
                                          sin_a, cos_a)
                g = (dp - dm) / (2.0 * step)
                jj += g * g
    rms = np.sqrt(_misfit(x, y, near, cx if wall else r, wall, r, sin_a, cos_a)
                  / max(count - 1, 1))
    if count < MIN_SIDE or arc < MIN_ARC or rms > FIT_NOISE * noise:
        return False
    if wall:
        if crown < MIN_ARC or open_ss - rms * rms * max(count - 1, 1) < WALL_GAIN * noise * noise:
            return False  # a wall's open border: its faces stop, no arc joins them
        # the faces' distance at u = 0 (p's place along the wall, near its end)
        var_r = 0.25 * (va1 + va0)
    else:
        if not jj > 0.0:
            return False
        # the apex's error along the bisector, through r = D sin(alpha) / (1 - sin(alpha))
        db = b1 - b0
        g_a1, g_a0 = -1.0 / db, 1.0 / db
        g_b1, g_b0 = -(a0 - a1) / (db * db), (a0 - a1) / (db * db)
        var_ua = (g_a1 * g_a1 * va1 + g_b1 * g_b1 * vb1 + 2.0 * g_a1 * g_b1 * cab1
                  + g_a0 * g_a0 * va0 + g_b0 * g_b0 * vb0 + 2.0 * g_a0 * g_b0 * cab0)
        var_r = rms * rms / jj + max(var_ua, 0.0) * (bx * bx) * (sin_a / (1.0 - sin_a)) ** 2
    k = 1.0 / r
    se = np.sqrt(var_r) / (r * r)
    if not k >= SIGNIFICANCE * se:
        return False
    # p on the arc, or on a face beyond where the arc meets it?
    px, py = -(-ua * bx - va * by), ua * by - va * bx
    d, on = _profile_distance(px, py, r, cx, half, sin_a, cos_a)
    if abs(d) > ON_ARC_NOISE * noise:
        return False
    if on:  # normal: from the circle's centre through p, outward
        nx, ny = px - cx, py
        nn = np.hypot(nx, ny)
        if not nn > 0.0:
            return False
        nx, ny = nx / nn, ny / nn
        # back to (u, v): x = -(du bx + dv by), y = -du by + dv bx
        nu = -nx * bx - ny * by
        nv = -nx * by + ny * bx
        out[11] = 0.0
    else:
        if px * cos_a + abs(py) * sin_a < cx * cos_a + FACE_MARGIN * noise:
            return False  # within noise of where the arc meets the face
        # p's face: the nearer line at p (u = 0); its outward side is away from the other
        on1 = abs(a1) < abs(a0)
        slope, bend, var_bend = _parabola(u, v, use1 if on1 else use0)
        if not np.isfinite(var_bend):
            return False
        sgn = 1.0 if (a1 > a0) == on1 else -1.0  # +1 on the face with the larger v
        w = (1.0 + slope * slope) ** 1.5  # (p is at u = 0)
        k = -sgn * 2.0 * bend / w  # positive where the face bulges outward
        se = 2.0 * np.sqrt(var_bend) / w
        nn = np.hypot(slope, 1.0)
        nu, nv = -sgn * slope / nn, sgn / nn
        out[11] = 1.0
    out[0], out[1] = k, se
    for c in range(3):
        out[2 + c] = nu * e1[c] + nv * e2[c]
    normal = out[2:5]
    across = np.array([axis[1] * normal[2] - axis[2] * normal[1],
                       axis[2] * normal[0] - axis[0] * normal[2],
                       axis[0] * normal[1] - axis[1] * normal[0]])
    for c in range(3):
        out[5 + c] = across[c]
        out[8 + c] = axis[c]
    return True


@njit(parallel=True, cache=True)
def wedge_tip_fits(points, query, nbr, noise, out):
    """Wedge-tip fits at ``query`` (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k), int
        Each point's nearest neighbors, nearest first; -1 marks one left out (an outlier).
    noise : float
        The cloud's noise (length unit).
    out : ndarray, shape (m, 12)
        Output: the curvature across the edge (1 / r on the arc, the face's on a face; NaN
        where no usable fit reads the point), its standard error, the outward normal (3) at
        the point, the direction across the edge (3), the edge's axis (3), and 0 where the
        point reads the arc, 1 where it reads a face.
    """
    for j in prange(query.shape[0]):
        out[j, 0] = np.nan
        row = nbr[j]
        m = 0
        for i in range(row.shape[0]):
            if row[i] >= 0:
                m += 1
        if m < 4 * MIN_SIDE:
            continue
        use = np.empty(m, np.int64)
        m = 0
        for i in range(row.shape[0]):
            if row[i] >= 0:
                use[m] = row[i]
                m += 1
        buf = np.empty(12)
        if _fit_one(points, query[j], use, noise, buf):
            for c in range(12):
                out[j, c] = buf[c]
