"""Sphere fits: one curvature where a point's patch bends alike in every direction, and
cylinder fits where it bends in one direction alone.

A flat face (k1 = k2 = 0) and a sphere (k1 = k2 = 1/R) are umbilic. Over a point's tangent
frame (u, v along the plane, z along its normal) both satisfy ``z = c0 + c1 u + c2 v +
c3 (u^2 + v^2 + z^2) / 2`` exactly, at any size: the algebraic sphere ``c3 |x|^2 / 2 +
(c1, c2, -1) . x + c0 = 0`` (a plane where ``c3 = 0``; the fit of algebraic spheres of
Guennebaud & Gross, SIGGRAPH 2007, reduced to a linear height regression by fixing the
normal's coefficient), of curvature ``-c3 / sqrt(1 + c1^2 + c2^2 - 2 c0 c3)``. One curvature
term where a quadric has three: fitted over the same points it is known about twice as well,
and since a patch of m points spans ``h ~ sqrt(m)``, a curvature's standard error falls as
``m^-1.5``, so a sphere fit over half the points a quadric kept reads the curvature about as
well. (A height quadric ``(u^2 + v^2) / 2`` instead of the sphere's term reads a sphere too
high by about ``h^2 / 4 R^2``: 0.4 at the filleted box's corners over 48 points.)

At each point, over its nearest neighbors in order, for each size of :data:`SIZES`:

1. the points join the fit unless, once a size has been fitted, they lie more than
   :data:`TRIM` noise off its sphere (the other face of a thin wall, an outlier);
2. the sphere and the sphere with two more terms, ``(u^2 - v^2) / 2`` and ``uv`` (unequal
   principal curvatures), are fitted by least squares from one set of moments; the size is
   usable when its inliers are at least :data:`MIN_SHARE` of the size, the sphere's residual
   is within :data:`RESIDUAL` noise (no shape it does not follow, no second sheet), the F
   statistic of the two terms is under its :data:`F_LEVEL` critical value (no difference
   between the principal curvatures shows) and its curvature agrees with every smaller
   size's within :data:`LEPSKI` of that one's standard error (Lepski's rule, as the
   default's scale selection); the first size that is not ends the ladder;
3. a usable size replaces the point's estimate (``k1 = k2``) where the points reject the
   estimate in its favour: the estimate's curvatures (its k1 and k2 along its principal
   directions, the constant and slopes fitted afresh) fit them worse than the sphere by more
   than :data:`REJECT` times the sphere's residual variance; where the estimate reads as
   well (a wide fit on a smooth surface) the points cannot tell them apart and it stays,
   whatever its standard errors say. An estimate kept over at most :data:`SMALL_KEPT`
   neighbors needs no rejection: it was fitted to about the sphere's own points, which
   never reject their own least-squares fit, and there the F test and the standard errors
   below decide (the sphere reads one curvature term from the points where the quadric
   read three). The size must also span :data:`SIZE_SHARE` of the estimate's neighbors
   (:data:`FAR_SHARE` where the points reject the estimate by more than :data:`REJECT_FAR`
   times the sphere's residual variance) and have a standard error below the larger of the
   estimate's two (a flat reading, within :data:`FLAT` of its error of zero) or below both
   (a curved one), unless the points reject it by more than :data:`REJECT_FAR` and it was
   kept over at least :data:`WIDE_KEPT` times the size's neighbors. Of those sizes, the one
   with the smallest standard error. (Its agreement with the estimate within their
   standard errors is not asked: where the points reject the estimate they have found it
   off, by more than the standard errors of a biased fit say.)
4. where no sphere replaces the estimate and it reads its less curved direction flat
   (within :data:`FLAT` of its standard error of 0), a cylinder across its more curved
   principal direction (u along it, v along the axis) may: ``z = c0 + c1 u + c2 v +
   c3 (u^2 + z^2) / 2`` is exact on a circular cylinder at any size, as the sphere's model
   is on a sphere (a fillet, a cylinder's side), where a height quadric over a wide patch
   reads the circle's quartic term ``u^4 / 8 R^3`` as extra curvature. (Without the
   estimate's flat axis asked, cylinders replaced estimates on the smooth grid's spheres
   and ellipsoids too, up to +3 % in a cell.) Its ladder is the sphere's with the F
   test of :data:`CYLINDER_EXTRAS` terms: ``v^2 / 2`` and ``uv`` (the surface bends along
   the axis, or the axis is turned) and ``u^3``, ``u^4`` (the profile is no circle: the
   patch has reached the flat face beside a fillet, or the surface is no cylinder). It
   replaces the estimate only where the points reject that by more than :data:`REJECT_FAR`
   (no :data:`SMALL_KEPT` waiver, :data:`FAR_SHARE` of its neighbors) with a curved reading
   whose standard error is below that of the estimate's curved direction (waived as for
   the sphere); the estimate's directions stay, with ``k`` across the axis and 0 along it.

The F test is the classic test of nested linear models (a restriction of q = 2
coefficients for the sphere, :data:`CYLINDER_EXTRAS` for the cylinder). Curvature sign:
positive where the surface bends away from the normal (DESIGN.md section 3).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from scipy.stats import f as f_distribution

from .linalg import solve_spd
from .quadric import tangent_basis_xyz

__all__ = ["CYLINDER_EXTRAS", "F_LEVEL", "FAR_SHARE", "FLAT", "LEPSKI", "MIN_REACH",
           "MIN_SHARE", "REJECT", "REJECT_FAR", "RESIDUAL", "RESIDUAL_FLOOR", "SIZES",
           "SIZE_SHARE", "SMALL_KEPT", "TRIM", "WIDE_KEPT", "f_critical", "reads_axis_flat",
           "umbilic_fits"]

# Relative pivot under which a fit's normal matrix counts as singular.
RANK_TOL = 1e-12
#: List sizes of the ladder (nearest neighbors, the point itself included). 24 is left out:
#: its fits are too noisy to beat a kept estimate over the 48 neighbors and more it may
#: replace. 384 reads the faces and corners of denser clouds, where the scale selection keeps
#: 768-point fits beside a fillet (their bias hides within the noise of its fixed-count
#: positional rungs, whose patches shrink with density): a 96,000-point filleted box at 0.05 %
#: noise read its faces 0.096 -> 0.087 and its corners 0.281 -> 0.227 with it (mean of the
#: larger error, regions of fixed width; docs/accuracy.md section 9, step 28).
SIZES = (48, 96, 192, 384)
#: Past the first size a point joins the fit only within this many noise of the previous
#: size's sphere.
TRIM = 8.0
#: A usable size's sphere residual (RMS, per degree of freedom) is at most this many noise.
#: The default's noise is its plan's cubic-fit residual, about 1.27 times the true noise.
RESIDUAL = 1.2
#: The residual variance divides the likelihood ratio: at least this share of the noise.
RESIDUAL_FLOOR = 1e-3
#: Level of the F test of k1 = k2.
F_LEVEL = 0.05
#: A size's curvature agrees with every smaller one's within this many of its standard error.
LEPSKI = 2.0
#: A usable size may replace the kept estimate only where the estimate's curvatures fit its
#: points worse than the sphere by more than this many times the sphere's residual variance
#: (a likelihood-ratio test, 2 standard errors of the sphere's curvature): where the
#: estimate reads as well (a wide fit on a smooth surface, whose standard errors may say
#: otherwise) it stays.
REJECT = 4.0
#: An estimate kept over at most this many neighbors (the ladder's smaller rungs) may be
#: replaced without the likelihood-ratio test (:data:`REJECT`): it is the least-squares fit
#: of about the sphere's own points, so they fit it about as well as the sphere however
#: much its three curvature terms err (the filleted box at 0.1 % noise, seed 1: the
#: estimates of its 101 corner points, over 48 and 96 neighbors, erred 0.51 on average and
#: 62 were not rejected, median statistic 0.3; the 48-point spheres, usable at 82 of them,
#: erred 0.21). 192 is left out: there the default also keeps normal quadrics, which read the
#: normals of more points than their own, and a 10,000-point sphere at 0.3 % noise read
#: 4 to 19 % worse when its 192-point estimates gave way to spheres (docs/accuracy.md,
#: section 9, step 29).
SMALL_KEPT = 96
#: A sphere reads flat where its curvature is within this many of its standard errors of 0.
#: Until stop 51 a sphere also had to agree with the estimate's k1 and k2 within this many
#: of their combined standard errors: where the points reject a biased estimate, which is
#: what this pass is for, its standard errors do not show that bias (docs/accuracy.md,
#: section 10), and the test turned the sphere down (the filleted box's corners at 48,000
#: points: 68 of the 182 points whose 192-point spheres were usable, those spheres erring
#: 0.063 against the estimates' 0.287; docs/accuracy.md, section 9, step 29).
FLAT = 2.0
#: A size replaces an estimate only where it spans at least this share of its neighbors.
#: 0.5 until stop 51: then a corner's estimate kept over 768 points of a 96,000-point box
#: could only give way to a 384-point sphere, usable at a third of them, while the 192-point
#: ones, usable at 333 of 400, erred 0.070 against the estimates' 0.307 (corners over
#: regions of fixed width 0.221 -> 0.168, faces 0.085 -> 0.083; the smooth grid's sphere and
#: Bezier cells +0.5 to +2.3 % in 5 of 72; docs/accuracy.md, section 9, step 29).
SIZE_SHARE = 0.25
#: ... or at least this share where the points reject the estimate by more than
#: :data:`REJECT_FAR` times the sphere's residual variance (4 of the sphere's standard
#: errors): a 192-point sphere may then replace a 1152-point fit. Added at stop 52: on a
#: 96,000-point filleted box at 0.05 % noise the faces beside the fillets keep 1152-point
#: fits that reach onto the fillet; of 300 sampled, 137 had no usable 384-point sphere (it
#: reaches the fillet too), while 78 of them had a usable 192-point one, erring 0.073
#: against the kept fits' 0.366 (faces over regions of fixed width 0.067 -> 0.060; with
#: no rejection asked beyond REJECT, 0.056, but the smooth grid's Bezier patch at 0.1 %
#: noise, which keeps 1152-point fits too, read 1.3 to 2.0 % worse; docs/accuracy.md
#: section 9, step 30).
FAR_SHARE = 0.16
REJECT_FAR = 16.0
#: Where the points reject it that strongly (:data:`REJECT_FAR`), an estimate kept over at
#: least this many times the sphere's neighbors need not have the larger standard error
#: either: over more points it has the smaller one by design, and the rejection shows the
#: bias that one leaves out. (The same 96,000-point box: of 300 sampled face points that
#: kept 768-point fits, 45 had a sphere the points preferred that the standard errors
#: turned down, erring 0.048 against the kept fits' 0.101; faces 0.060 -> 0.056. Over
#: smaller kept fits such spheres erred more than the estimates: 1.20 against 0.29 over
#: 192 points, 0.40 against 0.12 over 384.)
WIDE_KEPT = 2
#: The cylinder's extra terms in its F test: ``v^2 / 2``, ``uv``, ``u^3``, ``u^4``. Without
#: the last two (added at stop 53) a cylinder's patch reached the faces beside a fillet of
#: 6.5 spacings and read it low: the filleted box at 0.05 % noise (bench parts, seeds 1-4)
#: read its fillets 3 to 7 % worse with cylinders and the faces 0.5 to 1.9 %; with them
#: 3 to 4 % better, faces within 0.4 % (docs/accuracy.md section 9, step 31).
CYLINDER_EXTRAS = 4
#: Inliers of a usable size, at least this share of its size.
MIN_SHARE = 0.5
#: A size is used only where its list reaches this many noise from the point: the noise of
#: the positions across the patch biases a least-squares curvature by about (noise / h)^2,
#: and the points then reject the truth in favour of the biased fit (a sphere at 0.5 %
#: noise, 48 points within 6.5 noise: curvature 1 read -1.2 to 3.6, rejected 9 to 24 times
#: its residual variance).
MIN_REACH = 12.0


def f_critical(sizes=SIZES, level: float = F_LEVEL, extras: int = 2) -> np.ndarray:
    """Critical values of the F test of ``extras`` terms (``extras`` and ``size - 4 -
    extras`` degrees of freedom), shape (s,): the sphere's 2 by default, the cylinder's
    :data:`CYLINDER_EXTRAS`."""
    return np.array([f_distribution.isf(level, extras, max(s - 4 - extras, 1))
                     for s in sizes])


def reads_axis_flat(k1, k2, std1, std2) -> np.ndarray:
    """Whether estimates read their less curved direction flat, within :data:`FLAT` of its
    standard error of 0 (where a cylinder may replace them; step 4 of the module
    docstring), shape (m,), bool; ``k1``, ``k2``, ``std1``, ``std2``: shape (m,)."""
    k1, k2 = np.asarray(k1, float), np.asarray(k2, float)
    along_first = np.abs(k1) >= np.abs(k2)
    other = np.where(along_first, k2, k1)
    other_std = np.where(along_first, std2, std1)
    return np.abs(other) <= FLAT * other_std


@njit(cache=True)
def _inverse_diag(a, j):
    """Entry (j, j) of ``a``'s inverse (``a`` symmetric positive definite), NaN where singular."""
    e = np.zeros(a.shape[0])
    e[j] = 1.0
    x, ok = solve_spd(a, e, RANK_TOL)
    return x[j] if ok else np.nan


