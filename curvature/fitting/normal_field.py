"""Normal-field regression: curvature from how estimated normals vary across a neighborhood.

The shape operator is the derivative of the unit normal along the surface. Stage 1 estimates a
normal per point by PCA over a few dozen neighbors; stage 2 fits the tangent components of the
neighbors' normals as a cubic polynomial of their tangent-plane positions and takes the
symmetric part of the linear coefficients as the shape operator. On a sphere or a circular
cross-section the normal is an exactly linear function of position, so large noise-averaging
neighborhoods add no bias there (docs/research/issue6.md has the measurements).

The anchored fits of the default estimator (:func:`nfr_anchor_fits`) also fit the
normal-constrained quadric of :mod:`curvature.fitting.normal_quadric` to the same normals and
keep whichever model matches them better.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import cholesky, dot, jacobi3, solve_lower, solve_upper_t, total
from .normal_quadric import (
    curvature_from_quadric,
    quadric_curvature_xyz,
    regress_normal_quadric,
)
from .quadric import (
    DEGENERATE,
    NON_FINITE,
    OK,
    TOO_FEW,
    clear_outputs,
    eigen2,
    store_xyz,
    tangent_basis,
)

# Constant, 2 linear, 3 quadratic and 4 cubic monomials of the tangent coordinates.
N_TERMS = 10
MIN_POINTS_NFR = 12
# Which model an anchor keeps (nfr_anchor_fits).
MODEL_FIELD = 0
MODEL_QUADRIC = 1
# A quadric misfit below this (normals within about 1e-6 rad of the model) is an exact fit,
# kept whatever the field's misfit (both are then round-off).
EXACT_MISFIT = 1e-12
# A quadric's foot point farther than this many fit radii from the query point is rejected.
FOOT_LIMIT = 4.0
# Largest |k| * h a fit may report, h the RMS distance of its points from its centre: a
# curvature radius below half the spread of the points fitted is not something those points
# show (a sampled patch does not fold over within itself); it is what an implicit model does
# next to a feature it cannot follow (flat faces beside a fillet read 1e2 to 1e5 otherwise).
SUPPORT = 2.0
# Query points per parallel block of pca_normals (its two 3x3 scratch arrays per block).
PCA_BLOCK = 256


@njit(cache=True)
def supported(c1, c2, h):
    """Whether curvatures ``c1, c2`` of a fit of RMS radius ``h`` are within :data:`SUPPORT`."""
    return max(abs(c1), abs(c2)) * h <= SUPPORT


@njit(cache=True, inline="always")
def pca_normal_into(points, q, indices, lo, hi, cov, vec, out_row):
    """PCA normal of point ``q`` over ``indices[lo:hi]`` and ``q`` itself into ``out_row``
    (NaN where the points do not span a plane); returns the smallest eigenvalue of their
    covariance over its trace (0 for a plane, 1/3 for an isotropic blob; NaN with the
    normal). ``cov`` and ``vec`` (3, 3) are scratch."""
    k = hi - lo
    px, py, pz = points[q, 0], points[q, 1], points[q, 2]
    ss = 0.0
    for i in range(lo, hi):
        r = indices[i]
        x, y, z = points[r, 0] - px, points[r, 1] - py, points[r, 2] - pz
        ss += x * x
        ss += y * y
        ss += z * z
    scale = np.sqrt(ss / k) if k > 0 else 0.0
    unit = scale if scale > 0.0 else 1.0
    m = k + 1  # p itself, at the origin
    cx = cy = cz = 0.0
    for i in range(lo, hi):
        r = indices[i]
        cx += (points[r, 0] - px) / unit
        cy += (points[r, 1] - py) / unit
        cz += (points[r, 2] - pz) / unit
    cx, cy, cz = cx / m, cy / m, cz / m
    d0, d1, d2 = -cx, -cy, -cz
    c00, c01, c02 = d0 * d0, d0 * d1, d0 * d2
    c11, c12, c22 = d1 * d1, d1 * d2, d2 * d2
    for i in range(lo, hi):
        r = indices[i]
        d0 = (points[r, 0] - px) / unit - cx
        d1 = (points[r, 1] - py) / unit - cy
        d2 = (points[r, 2] - pz) / unit - cz
        c00 += d0 * d0
        c01 += d0 * d1
        c02 += d0 * d2
        c11 += d1 * d1
        c12 += d1 * d2
        c22 += d2 * d2
    cov[0, 0], cov[0, 1], cov[0, 2] = c00 / m, c01 / m, c02 / m
    cov[1, 0], cov[1, 1], cov[1, 2] = cov[0, 1], c11 / m, c12 / m
    cov[2, 0], cov[2, 1], cov[2, 2] = cov[0, 2], cov[1, 2], c22 / m
    i0, i1, i2 = jacobi3(cov, vec)
    if scale > 0.0 and cov[i1, i1] > 1e-10 * cov[i2, i2]:
        for d in range(3):
            out_row[d] = vec[d, i0]
        return cov[i0, i0] / (cov[0, 0] + cov[1, 1] + cov[2, 2])
    for d in range(3):
        out_row[d] = np.nan
    return np.nan


def pca_normals(points, query, indptr, indices, out):
    """Unit PCA normals (arbitrary sign) of the query points over their neighborhoods.

    The arithmetic of :func:`~curvature.fitting.kernels.gather_local` and
    :func:`~curvature.fitting.kernels.principal_axes`, in the same order (the same bits),
    without their per-point arrays: this runs at every point of the cloud.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    indptr, indices : ndarray
        CSR neighborhoods of the query points (query point not listed; it is added).
    out : ndarray, shape (m, 3)
        Output normals; NaN where the neighbors do not span a plane.
    """
    pca_flatness(points, query, indptr, indices, out, np.empty(0))


@njit(parallel=True, cache=True)
def pca_flatness(points, query, indptr, indices, out, flat):
    """:func:`pca_normals`, and how far each neighborhood is from a plane.

    Parameters
    ----------
    points, query, indptr, indices, out
        As for :func:`pca_normals`.
    flat : ndarray, shape (m,) or (0,)
        Output, unless empty: the smallest eigenvalue of each neighborhood's covariance over
        its trace (0 on a plane; about 0.1 over the two faces of a wall a few neighborhood
        radii thick); NaN where the normal is.
    """
    m_all = query.shape[0]
    blocks = (m_all + PCA_BLOCK - 1) // PCA_BLOCK
    for b in prange(blocks):
        cov = np.empty((3, 3))
        vec = np.empty((3, 3))
        for j in range(b * PCA_BLOCK, min(m_all, (b + 1) * PCA_BLOCK)):
            f = pca_normal_into(points, query[j], indices, indptr[j], indptr[j + 1], cov,
                                vec, out[j])
            if flat.shape[0] > 0:
                flat[j] = f


@njit(cache=True)
def _terms_into(u1, u2, cols, i):
    """The monomials 1, u1, u2, u1^2, u1 u2, u2^2, u1^3, u1^2 u2, u1 u2^2, u2^3 of one point,
    into column ``i`` of ``cols`` (N_TERMS, m)."""
    cols[0, i] = 1.0
    cols[1, i] = u1
    cols[2, i] = u2
    cols[3, i] = u1 * u1
    cols[4, i] = u1 * u2
    cols[5, i] = u2 * u2
    cols[6, i] = u1 * u1 * u1
    cols[7, i] = u1 * u1 * u2
    cols[8, i] = u1 * u2 * u2
    cols[9, i] = u2 * u2 * u2


@njit(cache=True)
def regress_normals(points, field, p, nbr, include_self, coef):
    """Cubic regression of the neighbors' normals on their tangent positions around ``p``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    field : ndarray, shape (n, 3)
        Unit normals of every point (sign arbitrary, NaN where unknown).
    p : int
        The fit's centre; its tangent frame is that of ``field[p]``.
    nbr : ndarray, shape (k,)
        Neighbors of p (p itself not listed).
    include_self : bool
        Whether p takes part in the fit.
    coef : ndarray, shape (2, N_TERMS)
        Output: coefficients of the two tangent normal components in the monomials of
        ``u / h`` (:func:`_terms_into`).

    Returns
    -------
    status : int
        OK, TOO_FEW or DEGENERATE.
    h : float
        RMS tangent distance of the fitted points (the monomials' unit).
    t1, t2 : ndarray, shape (3,)
        Tangent frame of ``field[p]``.
    residual : float
        RMS height of the fitted points above the osculating paraboloid of the fitted shape
        operator.
    misfit : float
        Mean squared residual of the fitted tangent normal components (about the squared
        angle between each normal and the field; compared with the normal-constrained
        quadric's misfit to choose between the two models).
    round_residual : float
        RMS height of the fitted points above the biconic of the fitted shape operator
        (:func:`_biconic_rms`): the shape a sphere or a cylinder would leave.
    """
    m = nbr.shape[0] + (1 if include_self else 0)
    n_p = field[p]
    t1, t2 = tangent_basis(np.array([1.0, 0.0, 0.0]))
    if m < MIN_POINTS_NFR:
        return TOO_FEW, 0.0, t1, t2, np.nan, np.nan, np.nan
    if not np.all(np.isfinite(n_p)):
        return DEGENERATE, 0.0, t1, t2, np.nan, np.nan, np.nan
    t1, t2 = tangent_basis(n_p)
    # Tangent coordinates, tangent normal components (neighbor normals flipped to agree with
    # p's) and heights of the fitted points, one row per quantity so the sums below run over
    # contiguous memory; p itself is column 0 when included.
    uv = np.empty((2, m))
    g = np.empty((2, m))
    hgt = np.empty(m)
    ok_pts = 0
    # Scalars throughout: this loop runs a few hundred times per fit and must not allocate.
    px, py, pz = points[p, 0], points[p, 1], points[p, 2]
    nx, ny, nz = n_p[0], n_p[1], n_p[2]
    for i in range(m):
        q = p if (include_self and i == 0) else nbr[i - (1 if include_self else 0)]
        qx, qy, qz = field[q, 0], field[q, 1], field[q, 2]
        if not (np.isfinite(qx) and np.isfinite(qy) and np.isfinite(qz)):
            continue
        dx = points[q, 0] - px
        dy = points[q, 1] - py
        dz = points[q, 2] - pz
        s = 1.0 if qx * nx + qy * ny + qz * nz >= 0.0 else -1.0
        uv[0, ok_pts] = dx * t1[0] + dy * t1[1] + dz * t1[2]
        uv[1, ok_pts] = dx * t2[0] + dy * t2[1] + dz * t2[2]
        g[0, ok_pts] = s * (qx * t1[0] + qy * t1[1] + qz * t1[2])
        g[1, ok_pts] = s * (qx * t2[0] + qy * t2[1] + qz * t2[2])
        hgt[ok_pts] = dx * nx + dy * ny + dz * nz
        ok_pts += 1
    if ok_pts < MIN_POINTS_NFR:
        return TOO_FEW, 0.0, t1, t2, np.nan, np.nan, np.nan
    h = np.sqrt((dot(uv[0], uv[0], ok_pts) + dot(uv[1], uv[1], ok_pts)) / ok_pts)
    if not h > 0.0:
        return DEGENERATE, 0.0, t1, t2, np.nan, np.nan, np.nan
    # The design matrix by columns (one monomial per row of `cols`): its Gram matrix is then
    # dot products of contiguous vectors.
    cols = np.empty((N_TERMS, ok_pts))
    for i in range(ok_pts):
        _terms_into(uv[0, i] / h, uv[1, i] / h, cols, i)
    ata = np.empty((N_TERMS, N_TERMS))
    atg = np.empty((N_TERMS, 2))
    for r in range(N_TERMS):
        atg[r, 0] = dot(cols[r], g[0], ok_pts)
        atg[r, 1] = dot(cols[r], g[1], ok_pts)
        for c in range(r, N_TERMS):
            ata[r, c] = dot(cols[r], cols[c], ok_pts)
            ata[c, r] = ata[r, c]
    l, good = cholesky(ata, 1e-12)
    if not good:
        return DEGENERATE, h, t1, t2, np.nan, np.nan, np.nan
    beta0 = solve_upper_t(l, solve_lower(l, atg[:, 0].copy()))
    beta1 = solve_upper_t(l, solve_lower(l, atg[:, 1].copy()))
    for r in range(N_TERMS):
        coef[0, r] = beta0[r]
        coef[1, r] = beta1[r]
    # d(normal_a)/d(u_b) = coef[a, 1 + b] / h at p; heights against the osculating paraboloid
    # w = w0 - u'Su/2 of its symmetric part (w0 fitted as a mean).
    s11 = 0.5 * beta0[1] / h
    s22 = 0.5 * beta1[2] / h
    s12 = 0.5 * (beta0[2] + beta1[1]) / h
    dev = np.empty(ok_pts)
    for i in range(ok_pts):
        u1, u2 = uv[0, i], uv[1, i]
        dev[i] = hgt[i] + s11 * u1 * u1 + s12 * u1 * u2 + s22 * u2 * u2
    off = total(dev, ok_pts) / ok_pts
    for i in range(ok_pts):
        dev[i] -= off
    # Residuals of the fitted tangent normal components, a monomial at a time.
    r0 = g[0, :ok_pts].copy()
    r1 = g[1, :ok_pts].copy()
    for r in range(N_TERMS):
        b0, b1 = beta0[r], beta1[r]
        for i in range(ok_pts):
            r0[i] -= b0 * cols[r, i]
            r1[i] -= b1 * cols[r, i]
    mis = dot(r0, r0, ok_pts) + dot(r1, r1, ok_pts)
    # (the Hessian of the paraboloid's height is -2 [[s11, s12 / 2], [s12 / 2, s22]])
    round_rms = _biconic_rms(uv, hgt, ok_pts, -2.0 * s11, -s12, -2.0 * s22)
    return (OK, h, t1, t2, np.sqrt(dot(dev, dev, ok_pts) / ok_pts), mis / ok_pts,
            round_rms)


@njit(cache=True)
def _biconic_rms(uv, hgt, m, k11, k12, k22):
    """RMS height of points above the biconic of a shape operator, about their mean.

    The biconic ``w = (k1 a^2 + k2 b^2) / (1 + sqrt(1 - k1^2 a^2 - k2^2 b^2))``, with (a, b)
    the tangent coordinates along the principal directions, is the sphere or the cylinder
    itself where the curvatures make one, and the paraboloid ``(k1 a^2 + k2 b^2) / 2`` to
    second order. Over a patch that wraps far around a tube (a torus's, 0.7 of its radius
    each way) a paraboloid misses the points by its slope alone, far above the noise; this
    misses them by what the curvature's change and the noise leave.

    Parameters
    ----------
    uv : ndarray, shape (2, >= m)
        Tangent coordinates.
    hgt : ndarray, shape (>= m,)
        Heights along the normal.
    m : int
        Points used (the first m).
    k11, k12, k22 : float
        The height's Hessian (shape operator) in the tangent coordinates.

    Returns
    -------
    float
    """
    ka, kb, ex, ey = eigen2(k11, k12, k22)
    dev = np.empty(m)
    for i in range(m):
        a = uv[0, i] * ex + uv[1, i] * ey
        b = uv[1, i] * ex - uv[0, i] * ey
        # (beyond the sphere's reach the root is cut at 0: the height of its equator)
        root = np.sqrt(max(1.0 - ka * ka * a * a - kb * kb * b * b, 0.0))
        dev[i] = hgt[i] - (ka * a * a + kb * b * b) / (1.0 + root)
    mean = total(dev, m) / m
    for i in range(m):
        dev[i] -= mean
    return np.sqrt(dot(dev, dev, m) / m)


@njit(cache=True)
def curvature_from_field(coef, h, n_p, t1, t2, u1, u2, j, k1, k2, normals, dir1, dir2):
    """Write the curvature of a fitted normal field at tangent position ``(u1, u2)``.

    The field is ``n_p + g1 t1 + g2 t2`` with ``g_a = coef[a] . terms(u / h)``
    (:func:`_terms_into`); its shape operator at u is the symmetric part of ``dg/du``.

    Returns
    -------
    bool
        False if the outputs are not finite (they are then left for the caller to clear).
    """
    # Scalars throughout: reads run this once per point.
    x1 = u1 / h
    x2 = u2 / h
    g1, j11, j12 = _component_at(coef, 0, x1, x2)
    g2, j21, j22 = _component_at(coef, 1, x1, x2)
    c1, c2, e1, e2 = eigen2(j11 / h, 0.5 * (j12 + j21) / h, j22 / h)
    # The field's normal there, and k1's direction made tangent to it.
    m0 = n_p[0] + g1 * t1[0] + g2 * t2[0]
    m1 = n_p[1] + g1 * t1[1] + g2 * t2[1]
    m2 = n_p[2] + g1 * t1[2] + g2 * t2[2]
    mn = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    m0, m1, m2 = m0 / mn, m1 / mn, m2 / mn
    d0 = e1 * t1[0] + e2 * t2[0]
    d1 = e1 * t1[1] + e2 * t2[1]
    d2 = e1 * t1[2] + e2 * t2[2]
    along = d0 * m0 + d1 * m1 + d2 * m2
    d0, d1, d2 = d0 - along * m0, d1 - along * m1, d2 - along * m2
    dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return store_xyz(j, c1, c2, m0, m1, m2, d0 / dn, d1 / dn, d2 / dn, k1, k2, normals, dir1,
                     dir2)


@njit(cache=True)
def _component_at(coef, a, x1, x2):
    """Tangent normal component ``a`` of a fitted field at scaled position ``(x1, x2)`` and its
    derivatives along x1 and x2 (the monomials of :func:`_terms_into`)."""
    c = coef[a]
    x11, x12, x22 = x1 * x1, x1 * x2, x2 * x2
    g = (c[0] + c[1] * x1 + c[2] * x2 + c[3] * x11 + c[4] * x12 + c[5] * x22
         + c[6] * x11 * x1 + c[7] * x11 * x2 + c[8] * x1 * x22 + c[9] * x22 * x2)
    d1 = (c[1] + c[3] * 2.0 * x1 + c[4] * x2 + c[6] * 3.0 * x11 + c[7] * 2.0 * x12
          + c[8] * x22)
    d2 = (c[2] + c[4] * x1 + c[5] * 2.0 * x2 + c[7] * x11 + c[8] * 2.0 * x12
          + c[9] * 3.0 * x22)
    return g, d1, d2


@njit(parallel=True, cache=True)
def nfr_batch(points, stage1, query, indptr, indices, include_self,
              k1, k2, normals, dir1, dir2, residual, status):
    """Cubic normal-field regression for every query point (outputs as in ``fit_batch``).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    stage1 : ndarray, shape (n, 3)
        Stage-1 unit normals of every point (sign arbitrary, NaN where unknown).
    query, indptr, indices, include_self
        As in :func:`curvature.fitting.kernels.fit_batch`.
    k1, k2, residual : ndarray, shape (m,)
    normals, dir1, dir2 : ndarray, shape (m, 3)
    status : ndarray, shape (m,), int8
        Outputs. ``residual`` is the RMS distance of the fitted points to the osculating
        paraboloid of the estimated shape operator. The normal's sign is the stage-1 normal's.
    """
    for j in prange(query.shape[0]):
        coef = np.empty((2, N_TERMS))  # per iteration: a buffer shared by threads would race
        clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
        p = query[j]
        st, h, t1, t2, res, _, _ = regress_normals(points, stage1, p,
                                                indices[indptr[j]:indptr[j + 1]],
                                                include_self, coef)
        if st != OK:
            status[j] = st
            continue
        if not curvature_from_field(coef, h, stage1[p], t1, t2, 0.0, 0.0, j,
                                    k1, k2, normals, dir1, dir2):
            clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
            status[j] = NON_FINITE
            continue
        residual[j] = res
        status[j] = OK


@njit(parallel=True, cache=True)
def nfr_anchor_fits(points, field, anchors, indptr, indices, nfr_ratio, coef, scale, frame,
                    quad, quad_scale, model, residual, status):
    """Normal-field fits at anchor points, kept as coefficients for nearby points.

    Every anchor fits both the cubic normal field (:func:`regress_normals`) and the
    normal-constrained quadric (:mod:`curvature.fitting.normal_quadric`) to the same normals,
    and keeps the field only where it fits the normals clearly better: its misfit below
    ``nfr_ratio`` times the quadric's, and the quadric's not exact (``EXACT_MISFIT``). The
    quadric averages noise better and is exact on every quadric surface; the field follows
    surfaces that are no quadric at the fit's scale.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    field : ndarray, shape (n, 3)
        Unit normals of every point (sign arbitrary, NaN where unknown).
    anchors : ndarray, shape (a,), int64
        Anchor point indices.
    indptr, indices : ndarray
        CSR neighborhoods of the anchors (anchor not listed; it takes part in its fit).
    nfr_ratio : float
        Misfit ratio below which the cubic field is kept (0: always the quadric; inf: always
        the field).
    coef : ndarray, shape (a, 2, N_TERMS)
    scale : ndarray, shape (a,)
    frame : ndarray, shape (a, 3, 3)
        Outputs of the field: coefficients, monomial unit h, rows (t1, t2, n) of its frame.
    quad : ndarray, shape (a, N_QUAD)
    quad_scale : ndarray, shape (a,)
        Outputs of the quadric: coefficients and coordinate unit.
    model : ndarray, shape (a,), int8
        Output: MODEL_FIELD or MODEL_QUADRIC, the model kept.
    residual : ndarray, shape (a,)
        Output: the kept model's residual distance.
    status : ndarray, shape (a,), int8
        Output status of each anchor's fit.
    """
    for j in prange(anchors.shape[0]):
        nfr_anchor_fits_one(points, field, anchors[j], indices[indptr[j]:indptr[j + 1]],
                            nfr_ratio, coef[j], quad[j], frame[j], j, scale, quad_scale, model,
                            residual, status)


@njit(cache=True)
def nfr_anchor_fits_one(points, field, p, nbr, nfr_ratio, coef_j, quad_j, frame_j, j, scale,
                        quad_scale, model, residual, status):
    """One anchor of :func:`nfr_anchor_fits` (row ``j`` of its outputs); also returns the
    kept model's curvature at the anchor, for the scale selection of
    :mod:`curvature.fitting.scale_selection`.

    Returns
    -------
    k1, k2 : float
        The kept model's principal curvatures at the anchor (NaN when not OK).
    distance : float
        The kept model's RMS distance of the fitted points to its surface.
    radius : float
        RMS distance of the fitted points from the anchor.
    misfit : float
        The kept model's mean squared residual of the fitted normals (about the squared
        angle between each normal and the model's).
    shape_distance : float
        What of ``distance`` a shape of the fitted curvature does not explain: for the
        normal field its RMS distance to the biconic, not the paraboloid
        (:func:`regress_normals`); for the quadric ``distance`` itself.
    """
    st, h, t1, t2, res, mis, round_res = regress_normals(points, field, p, nbr, True, coef_j)
    qst, qh, qmis, qres = regress_normal_quadric(points, field, p, nbr, True, quad_j)
    scale[j] = h
    quad_scale[j] = qh
    for d in range(3):
        frame_j[0, d] = t1[d]
        frame_j[1, d] = t2[d]
        frame_j[2, d] = field[p, d]
    if qst == OK and not (st == OK and qmis > EXACT_MISFIT and mis < nfr_ratio * qmis):
        model[j] = MODEL_QUADRIC
        status[j] = OK
        residual[j] = qres
        fst, c1, c2, _, _, _ = curvature_from_quadric(quad_j, qh, np.zeros(3), FOOT_LIMIT)
        if fst != OK:
            return np.nan, np.nan, qres, qh, qmis, qres
        return c1, c2, qres, qh, qmis, qres
    model[j] = MODEL_FIELD
    status[j] = st
    residual[j] = res
    if st != OK:
        return np.nan, np.nan, res, qh, mis, round_res
    # Scratch outputs of one row: curvature_from_field writes into result arrays.
    k1o, k2o = np.empty(1), np.empty(1)
    vecs = np.empty((3, 1, 3))
    if not curvature_from_field(coef_j, h, field[p], t1, t2, 0.0, 0.0, 0, k1o, k2o, vecs[0],
                                vecs[1], vecs[2]):
        return np.nan, np.nan, res, qh, mis, round_res
    return k1o[0], k2o[0], res, qh, mis, round_res


@njit(parallel=True, cache=True)
def nfr_from_anchors(points, query, owner, anchors, coef, scale, frame, quad, quad_scale, model,
                     fit_residual, fit_status, k1, k2, normals, dir1, dir2, residual, status):
    """Curvature of query points from the model fitted at their anchor.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
        Query point indices.
    owner : ndarray, shape (m,), int64
        Index into ``anchors`` of each query point's anchor.
    anchors, coef, scale, frame, quad, quad_scale, model, fit_residual, fit_status
        As written by :func:`nfr_anchor_fits`.
    k1, k2, residual : ndarray, shape (m,)
    normals, dir1, dir2 : ndarray, shape (m, 3)
    status : ndarray, shape (m,), int8
        Outputs as in ``fit_batch``; the residual is the anchor fit's. Normals are on the side
        of the anchor's normal. The field is read at the point's tangent position; the quadric
        at the point's foot point on it.
    """
    for j in prange(query.shape[0]):
        clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
        a = owner[j]
        if fit_status[a] != OK:
            status[j] = fit_status[a]
            continue
        p = query[j]
        c = anchors[a]
        dx = points[p, 0] - points[c, 0]
        dy = points[p, 1] - points[c, 1]
        dz = points[p, 2] - points[c, 2]
        if model[a] == MODEL_QUADRIC:
            hq = quad_scale[a]
            st, c1, c2, n0, n1, n2, e0, e1, e2 = quadric_curvature_xyz(
                quad[a], hq, dx / hq, dy / hq, dz / hq, FOOT_LIMIT)
            if st != OK or not supported(c1, c2, hq):
                # Read the model at its anchor instead: scale selection admitted it there.
                st, c1, c2, n0, n1, n2, e0, e1, e2 = quadric_curvature_xyz(
                    quad[a], hq, 0.0, 0.0, 0.0, FOOT_LIMIT)
            if st != OK or not supported(c1, c2, hq):
                status[j] = DEGENERATE if st == OK else st
                continue
            if not store_xyz(j, c1, c2, n0, n1, n2, e0, e1, e2, k1, k2, normals, dir1, dir2):
                clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
                status[j] = NON_FINITE
                continue
        else:
            t1 = frame[a, 0]
            t2 = frame[a, 1]
            u1 = dx * t1[0] + dy * t1[1] + dz * t1[2]
            u2 = dx * t2[0] + dy * t2[1] + dz * t2[2]
            ok = curvature_from_field(coef[a], scale[a], frame[a, 2], t1, t2, u1, u2, j,
                                      k1, k2, normals, dir1, dir2)
            if not (ok and supported(k1[j], k2[j], scale[a])):
                ok = curvature_from_field(coef[a], scale[a], frame[a, 2], t1, t2, 0.0, 0.0, j,
                                          k1, k2, normals, dir1, dir2)
                if ok and not supported(k1[j], k2[j], scale[a]):
                    clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
                    status[j] = DEGENERATE
                    continue
            if not ok:
                clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
                status[j] = NON_FINITE
                continue
        residual[j] = fit_residual[a]
        status[j] = OK
