"""The bicubic Bezier patch: a free-form surface with elliptic and hyperbolic regions, the
paper's second test shape (DESIGN.md section 8). Conventions in :mod:`curvature.synthetic`.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .base import (
    _check_common,
    _cross,
    _finish,
    _grid_max,
    _rejection_sample,
    _square_interior,
    _uniform_box,
)

#: Heights z_ij of the default bicubic Bezier control net. Control point P_ij = (i, j, z_ij)
#: for i, j = 0..3 (i runs along x, j along y), so the net spans [0, 3] x [0, 3] in x, y.
#: The resulting wavy patch has both elliptic (K > 0, about 48 % of its area) and hyperbolic
#: (K < 0, about 52 %) regions; k1 lies in about [-0.09, 0.93] and k2 in [-1.09, 0.46], the
#: larger magnitude max(|k1|, |k2|) is 0.15 .. 0.75 on 90 % of the area (max 1.09), and the slope
#: |grad z| stays below 0.8.
BEZIER_DEFAULT_HEIGHTS = (
    (0.0, 0.6, 0.4, 0.0),
    (0.5, 1.4, -0.6, 0.2),
    (0.3, -0.5, 1.2, 0.6),
    (0.0, 0.3, 0.5, 0.1),
)


def bezier_control_net(heights=BEZIER_DEFAULT_HEIGHTS):
    """The 4x4 control net P_ij = (i, j, heights[i][j]) over [0, 3] x [0, 3].

    Parameters
    ----------
    heights : array_like, shape (4, 4)
        z coordinates of the control points.

    Returns
    -------
    ndarray, shape (4, 4, 3)
    """
    h = np.asarray(heights, dtype=np.float64)
    if h.shape != (4, 4):
        raise ParameterError(f"heights must have shape (4, 4), got {h.shape}")
    i, j = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij")
    return np.stack([i, j, h], axis=-1)


def _bernstein3(t, order):
    """Cubic Bernstein basis B_i(t) and its derivatives up to ``order`` (0..2).

    Returns a list of ``order + 1`` arrays of shape (4, n): B, B', B'' (basis index first, so
    every row is contiguous).
    """
    s = 1.0 - t
    ts, tt, ss = t * s, t * t, s * s
    out = [np.stack([ss * s, 3.0 * ts * s, 3.0 * ts * t, tt * t])]
    if order >= 1:
        out.append(np.stack([-3.0 * ss, 3.0 * ss - 6.0 * ts, 6.0 * ts - 3.0 * tt, 3.0 * tt]))
    if order >= 2:
        out.append(np.stack([6.0 * s, 18.0 * t - 12.0, 6.0 - 18.0 * t, 6.0 * t]))
    return out


def _bezier_derivatives(net, u, v, orders):
    """Partial derivatives of the bicubic patch at (u, v).

    r(u, v) = sum_ij B_i(u) B_j(v) P_ij (tensor-product Bezier patch; Farin, *Curves and
    Surfaces for CAGD*, ch. 14), so d^(a+b) r / du^a dv^b = sum_ij B_i^(a)(u) B_j^(b)(v) P_ij.

    Parameters
    ----------
    net : ndarray, shape (4, 4, 3)
        Control points P_ij.
    u, v : ndarray, shape (n,)
        Parameters in [0, 1].
    orders : sequence of (int, int)
        Derivative orders (a, b), each 0..2.

    Returns
    -------
    list of ndarray, shape (n, 3)
        One array per requested order (Fortran-ordered views).
    """
    bu = _bernstein3(u, max(a for a, _ in orders))
    bv = _bernstein3(v, max(b for _, b in orders))
    flat = net.transpose(1, 2, 0).reshape(12, 4)  # rows (j, k), columns i
    partial = {}
    out = []
    for a, b in orders:
        if a not in partial:
            # sum over i: partial[j, k, :] = sum_i P_ijk B_i^(a)(u), shape (4, 3, n)
            partial[a] = (flat @ bu[a]).reshape(4, 3, -1)
        p, w = partial[a], bv[b]
        r = p[0] * w[0]
        for j in range(1, 4):  # sum over j
            r += p[j] * w[j]
        out.append(r.T)
    return out


def bezier_patch(n=10000, control=None, *, sampling="area", noise=0.0, noise_model="axis",
                 seed=0):
    """Bicubic tensor-product Bezier patch r(u, v) = sum_ij B_i(u) B_j(v) P_ij, (u, v) in [0, 1]^2.

    The default control net is P_ij = (i, j, z_ij), i, j = 0..3, with heights
    :data:`BEZIER_DEFAULT_HEIGHTS`::

        z = [[0.0,  0.6,  0.4, 0.0],
             [0.5,  1.4, -0.6, 0.2],
             [0.3, -0.5,  1.2, 0.6],
             [0.0,  0.3,  0.5, 0.1]]

    Because x and y control coordinates are evenly spaced, x = 3u and y = 3v exactly and the
    patch is the graph of a bicubic height function over [0, 3] x [0, 3]. It has both positive
    (about 48 % of the area) and negative Gaussian curvature; k1 is in about [-0.09, 0.93],
    k2 in [-1.09, 0.46], and max(|k1|, |k2|) is 0.15 .. 0.75 on 90 % of the area (median
    0.36, max 1.09). Umbilics, if any, are isolated points, so dir1/dir2 are finite in
    practice. Normals have a positive z
    component (for the default net; for a custom net, the direction of r_u x r_v).
    ``uv`` holds (u, v). Area-uniform sampling rejects on |r_u x r_v|, with its bound
    estimated on a 129 x 129 grid plus 5 % (raised and resampled, deterministically, if a
    sample ever exceeds it).

    Parameters
    ----------
    n : int
        Number of points.
    control : array_like, shape (4, 4, 3), optional
        Control points P_ij; default :func:`bezier_control_net`. The patch must be regular
        (r_u x r_v != 0).
    sampling, noise, noise_model, seed
        As in :func:`sphere`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    net = bezier_control_net() if control is None else np.asarray(control, dtype=np.float64)
    if net.shape != (4, 4, 3) or not np.all(np.isfinite(net)):
        raise ParameterError(f"control must be a finite (4, 4, 3) array, got shape {net.shape}")
    rng = np.random.default_rng(seed)
    lo, hi = (0.0, 0.0), (1.0, 1.0)
    propose = _uniform_box(lo, hi)

    def weight(p):
        ru_, rv_ = _bezier_derivatives(net, p[:, 0], p[:, 1], ((1, 0), (0, 1)))
        return np.linalg.norm(_cross(ru_, rv_), axis=1)

    if sampling == "parameter":
        uv = propose(rng, n)
    else:
        uv = _rejection_sample(rng, n, propose, weight, _grid_max(weight, lo, hi))
    u, v = uv[:, 0], uv[:, 1]
    clean, *derivs = _bezier_derivatives(net, u, v,
                                         ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)))
    clean = np.ascontiguousarray(clean)
    # (u, v) is roughly unit-speed up to the factor 3, so spacings are measured in (u, v).
    interior = _square_interior(uv, 0.0, 1.0, n)
    params = {"control": net.tolist(), "sampling": sampling}
    return _finish("bezier", params, rng, uv, clean, derivs, False, interior, noise, noise_model,
                   seed)