@njit(cache=True)
def _current_terms(dir1, dir2, k1, k2, t10, t11, t12, t20, t21, t22):
    """The estimate (k1, k2 along dir1, dir2) as the coefficients of ``(u^2 + v^2) / 2``,
    ``(u^2 - v^2) / 2`` and ``uv`` of the height over the frame (t1, t2, normal), (3,)."""
    a1 = dir1[0] * t10 + dir1[1] * t11 + dir1[2] * t12
    b1 = dir1[0] * t20 + dir1[1] * t21 + dir1[2] * t22
    a2 = dir2[0] * t10 + dir2[1] * t11 + dir2[2] * t12
    b2 = dir2[0] * t20 + dir2[1] * t21 + dir2[2] * t22
    n1 = np.hypot(a1, b1)
    n2 = np.hypot(a2, b2)
    out = np.zeros(3)
    if not (n1 > 0.0 and n2 > 0.0):
        return out
    a1, b1, a2, b2 = a1 / n1, b1 / n1, a2 / n2, b2 / n2
    s11 = k1 * a1 * a1 + k2 * a2 * a2
    s22 = k1 * b1 * b1 + k2 * b2 * b2
    s12 = k1 * a1 * b1 + k2 * a2 * b2
    # height -1/2 [u v] S [u v]^T (bending away from the normal where positive)
    out[0] = -0.5 * (s11 + s22)
    out[1] = -0.5 * (s11 - s22)
    out[2] = -s12
    return out


