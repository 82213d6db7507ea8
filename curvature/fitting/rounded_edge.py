"""Circle fits across rounded thin edges: a plate's rim, a blade's leading edge.

Where a thin wall ends in a rounded edge, the surface turns by about half a turn within a few
point spacings. No height function over a tangent plane follows it (the wall's faces stand
upright on the plane): the default's anchored fits misread it or find it unsupported (the
bench's plate's rims of 1.5 spacings' radius, k = 33, read 18 on average at 0.1 % noise;
docs/accuracy.md section 9). Across the edge, though, the points lie on a circle: in the
plane normal to the edge's axis they are a circular arc, continued by the faces' lines. This
module fits that circle (a facts-only use of the classic algebraic and geometric circle fits:
I. Kasa, IEEE Trans. Instrum. Meas. 25, 1976; N. Chernov, *Circular and Linear Regression*,
2010).

At a point, for each size K of a short ladder of nearest-neighbor lists (:data:`EDGE_LADDER`):

1. the axis: the eigenvector of the smallest eigenvalue of ``sum n n^T`` over the first
   neighbors' normals (their sign does not matter); the middle eigenvalue's share says how
   far the normals fan out around it (:data:`FAN_MIN`);
2. the neighbors in the plane normal to the axis, and a circle fitted to them (Kasa's
   algebraic fit), trimmed to the points within :data:`TRIM_NOISE` noise of it and, after two
   rounds, to those whose normal points along the radius within :data:`NORMAL_TOLERANCE`
   degrees, which leaves out the faces beyond the arc but for a band at each of its ends;
3. Gauss-Newton on the geometric distance, then the same once more without the inliers of
   those two bands, whose faces pull the circle wide (the bench's blade's leading edge,
   K = 192: k read 1.0 low with them, 0.04 without);
4. its curvature ``1 / R`` and standard error (least-squares covariance of the geometric
   fit), the angle its inliers span around the centre and the largest gap between them.

A circle is usable with at least :data:`MIN_INLIERS` inliers, a radius of at least
:data:`RADIUS_NOISE` noise, a curvature of at least :data:`SIGNIFICANCE` standard errors, no
gap along its arc above :data:`GAP_MAX` degrees and, under :data:`SMALL_RADIUS_NOISE` noise,
no more than :data:`BEYOND_MAX` points beyond its arc (a wedge's sides run on past it). A
point reads an edge where a usable circle spans at least :data:`SPAN_GATE` degrees (the
bench's blade's leading edge about 200, a plate's rim 220; a fillet between faces at right
angles 140); the size kept is the largest whose curvature agrees with every smaller one
within :data:`AGREEMENT` of their summed standard errors (Lepski's rule, as the default's
scale selection). The curvature along the axis is the slope of the inliers' normals' axial
component against their axial offset.

The point takes the circle's curvatures, its radius as normal and the axis as a principal
direction where it lies on the circle (within :data:`TRIM_NOISE` noise) and inside the arc
without its end bands (:func:`read_edge_circles`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import cholesky, jacobi3, solve_lower, solve_spd

__all__ = ["AGREEMENT", "AXIS_MIN", "BEYOND_MAX", "EDGE_FAN_K", "EDGE_FLAT", "EDGE_FLAT_NOISE",
           "EDGE_KEEP", "EDGE_LADDER", "EDGE_NORMAL_K", "FAN_MIN", "GAP_MAX", "MIN_INLIERS",
           "NORMAL_TOLERANCE", "RADIUS_NOISE", "SIGNIFICANCE", "SMALL_RADIUS_NOISE", "SPAN_GATE",
           "TRIM_NOISE", "edge_circle_fits", "read_edge_circles", "worth_trying", "wraps"]

#: Points whose stage-1 neighborhood's flatness (smallest covariance eigenvalue over the
#: trace, :func:`~curvature.fitting.normal_field.pca_flatness`) is at least this are tried: a
#: noisy plane at 0.1 % noise reads 0.001, fillets of 6 spacings 0.006 to 0.02, leading edges
#: of 2.6 and 3.5 spacings at least 0.039 and 0.021 (1st percentile), a plate's rim 0.11. Of
#: the real scans' points 6 % (bun000) to 34 % (PCL's scenes) are tried (0.01: 15 to 74 %).
EDGE_FLAT = 0.018
#: ... and at least this many times what noise alone makes of a flat neighborhood of radius
#: r, ``2 sigma^2 / r^2`` (a disk's in-plane variances are r^2 / 4). On a torus at 0.1 %
#: noise the flatness reads that noise: 6,210 of 100,000 points were tried by EDGE_FLAT
#: alone, and at a million points (sigma about a spacing) the circle fits took 9.9 s of 27.6;
#: with this, no point. On the bench's plate and blade this bound is 0.003 and 0.006, under
#: EDGE_FLAT; 4 left some of the 20,000-point blade's leading edge untried (0.313 -> 0.357
#: on seed 2).
EDGE_FLAT_NOISE = 2.0
#: Neighbors whose normals must fan out (:func:`wraps`) for a point to be fitted.
EDGE_FAN_K = 24
#: The circle fits read PCA normals over this many nearest neighbors.
EDGE_NORMAL_K = 16
#: List sizes of the circle ladder. 24 is left out: its circles err by 1 to 4 times those of
#: 48 and, kept where 48 disagreed, read a leading edge of k = 20 as 35.
EDGE_LADDER = (48, 96, 192)
#: A point keeps its anchored fit where that agrees with its circle within this many of the
#: circle's standard errors, in k1 and in k2.
EDGE_KEEP = 2.0
#: Normals of this many nearest neighbors (at most) give the axis; at least AXIS_MIN of them
#: must be usable.
AXIS_K = 48
AXIS_MIN = 12
#: Share of ``sum n n^T``'s trace in its middle eigenvalue below which the normals do not fan
#: out around an axis: normals spread uniformly over a fan of angle a give
#: ``1/2 - sin(a) / (2 a)``: 0.13 for 75 degrees, 0.5 for a half turn.
FAN_MIN = 0.08
#: Inliers lie within this many noise standard deviations of the circle.
TRIM_NOISE = 3.0
#: ... and, after two rounds, have their normal along the circle's radius within this angle
#: (degrees). 15 left too few inliers on a rim of 1.5 spacings (PCA normals there turn
#: slower than the surface); 35 read rims and leading edges 2.1 and 1.4 times worse.
NORMAL_TOLERANCE = 25.0
#: Smallest radius of a usable circle, in noise standard deviations: within the trimming band
#: of one under TRIM_NOISE lies a whole disk of noisy points (a noisy plane at 0.5 % noise read
#: half turns at 5 % of its points without this and SIGNIFICANCE). 6 until stop 47 left the
#: trailing edge of the 100,000-point blade unread (radius 4.4 noise, 1.6 spacings): 45.0 ->
#: 19.5 with 4 (k = 100), 11.4 with 3; but at 3 circles through both sides of a wedge (3 to 4
#: noise) passed SMALL_RADIUS_NOISE's test more often, and the 20,000-point blade's sides at
#: 0.5 % per-axis noise rose 17 % (docs/accuracy.md, section 9, step 25).
RADIUS_NOISE = 4.0
#: A circle under this many noise standard deviations in radius is used only where at most
#: BEYOND_MAX points of its list lie outside it, beyond the trimming band, within its arc less
#: the end bands (:func:`_beyond`). Across a rounded end hardly any do: at most 1 for 90 % of
#: the small circles of the 100,000-point blade's trailing edge at 0.1 % noise, of the
#: 20,000-point blade's leading edge at 0.5 % and of the plate's rims at 0.25 and 0.5 %. A
#: circle through both sides of a wedge, in noise of a quarter of its radius, has the wedge
#: running on past it: 2 to 13 at the 10th percentile, 15 to 42 at the median (the
#: 20,000-point blade's sides within 0.4 of its trailing edge at 0.25 and 0.5 % noise).
#: 6 until stop 48: the thinned shares of the 1,000,000-point blade at 0.25 % noise (a dense
#: cloud, since step 26 read by its circles) fit circles of 6 noise and more through both
#: sides of the wedge near its trailing edge, which put its sides at 1.20 (0.93 with 10). Not
#: every circle is tested: on a half round of 30 noise, 3 noise points of 1,500 lie 3.3 to 3.9
#: noise out, in the lists of most of its centres, and 59 % of its circles failed.
SMALL_RADIUS_NOISE = 10.0
BEYOND_MAX = 1
#: ... its curvature, in its standard errors (a leading edge reads 70, a rim 30).
SIGNIFICANCE = 10.0
#: Largest gap (degrees) between inliers along the arc: a blade's sides either side of a
#: trailing edge thinner than the spacing fit a circle with nothing at its tip (side points
#: read k = 42 there otherwise).
GAP_MAX = 45.0
#: Smallest number of inliers of a usable circle.
MIN_INLIERS = 24
#: Angle (degrees) a usable circle's inliers must span around its centre at some size.
SPAN_GATE = 160.0
#: A larger size is kept while its curvature agrees with every smaller one within this many
#: summed standard errors.
AGREEMENT = 2.0
_ROUNDS = 6
_REFINE = 4
#: A Cholesky pivot below this share of the largest diagonal entry counts as singular.
RANK_TOL = 1e-12


def worth_trying(flat: np.ndarray, radius: np.ndarray, noise: float) -> np.ndarray:
    """Whether points whose stage-1 neighborhoods have flatness ``flat`` (m,) within
    ``radius`` (m,) may lie on a rounded edge: at least :data:`EDGE_FLAT` and
    :data:`EDGE_FLAT_NOISE` times what noise ``noise`` (length unit) alone makes of a flat
    neighborhood of that radius, shape (m,), bool."""
    with np.errstate(divide="ignore", invalid="ignore"):
        noisy = EDGE_FLAT_NOISE * 2.0 * noise ** 2 / (radius * radius)
    return flat >= np.maximum(EDGE_FLAT, noisy)


@njit(cache=True)
def _kasa(u, v, w, out):
    """Weighted algebraic circle fit; ``out`` = (cu, cv, R). False where it fails."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for i in range(u.shape[0]):
        if w[i] == 0.0:
            continue
        row = (u[i], v[i], 1.0)
        rhs = -(u[i] * u[i] + v[i] * v[i])
        for r in range(3):
            b[r] += row[r] * rhs
            for c in range(3):
                a[r, c] += row[r] * row[c]
    x, ok = solve_spd(a, b, RANK_TOL)
    if not ok:
        return False
    cu, cv = -0.5 * x[0], -0.5 * x[1]
    r2 = cu * cu + cv * cv - x[2]
    if not r2 > 0.0:
        return False
    out[0], out[1], out[2] = cu, cv, np.sqrt(r2)
    return True


