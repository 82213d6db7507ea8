"""Normal-field regression: curvature from how estimated normals vary across a neighborhood.

The shape operator is the derivative of the unit normal along the surface. Stage 1 estimates a
normal per point by PCA over a few dozen neighbors; stage 2 fits the tangent components of the
neighbors' normals as a cubic polynomial of their tangent-plane positions and takes the
symmetric part of the linear coefficients as the shape operator. On a sphere or a circular
cross-section the normal is an exactly linear function of position, so large noise-averaging
neighborhoods add no bias there (docs/research/issue6.md has the measurements).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .kernels import gather_local, principal_axes
from .linalg import cholesky, solve_lower, solve_upper_t
from .quadric import (
    DEGENERATE,
    NON_FINITE,
    OK,
    TOO_FEW,
    clear_outputs,
    tangent_basis,
    tangent_eigen,
)

# Constant, 2 linear, 3 quadratic and 4 cubic monomials of the tangent coordinates.
N_TERMS = 10
MIN_POINTS_NFR = 12


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
        row = np.empty(N_TERMS)  # per iteration: a buffer shared across threads would race
        clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
        p = query[j]
        nbr = indices[indptr[j]:indptr[j + 1]]
        m = nbr.shape[0] + (1 if include_self else 0)
        if m < MIN_POINTS_NFR:
            status[j] = TOO_FEW
            continue
        n_p = stage1[p]
        if not np.all(np.isfinite(n_p)):
            status[j] = DEGENERATE
            continue
        t1, t2 = tangent_basis(n_p)
        # Tangent coordinates, tangent normal components (neighbor normals flipped to agree
        # with p's) and heights of the fitted points; p itself is row 0 when included.
        uv = np.empty((m, 2))
        g = np.empty((m, 2))
        hgt = np.empty(m)
        ok_pts = 0
        # Scalars throughout: this loop runs a few hundred times per point and must not
        # allocate.
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        nx, ny, nz = n_p[0], n_p[1], n_p[2]
        for i in range(m):
            q = p if (include_self and i == 0) else nbr[i - (1 if include_self else 0)]
            qx, qy, qz = stage1[q, 0], stage1[q, 1], stage1[q, 2]
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
            status[j] = TOO_FEW
            continue
        h = np.sqrt(np.sum(uv[:ok_pts] ** 2) / ok_pts)
        if not h > 0.0:
            status[j] = DEGENERATE
            continue
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
            status[j] = DEGENERATE
            continue
        beta0 = solve_upper_t(l, solve_lower(l, atg[:, 0].copy()))
        beta1 = solve_upper_t(l, solve_lower(l, atg[:, 1].copy()))
        # d(normal_a)/d(u_b) = beta_a[1 + b] / h; the shape operator is its symmetric part.
        s11 = beta0[1] / h
        s22 = beta1[2] / h
        s12 = 0.5 * (beta0[2] + beta1[1]) / h
        c1, c2, d1 = tangent_eigen(s11, s12, s22, t1, t2)
        # The intercepts are the tangent components of the smoothed normal at p.
        nn = n_p + beta0[0] * t1 + beta1[0] * t2
        nn /= np.sqrt(np.sum(nn * nn))
        d1 = d1 - np.sum(d1 * nn) * nn
        d1 /= np.sqrt(np.sum(d1 * d1))
        d2 = np.cross(nn, d1)
        # Heights against the osculating paraboloid w = w0 - u'Su/2 (w0 fitted as a mean).
        off = 0.0
        for i in range(ok_pts):
            u1, u2 = uv[i, 0], uv[i, 1]
            off += hgt[i] + 0.5 * (s11 * u1 * u1 + 2.0 * s12 * u1 * u2 + s22 * u2 * u2)
        off /= ok_pts
        ss = 0.0
        for i in range(ok_pts):
            u1, u2 = uv[i, 0], uv[i, 1]
            dev = hgt[i] + 0.5 * (s11 * u1 * u1 + 2.0 * s12 * u1 * u2 + s22 * u2 * u2) - off
            ss += dev * dev
        if not (np.isfinite(c1) and np.isfinite(c2) and np.all(np.isfinite(nn))
                and np.all(np.isfinite(d1))):
            status[j] = NON_FINITE
            continue
        k1[j] = c1
        k2[j] = c2
        residual[j] = np.sqrt(ss / ok_pts)
        for d in range(3):
            normals[j, d] = nn[d]
            dir1[j, d] = d1[d]
            dir2[j, d] = d2[d]
        status[j] = OK
