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

from .kernels import gather_local, principal_axes
from .linalg import cholesky, solve_lower, solve_upper_t
from .normal_quadric import curvature_from_quadric, regress_normal_quadric
from .quadric import (
    DEGENERATE,
    NON_FINITE,
    OK,
    TOO_FEW,
    clear_outputs,
    store_outputs,
    tangent_basis,
    tangent_eigen,
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


@njit(cache=True)
def supported(c1, c2, h):
    """Whether curvatures ``c1, c2`` of a fit of RMS radius ``h`` are within :data:`SUPPORT`."""
    return max(abs(c1), abs(c2)) * h <= SUPPORT


@njit(parallel=True, cache=True)
def pca_normals(points, query, indptr, indices, out):
    """Unit PCA normals (arbitrary sign) of the query points over their neighborhoods.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    indptr, indices : ndarray
        CSR neighborhoods of the query points (query point not listed; it is added).
    out : ndarray, shape (m, 3)
        Output normals; NaN where the neighbors do not span a plane.
    """
    for j in prange(query.shape[0]):
        nbr = indices[indptr[j]:indptr[j + 1]]
        xs, scale = gather_local(points, query[j], nbr, True)
        w, v = principal_axes(xs)
        if scale > 0.0 and w[1] > 1e-10 * w[2]:
            for d in range(3):
                out[j, d] = v[d, 0]
        else:
            for d in range(3):
                out[j, d] = np.nan


@njit(cache=True)
def _terms(u1, u2, row):
    row[0] = 1.0
    row[1] = u1
    row[2] = u2
    row[3] = u1 * u1
    row[4] = u1 * u2
    row[5] = u2 * u2
    row[6] = u1 * u1 * u1
    row[7] = u1 * u1 * u2
    row[8] = u1 * u2 * u2
    row[9] = u2 * u2 * u2


@njit(cache=True)
def _d_terms(u1, u2, d1, d2):
    """Derivatives of :func:`_terms` with respect to u1 (into ``d1``) and u2 (``d2``)."""
    d1[0] = 0.0
    d1[1] = 1.0
    d1[2] = 0.0
    d1[3] = 2.0 * u1
    d1[4] = u2
    d1[5] = 0.0
    d1[6] = 3.0 * u1 * u1
    d1[7] = 2.0 * u1 * u2
    d1[8] = u2 * u2
    d1[9] = 0.0
    d2[0] = 0.0
    d2[1] = 0.0
    d2[2] = 1.0
    d2[3] = 0.0
    d2[4] = u1
    d2[5] = 2.0 * u2
    d2[6] = 0.0
    d2[7] = u1 * u1
    d2[8] = 2.0 * u1 * u2
    d2[9] = 3.0 * u2 * u2


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
        ``u / h`` (:func:`_terms`).

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
    """
    m = nbr.shape[0] + (1 if include_self else 0)
    n_p = field[p]
    t1, t2 = tangent_basis(np.array([1.0, 0.0, 0.0]))
    if m < MIN_POINTS_NFR:
        return TOO_FEW, 0.0, t1, t2, np.nan, np.nan
    if not np.all(np.isfinite(n_p)):
        return DEGENERATE, 0.0, t1, t2, np.nan, np.nan
    t1, t2 = tangent_basis(n_p)
    # Tangent coordinates, tangent normal components (neighbor normals flipped to agree with
    # p's) and heights of the fitted points; p itself is row 0 when included.
    uv = np.empty((m, 2))
    g = np.empty((m, 2))
    hgt = np.empty(m)
    row = np.empty(N_TERMS)
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
        uv[ok_pts, 0] = dx * t1[0] + dy * t1[1] + dz * t1[2]
        uv[ok_pts, 1] = dx * t2[0] + dy * t2[1] + dz * t2[2]
        g[ok_pts, 0] = s * (qx * t1[0] + qy * t1[1] + qz * t1[2])
        g[ok_pts, 1] = s * (qx * t2[0] + qy * t2[1] + qz * t2[2])
        hgt[ok_pts] = dx * nx + dy * ny + dz * nz
        ok_pts += 1
    if ok_pts < MIN_POINTS_NFR:
        return TOO_FEW, 0.0, t1, t2, np.nan, np.nan
    h = np.sqrt(np.sum(uv[:ok_pts] ** 2) / ok_pts)
    if not h > 0.0:
        return DEGENERATE, 0.0, t1, t2, np.nan, np.nan
    ata = np.zeros((N_TERMS, N_TERMS))
    atg = np.zeros((N_TERMS, 2))
    for i in range(ok_pts):
        _terms(uv[i, 0] / h, uv[i, 1] / h, row)
        for r in range(N_TERMS):
            atg[r, 0] += row[r] * g[i, 0]
            atg[r, 1] += row[r] * g[i, 1]
            for c in range(r, N_TERMS):
                ata[r, c] += row[r] * row[c]
    for r in range(N_TERMS):
        for c in range(r + 1, N_TERMS):
            ata[c, r] = ata[r, c]
    l, good = cholesky(ata, 1e-12)
    if not good:
        return DEGENERATE, h, t1, t2, np.nan, np.nan
    beta0 = solve_upper_t(l, solve_lower(l, atg[:, 0].copy()))
    beta1 = solve_upper_t(l, solve_lower(l, atg[:, 1].copy()))
    for r in range(N_TERMS):
        coef[0, r] = beta0[r]
        coef[1, r] = beta1[r]
    # d(normal_a)/d(u_b) = coef[a, 1 + b] / h at p; heights against the osculating paraboloid
    # w = w0 - u'Su/2 of its symmetric part (w0 fitted as a mean).
    s11 = beta0[1] / h
    s22 = beta1[2] / h
    s12 = 0.5 * (beta0[2] + beta1[1]) / h
    off = 0.0
    for i in range(ok_pts):
        u1, u2 = uv[i, 0], uv[i, 1]
        off += hgt[i] + 0.5 * (s11 * u1 * u1 + 2.0 * s12 * u1 * u2 + s22 * u2 * u2)
    off /= ok_pts
    ss = 0.0
    mis = 0.0
    for i in range(ok_pts):
        u1, u2 = uv[i, 0], uv[i, 1]
        dev = hgt[i] + 0.5 * (s11 * u1 * u1 + 2.0 * s12 * u1 * u2 + s22 * u2 * u2) - off
        ss += dev * dev
        _terms(u1 / h, u2 / h, row)
        r0 = g[i, 0]
        r1 = g[i, 1]
        for r in range(N_TERMS):
            r0 -= beta0[r] * row[r]
            r1 -= beta1[r] * row[r]
        mis += r0 * r0 + r1 * r1
    return OK, h, t1, t2, np.sqrt(ss / ok_pts), mis / ok_pts


@njit(cache=True)
def curvature_from_field(coef, h, n_p, t1, t2, u1, u2, j, k1, k2, normals, dir1, dir2):
    """Write the curvature of a fitted normal field at tangent position ``(u1, u2)``.

    The field is ``n_p + g1 t1 + g2 t2`` with ``g_a = coef[a] . terms(u / h)``; its shape
    operator at u is the symmetric part of ``dg/du``.

    Returns
    -------
    bool
        False if the outputs are not finite (they are then left for the caller to clear).
    """
    row = np.empty(N_TERMS)
    d1t = np.empty(N_TERMS)
    d2t = np.empty(N_TERMS)
    x1 = u1 / h
    x2 = u2 / h
    _terms(x1, x2, row)
    _d_terms(x1, x2, d1t, d2t)
    g1 = 0.0
    g2 = 0.0
    j11 = 0.0
    j12 = 0.0
    j21 = 0.0
    j22 = 0.0
    for r in range(N_TERMS):
        g1 += coef[0, r] * row[r]
        g2 += coef[1, r] * row[r]
        j11 += coef[0, r] * d1t[r]
        j12 += coef[0, r] * d2t[r]
        j21 += coef[1, r] * d1t[r]
        j22 += coef[1, r] * d2t[r]
    c1, c2, d1 = tangent_eigen(j11 / h, 0.5 * (j12 + j21) / h, j22 / h, t1, t2)
    nn = n_p + g1 * t1 + g2 * t2
    nn /= np.sqrt(np.sum(nn * nn))
    d1 = d1 - np.sum(d1 * nn) * nn
    d1 /= np.sqrt(np.sum(d1 * d1))
    d2 = np.cross(nn, d1)
    return store_outputs(j, c1, c2, nn, d1, d2, k1, k2, normals, dir1, dir2)


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
        st, h, t1, t2, res, _ = regress_normals(points, stage1, p,
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
    """
    st, h, t1, t2, res, mis = regress_normals(points, field, p, nbr, True, coef_j)
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
            return np.nan, np.nan, qres, qh
        return c1, c2, qres, qh
    model[j] = MODEL_FIELD
    status[j] = st
    residual[j] = res
    if st != OK:
        return np.nan, np.nan, res, qh
    # Scratch outputs of one row: curvature_from_field writes into result arrays.
    k1o, k2o = np.empty(1), np.empty(1)
    vecs = np.empty((3, 1, 3))
    if not curvature_from_field(coef_j, h, field[p], t1, t2, 0.0, 0.0, 0, k1o, k2o, vecs[0],
                                vecs[1], vecs[2]):
        return np.nan, np.nan, res, qh
    return k1o[0], k2o[0], res, qh


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
            st, c1, c2, nn, d1, d2 = curvature_from_quadric(
                quad[a], hq, np.array([dx / hq, dy / hq, dz / hq]), FOOT_LIMIT)
            if st != OK or not supported(c1, c2, hq):
                # Read the model at its anchor instead: scale selection admitted it there.
                st, c1, c2, nn, d1, d2 = curvature_from_quadric(quad[a], hq, np.zeros(3),
                                                                FOOT_LIMIT)
            if st != OK or not supported(c1, c2, hq):
                status[j] = DEGENERATE if st == OK else st
                continue
            if not store_outputs(j, c1, c2, nn, d1, d2, k1, k2, normals, dir1, dir2):
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