@njit(cache=True)
def _geometric(u, v, w, out):
    """Gauss-Newton on the geometric distance from the circle ``out`` (updated in place).

    Returns the standard error of R (from the residuals and ``(J^T J)^-1``), NaN on failure.
    """
    jtj = np.zeros((3, 3))
    jtr = np.zeros(3)
    ss, m = 0.0, 0
    for it in range(_REFINE + 1):
        jtj[:, :] = 0.0
        jtr[:] = 0.0
        ss, m = 0.0, 0
        for i in range(u.shape[0]):
            if w[i] == 0.0:
                continue
            du, dv = u[i] - out[0], v[i] - out[1]
            rho = np.sqrt(du * du + dv * dv)
            if rho == 0.0:
                continue
            row = (-du / rho, -dv / rho, -1.0)
            res = rho - out[2]
            ss += res * res
            m += 1
            for r in range(3):
                jtr[r] += row[r] * res
                for c in range(3):
                    jtj[r, c] += row[r] * row[c]
        if it == _REFINE:
            break
        step, ok = solve_spd(jtj, -jtr, RANK_TOL)
        if not ok:
            return np.nan
        out[0] += step[0]
        out[1] += step[1]
        out[2] += step[2]
        if not out[2] > 0.0:
            return np.nan
    low, ok = cholesky(jtj, RANK_TOL)
    if m <= 3 or not ok:
        return np.nan
    # (J^T J)^-1 [2, 2] = |L^-1 e_R|^2
    unit = np.zeros(3)
    unit[2] = 1.0
    y = solve_lower(low, unit)
    return np.sqrt(ss / (m - 3) * np.sum(y * y))