@njit(cache=True)
def _rejection(mom, rhs, zz, g, rss_sphere, s2):
    """How much worse than the sphere the estimate's terms ``g`` (3,) fit the points, with
    the constant and the slopes fitted afresh: ``(RSS - rss_sphere) / s2``."""
    yy = zz
    for a in range(3):
        yy -= 2.0 * g[a] * rhs[3 + a]
        for b in range(3):
            yy += g[a] * g[b] * mom[3 + a, 3 + b]
    b3 = np.empty(3)
    for i in range(3):
        b3[i] = rhs[i]
        for a in range(3):
            b3[i] -= mom[i, 3 + a] * g[a]
    x, ok = solve_spd(np.ascontiguousarray(mom[:3, :3]), b3, RANK_TOL)
    if not ok:
        return 0.0
    rss = yy - (x[0] * b3[0] + x[1] * b3[1] + x[2] * b3[2])
    return (rss - rss_sphere) / s2


@njit(cache=True)
def _ladder(points, normal, frame, cylinder, p, nbr, noise, sizes, fcrit, g, out_k, out_se,
            out_count, out_reject):
    """The sphere ladder at point ``p`` over its neighbors ``nbr`` (nearest first), or the
    cylinder ladder where ``cylinder`` (u across the axis); fills ``out_k``, ``out_se``,
    ``out_count`` and ``out_reject`` (s,) up to the first unusable size (left as they were
    after: NaN, 0). ``frame`` (6,): the tangent directions u and v (x, y, z each); ``fcrit``
    (s,): :func:`f_critical` with the model's extra terms; ``g`` (3,): the estimate's terms
    (:func:`_current_terms`, or its curvatures across and along the axis, negated, and 0),
    whose :func:`_rejection` at each usable size goes to ``out_reject``."""
    t10, t11, t12, t20, t21, t22 = frame
    w = 0.0 if cylinder else 1.0  # the model term's weight of v^2
    nc = 4 + (CYLINDER_EXTRAS if cylinder else 2)
    m = nbr.shape[0]
    # Lengths in units of the farthest neighbor's distance: the moments stay of order one.
    far = 0.0
    for c in range(m):
        q = nbr[c]
        d0 = points[q, 0] - points[p, 0]
        d1 = points[q, 1] - points[p, 1]
        d2 = points[q, 2] - points[p, 2]
        far = max(far, d0 * d0 + d1 * d1 + d2 * d2)
    unit = np.sqrt(far)
    if not unit > 0.0:
        return
    noise_u = noise / unit
    mom = np.zeros((nc, nc))
    rhs = np.zeros(nc)
    zz = 0.0
    count = 0
    row = np.empty(nc)
    coef = np.zeros(4)
    fitted = False  # whether coef holds a smaller size's sphere (the trimming's reference)
    pos = 0
    for j in range(sizes.shape[0]):
        end = min(sizes[j], m)
        while pos < end:
            q = nbr[pos]
            pos += 1
            d0 = (points[q, 0] - points[p, 0]) / unit
            d1 = (points[q, 1] - points[p, 1]) / unit
            d2 = (points[q, 2] - points[p, 2]) / unit
            u = d0 * t10 + d1 * t11 + d2 * t12
            v = d0 * t20 + d1 * t21 + d2 * t22
            z = d0 * normal[0] + d1 * normal[1] + d2 * normal[2]
            if fitted:
                pred = (coef[0] + coef[1] * u + coef[2] * v
                        + 0.5 * coef[3] * (u * u + w * v * v + z * z))
                if abs(z - pred) > TRIM * noise_u:
                    continue
            row[0], row[1], row[2] = 1.0, u, v
            row[3] = 0.5 * (u * u + w * v * v + z * z)
            if cylinder:
                row[4], row[5] = 0.5 * v * v, u * v
                for a in range(6, nc):  # u^3, u^4
                    row[a] = u ** (a - 3)
            else:
                row[4], row[5] = 0.5 * (u * u - v * v), u * v
            for a in range(nc):
                rhs[a] += row[a] * z
                for b in range(a, nc):  # the upper triangle; mirrored where solved
                    mom[a, b] += row[a] * row[b]
            zz += z * z
            count += 1
        if count < max(MIN_SHARE * sizes[j], 12.0):
            return
        q = nbr[end - 1]
        reach = np.sqrt((points[q, 0] - points[p, 0]) ** 2 + (points[q, 1] - points[p, 1]) ** 2
                        + (points[q, 2] - points[p, 2]) ** 2) / unit
        if reach < MIN_REACH * noise_u:
            continue  # noise across the patch too: a larger size may do
        for a in range(nc):
            for b in range(a):
                mom[a, b] = mom[b, a]
        cq, ok_q = solve_spd(mom, rhs, RANK_TOL)
        # The sphere's design is the first four columns of the anisotropic one.
        mu = np.ascontiguousarray(mom[:4, :4])
        bu = rhs[:4].copy()
        cu, ok_u = solve_spd(mu, bu, RANK_TOL)
        if not (ok_q and ok_u):
            return
        rss_q = zz
        for a in range(nc):
            rss_q -= cq[a] * rhs[a]
        rss_q = max(rss_q, 0.0)
        rss_u = max(zz - (cu[0] * bu[0] + cu[1] * bu[1] + cu[2] * bu[2] + cu[3] * bu[3]),
                    rss_q)
        # (floored: a patch without noise, in a cloud with some, still divides by it)
        s2 = max(rss_u / (count - 4), (RESIDUAL_FLOOR * noise_u) ** 2)
        if np.sqrt(s2) > RESIDUAL * noise_u:
            return
        if rss_q > 0.0 and (rss_u - rss_q) / (nc - 4) / (rss_q / (count - nc)) > fcrit[j]:
            return
        # The sphere (plane where c3 = 0) c3 |x|^2 / 2 + (c1, c2, -1) . x + c0 = 0: its
        # curvature at any size, bending away from the normal where positive (the cylinder's
        # across its axis, the same with v left out).
        root = np.sqrt(max(1.0 + cu[1] * cu[1] + w * cu[2] * cu[2] - 2.0 * cu[3] * cu[0],
                           1e-12))
        k = -cu[3] / root / unit
        se = np.sqrt(s2 * _inverse_diag(mu, 3)) / root / unit
        if not np.isfinite(se):
            return
        for i in range(j):
            if abs(k - out_k[i]) > LEPSKI * out_se[i]:
                return
        out_k[j], out_se[j], out_count[j] = k, se, count
        out_reject[j] = _rejection(mom, rhs, zz, g * unit, rss_u, s2)
        for a in range(4):
            coef[a] = cu[a]
        fitted = True