@njit(cache=True)
def _span(u, v, w, cu, cv, angles):
    """Angle (radians) the inliers span around (cu, cv), where that arc starts, and the
    largest gap between inliers within it."""
    m = 0
    for i in range(u.shape[0]):
        if w[i] != 0.0:
            angles[m] = np.arctan2(v[i] - cv, u[i] - cu)
            m += 1
    if m < 2:
        return 0.0, 0.0, 2.0 * np.pi
    a = np.sort(angles[:m])
    gap, start, inner = a[0] + 2.0 * np.pi - a[m - 1], a[0], 0.0
    for i in range(1, m):
        step = a[i] - a[i - 1]
        if step > gap:
            gap, start, inner = step, a[i], max(inner, gap)
        else:
            inner = max(inner, step)
    return 2.0 * np.pi - gap, start, inner


@njit(cache=True)
def _axis_frame(field, nbr, count, frame):
    """Axis and cross-section axes from the normals of ``nbr[:count]`` (rows of ``frame``:
    e1, e2, axis); returns the middle eigenvalue's share of the trace (0 if unusable)."""
    s = np.zeros((3, 3))
    used = 0
    for i in range(count):
        n = field[nbr[i]]
        if not (np.isfinite(n[0]) and np.isfinite(n[1]) and np.isfinite(n[2])):
            continue
        used += 1
        for r in range(3):
            for c in range(3):
                s[r, c] += n[r] * n[c]
    if used < AXIS_MIN:
        return 0.0
    vec = np.empty((3, 3))
    i0, i1, i2 = jacobi3(s, vec)
    trace = s[0, 0] + s[1, 1] + s[2, 2]
    if not trace > 0.0:
        return 0.0
    for c in range(3):
        frame[0, c] = vec[c, i2]
        frame[1, c] = vec[c, i1]
        frame[2, c] = vec[c, i0]
    return s[i1, i1] / trace


@njit(cache=True, inline="always")
def _inside_arc(du, dv, start, span):
    """Whether the direction (``du``, ``dv``) from a circle's centre lies within its arc (from
    ``start``, spanning ``span`` radians) less the bands of :data:`NORMAL_TOLERANCE` degrees at
    its ends, where the faces continue it."""
    trim = np.radians(NORMAL_TOLERANCE)
    offset = (np.arctan2(dv, du) - start) % (2.0 * np.pi)
    return trim <= offset <= span - trim


@njit(cache=True)
def _fit_one(points, field, p, nbr, count, noise, frame, circle):
    """One trimmed circle fit over ``nbr[:count]`` around point ``p``.

    Returns (curvature, its standard error, span in radians, arc start, inliers); the
    inliers' weights are left in the last returned array.
    """
    fail = (np.nan, np.nan, 0.0, 0.0, 0, np.zeros(0))
    if _axis_frame(field, nbr, min(count, AXIS_K), frame) < FAN_MIN:
        return fail
    u = np.empty(count)
    v = np.empty(count)
    nu = np.empty(count)
    nv = np.empty(count)
    for i in range(count):
        q = nbr[i]
        d0 = points[q, 0] - points[p, 0]
        d1 = points[q, 1] - points[p, 1]
        d2 = points[q, 2] - points[p, 2]
        u[i] = d0 * frame[0, 0] + d1 * frame[0, 1] + d2 * frame[0, 2]
        v[i] = d0 * frame[1, 0] + d1 * frame[1, 1] + d2 * frame[1, 2]
        n = field[q]
        a = n[0] * frame[0, 0] + n[1] * frame[0, 1] + n[2] * frame[0, 2]
        b = n[0] * frame[1, 0] + n[1] * frame[1, 1] + n[2] * frame[1, 2]
        norm = np.sqrt(a * a + b * b)
        if np.isfinite(norm) and norm > 0.0:
            nu[i], nv[i] = a / norm, b / norm
        else:
            nu[i], nv[i] = 0.0, 0.0  # no normal: never along the radius
    w = np.ones(count)
    cos_tol = np.cos(np.radians(NORMAL_TOLERANCE))
    band = TRIM_NOISE * noise
    for it in range(_ROUNDS):
        if not _kasa(u, v, w, circle):
            return fail
        m = 0
        for i in range(count):
            du, dv = u[i] - circle[0], v[i] - circle[1]
            rho = np.sqrt(du * du + dv * dv)
            keep = abs(rho - circle[2]) <= band
            if keep and it >= 2:
                keep = rho > 0.0 and abs(du * nu[i] + dv * nv[i]) >= cos_tol * rho
            w[i] = 1.0 if keep else 0.0
            if keep:
                m += 1
        if m < MIN_INLIERS:
            return fail
    std_r = _geometric(u, v, w, circle)
    if not np.isfinite(std_r):
        return fail
    inliers = 0
    for i in range(count):
        if w[i] != 0.0:
            du, dv = u[i] - circle[0], v[i] - circle[1]
            if abs(np.sqrt(du * du + dv * dv) - circle[2]) <= band:
                inliers += 1
            else:
                w[i] = 0.0
    if inliers < MIN_INLIERS:
        return fail
    span, start, inner_gap = _span(u, v, w, circle[0], circle[1], np.empty(count))
    if inner_gap > np.radians(GAP_MAX):
        return fail  # two separate stretches (a wedge's sides beside an edge it cannot see)
    # The faces continue the arc at both its ends, within the normal tolerance of it: points
    # there pull the circle wide. The fit is made again without both ends' bands.
    trim = np.radians(NORMAL_TOLERANCE)
    if span > 2.0 * trim:
        inner = w.copy()
        kept = 0
        for i in range(count):
            if inner[i] != 0.0:
                if _inside_arc(u[i] - circle[0], v[i] - circle[1], start, span):
                    kept += 1
                else:
                    inner[i] = 0.0
        if kept >= MIN_INLIERS:
            refit = circle.copy()
            std_inner = _geometric(u, v, inner, refit)
            if np.isfinite(std_inner):
                circle[:] = refit
                std_r = std_inner
    r = circle[2]
    if r < RADIUS_NOISE * noise or not std_r / (r * r) * SIGNIFICANCE < 1.0 / r:
        return fail
    if r < SMALL_RADIUS_NOISE * noise and (_beyond(u, v, count, circle, start, span, band)
                                           > BEYOND_MAX):
        return fail  # a wedge's sides, which run on past the arc
    return 1.0 / r, std_r / (r * r), span, start, inliers, w