@njit(cache=True)
def _pick(ks, ses, counts, reject, sizes, used, low, high, cylinder):
    """The size of a ladder's readings (``ks``, ``ses``, ``counts``, ``reject``, (s,)) that
    replaces an estimate kept over ``used`` neighbors, -1 where none (module docstring,
    step 3 for the sphere, step 4 for the cylinder). ``low``, ``high``: the smaller and the
    larger of the estimate's standard errors (for a cylinder, its curved direction's
    twice)."""
    best, pick = np.inf, -1
    for j in range(ks.shape[0]):
        se = ses[j]
        strong = reject[j] > REJECT_FAR
        allowed = strong if cylinder else (reject[j] > REJECT or used <= SMALL_KEPT)
        share = FAR_SHARE if strong else SIZE_SHARE
        if not (np.isfinite(se) and allowed and counts[j] >= share * used):
            continue
        # a flat reading must beat the larger of the estimate's errors, a curved one both;
        # a flat cylinder is the sphere's plane
        flat = abs(ks[j]) <= FLAT * se
        if flat and cylinder:
            continue
        limit = high if flat else low
        if strong and used >= WIDE_KEPT * sizes[j]:
            limit = np.inf
        if se < limit and se < best:
            best, pick = se, j
    return pick


@njit(cache=True)
def _across(normal, d):
    """Whether ``d`` (3,) has a direction in the tangent plane of ``normal``, and the frame
    (u, v; x, y, z each) of the cylinder across it: u that direction, v = normal x u."""
    dn = d[0] * normal[0] + d[1] * normal[1] + d[2] * normal[2]
    a0, a1, a2 = d[0] - normal[0] * dn, d[1] - normal[1] * dn, d[2] - normal[2] * dn
    na = max(np.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300)
    a0, a1, a2 = a0 / na, a1 / na, a2 / na
    return na > 1e-12, (a0, a1, a2, normal[1] * a2 - normal[2] * a1,
                        normal[2] * a0 - normal[0] * a2, normal[0] * a1 - normal[1] * a0)