@njit(cache=True)
def _beyond(u, v, count, circle, start, span, band):
    """How many of the first ``count`` points (cross-section coordinates ``u``, ``v``) lie
    farther than ``band`` outside ``circle`` (centre and radius) within its arc (from
    ``start``, spanning ``span`` radians) less the end bands."""
    out = 0
    for i in range(count):
        du, dv = u[i] - circle[0], v[i] - circle[1]
        if np.sqrt(du * du + dv * dv) > circle[2] + band and _inside_arc(du, dv, start, span):
            out += 1
    return out


@njit(cache=True)
def _axial(points, field, p, nbr, w, frame, circle):
    """Curvature along the axis and its standard error: the slope of the inliers' normals'
    axial component (each turned along its radius) against their axial offset."""
    sx, sy, sxx, sxy, syy, m = 0.0, 0.0, 0.0, 0.0, 0.0, 0
    for i in range(w.shape[0]):
        if w[i] == 0.0:
            continue
        q = nbr[i]
        d = points[q] - points[p]
        u = d[0] * frame[0, 0] + d[1] * frame[0, 1] + d[2] * frame[0, 2] - circle[0]
        v = d[0] * frame[1, 0] + d[1] * frame[1, 1] + d[2] * frame[1, 2] - circle[1]
        t = d[0] * frame[2, 0] + d[1] * frame[2, 1] + d[2] * frame[2, 2]
        n = field[q]
        radial = (n[0] * (u * frame[0, 0] + v * frame[1, 0])
                  + n[1] * (u * frame[0, 1] + v * frame[1, 1])
                  + n[2] * (u * frame[0, 2] + v * frame[1, 2]))
        y = n[0] * frame[2, 0] + n[1] * frame[2, 1] + n[2] * frame[2, 2]
        if radial < 0.0:
            y = -y
        sx += t
        sy += y
        sxx += t * t
        sxy += t * y
        syy += y * y
        m += 1
    if m < 3:
        return 0.0, np.inf
    vx = sxx - sx * sx / m
    if not vx > 0.0:
        return 0.0, np.inf
    slope = (sxy - sx * sy / m) / vx
    ss = max(syy - sy * sy / m - slope * slope * vx, 0.0)
    return slope, np.sqrt(ss / max(m - 2, 1) / vx)


@njit(parallel=True, cache=True)
def edge_circle_fits(points, field, centres, indptr, indices, noise, ladder,
                     frame, circle, curv, std, arc, count, ok):
    """Circle fits across rounded edges around the points ``centres`` (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    field : ndarray, shape (n, 3)
        Unit normals of every point (any sign; NaN where none).
    centres : ndarray, shape (a,), int64
    indptr, indices : ndarray, int
        CSR neighbor lists of the centres, nearest first (the centre itself first).
    noise : float
        The cloud's noise (standard deviation across the surface, length unit).
    ladder : ndarray, shape (s,), int64
        List sizes tried, increasing.
    frame : ndarray, shape (a, 3, 3)
        Output: rows e1, e2 (the cross-section) and the axis of the kept fit.
    circle : ndarray, shape (a, 3)
        Output: the circle's centre (in e1, e2, from the point) and radius.
    curv, std : ndarray, shape (a, 2)
        Output: curvature across (``1 / R``, for normals pointing away from the centre) and
        along the axis, and their standard errors.
    arc : ndarray, shape (a, 2)
        Output: start angle of the inliers' arc around the centre and the angle it spans
        (radians, from e1 towards e2).
    count : ndarray, shape (a,), int64
        Output: inliers of the kept fit.
    ok : ndarray, shape (a,), bool
        Output: whether the point reads a rounded edge.
    """
    for j in prange(centres.shape[0]):
        ok[j] = False
        p = centres[j]
        nbr = indices[indptr[j]:indptr[j + 1]]
        s = ladder.shape[0]
        ks = np.full(s, np.nan)
        sks = np.full(s, np.nan)
        widest = 0.0
        best = -1
        kept = np.zeros(0)  # the inliers of the size kept
        f = np.empty((3, 3))
        c = np.empty(3)
        for t in range(s):
            size = ladder[t]
            if size > nbr.shape[0]:
                break
            k, sk, span, start, m, w = _fit_one(points, field, p, nbr, size, noise, f, c)
            if m == 0:
                continue
            ks[t], sks[t] = k, sk
            widest = max(widest, span)
            agree = True
            for r in range(t):
                if np.isfinite(ks[r]) and abs(k - ks[r]) > AGREEMENT * (sk + sks[r]):
                    agree = False
            if not agree:
                break
            best, kept = t, w
            frame[j] = f
            circle[j] = c
            curv[j, 0], std[j, 0] = k, sk
            arc[j, 0], arc[j, 1] = start, span
            count[j] = m
        ok[j] = best >= 0 and widest >= np.radians(SPAN_GATE)
        if ok[j]:
            curv[j, 1], std[j, 1] = _axial(points, field, p, nbr, kept, frame[j], circle[j])