@njit(parallel=True, cache=True)
def umbilic_fits(points, normals, dir1, dir2, query, nbr, noise, sizes, fcrit, fcrit_cylinder,
                 k1, k2, std1, std2, used, cylinders, out_k, out_se, out_count, out_kind):
    """Sphere fits, and cylinder fits where no sphere does, where the points reject the kept
    estimate in their favour (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    normals, dir1, dir2 : ndarray, shape (n, 3)
        The kept estimate's unit normals and principal directions; the query points' normals
        give their frames.
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, K), int
        Each query point's nearest neighbors, nearest first (outliers replaced by -1 are
        skipped), ``K >= sizes[-1]`` or the cloud's size.
    noise : float
        The cloud's noise (length unit).
    sizes : ndarray, shape (s,), int64
    fcrit, fcrit_cylinder : ndarray, shape (s,)
        :func:`f_critical` of ``sizes``, with 2 and with :data:`CYLINDER_EXTRAS` extra terms.
    k1, k2, std1, std2 : ndarray, shape (m,)
        The kept estimate at the query points and its standard errors.
    used : ndarray, shape (m,), int
        Its neighbor count.
    cylinders : ndarray, shape (m,), bool
        Where a cylinder may be tried.
    out_k, out_se : ndarray, shape (m,)
        The sphere's curvature (the cylinder's across its axis) and its standard error where
        it replaces the estimate, NaN elsewhere.
    out_count : ndarray, shape (m,), int64
        Its size (0 elsewhere): its neighbors, of which the trimming may have left some out.
    out_kind : ndarray, shape (m,), int64
        0: a sphere (or nothing); 1 or 2: a cylinder across the estimate's ``dir1`` or
        ``dir2`` (its more curved direction), whose axis is the other.
    """
    s = sizes.shape[0]
    for i in prange(query.shape[0]):
        out_k[i] = np.nan
        out_se[i] = np.nan
        out_count[i] = 0
        out_kind[i] = 0
        p = query[i]
        row = nbr[i]
        keep = np.empty(row.shape[0], np.int64)
        m = 0
        for c in range(row.shape[0]):
            if row[c] >= 0:
                keep[m] = row[c]
                m += 1
        n = normals[p]
        t10, t11, t12, t20, t21, t22 = tangent_basis_xyz(n[0], n[1], n[2])
        g = _current_terms(dir1[p], dir2[p], k1[i], k2[i], t10, t11, t12, t20, t21, t22)
        ks = np.full(s, np.nan)
        ses = np.full(s, np.nan)
        counts = np.zeros(s, np.int64)
        reject = np.full(s, np.nan)
        _ladder(points, n, (t10, t11, t12, t20, t21, t22), False, p, keep[:m], noise, sizes,
                fcrit, g, ks, ses, counts, reject)
        j = _pick(ks, ses, counts, reject, sizes, used[i], min(std1[i], std2[i]),
                  max(std1[i], std2[i]), False)
        if j >= 0:
            out_k[i], out_se[i], out_count[i] = ks[j], ses[j], sizes[j]
            continue
        if not cylinders[i]:
            continue
        along = 1 if abs(k1[i]) >= abs(k2[i]) else 2
        other, other_std = (k2[i], std2[i]) if along == 1 else (k1[i], std1[i])
        if not abs(other) <= FLAT * other_std:
            continue  # the estimate reads the axis curved
        ok, frame = _across(n, dir1[p] if along == 1 else dir2[p])
        if not ok:
            continue
        # the estimate across and along the axis, as the cylinder's terms
        g[0], g[1], g[2] = (-k1[i], -k2[i], 0.0) if along == 1 else (-k2[i], -k1[i], 0.0)
        ks[:] = np.nan
        ses[:] = np.nan
        counts[:] = 0
        reject[:] = np.nan
        _ladder(points, n, frame, True, p, keep[:m], noise, sizes, fcrit_cylinder, g, ks, ses,
                counts, reject)
        limit = std1[i] if along == 1 else std2[i]
        j = _pick(ks, ses, counts, reject, sizes, used[i], limit, limit, True)
        if j >= 0:
            out_k[i], out_se[i], out_count[i] = ks[j], ses[j], sizes[j]
            out_kind[i] = along