@njit(parallel=True, cache=True)
def read_edge_circles(noise, offsets, frame, circle, curv, std, arc, k1, k2, normals, dir1, dir2,
                      k1_std, k2_std, read):
    """Curvatures, normals and directions of points from circles, where a point lies on its
    circle and inside its arc without the bands at the arc's ends, where the faces begin
    (module docstring); ``read[i]`` says whether it did (the outputs are left alone elsewhere).

    Parameters
    ----------
    noise : float
    offsets : ndarray, shape (m, 3)
        Each reading point's position less that of the point its circle was fitted around
        (zeros where a point reads its own circle).
    frame, circle, curv, std, arc : ndarray
        As :func:`edge_circle_fits` returned them, shape (m, ...).
    k1, k2, k1_std, k2_std : ndarray, shape (m,)
        Output: signed for the normal below (k1 >= k2).
    normals, dir1, dir2 : ndarray, shape (m, 3)
        Output: the normal points away from the circle's centre.
    read : ndarray, shape (m,), bool
    """
    band = TRIM_NOISE * noise
    for i in prange(frame.shape[0]):
        read[i] = False
        e1, e2, ax = frame[i, 0], frame[i, 1], frame[i, 2]
        d = offsets[i]
        # the point, from the centre
        u = d[0] * e1[0] + d[1] * e1[1] + d[2] * e1[2] - circle[i, 0]
        v = d[0] * e2[0] + d[1] * e2[1] + d[2] * e2[2] - circle[i, 1]
        rho = np.sqrt(u * u + v * v)
        if not (rho > 0.0 and abs(rho - circle[i, 2]) <= band):
            continue
        if not _inside_arc(u, v, arc[i, 0], arc[i, 1]):
            continue
        nr = np.empty(3)
        for c in range(3):
            nr[c] = (u * e1[c] + v * e2[c]) / rho
        across = np.empty(3)  # the tangent across the edge: axis x normal
        across[0] = ax[1] * nr[2] - ax[2] * nr[1]
        across[1] = ax[2] * nr[0] - ax[0] * nr[2]
        across[2] = ax[0] * nr[1] - ax[1] * nr[0]
        normals[i] = nr
        if curv[i, 0] >= curv[i, 1]:
            k1[i], k2[i], k1_std[i], k2_std[i] = curv[i, 0], curv[i, 1], std[i, 0], std[i, 1]
            dir1[i], dir2[i] = across, ax
        else:
            k1[i], k2[i], k1_std[i], k2_std[i] = curv[i, 1], curv[i, 0], std[i, 1], std[i, 0]
            dir1[i], dir2[i] = ax, across
        read[i] = True


@njit(parallel=True, cache=True)
def wraps(field, centres, indptr, indices, share):
    """Whether the normals of each centre's neighbors (CSR lists) fan out around an axis by
    more than ``share`` (the middle eigenvalue's share of ``sum n n^T``), shape (a,), bool:
    the points worth a circle fit."""
    out = np.zeros(centres.shape[0], np.bool_)
    for j in prange(centres.shape[0]):
        f = np.empty((3, 3))
        out[j] = _axis_frame(field, indices[indptr[j]:indptr[j + 1]],
                             indptr[j + 1] - indptr[j], f) >= share
    return out
