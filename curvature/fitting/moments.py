"""Quadric design matrices assembled from coordinate moments.

Every entry of the implicit quadric's scatter matrix sum z z' and of Taubin's gradient metric
sum J J' is a sum of monomials of degree <= 4 in the local coordinates. Accumulating the 35
moments once per neighbor and assembling both matrices from index tables costs far less than
forming the 10x10 and 9x9 products per neighbor.
"""

from __future__ import annotations

import numpy as np
from numba import njit

SQRT2 = np.sqrt(2.0)
# Monomial basis of the implicit quadric: x^2, y^2, z^2, sqrt2 xy, sqrt2 yz, sqrt2 xz, x, y, z, 1.
BASIS_EXP = np.array([[2, 0, 0], [0, 2, 0], [0, 0, 2], [1, 1, 0], [0, 1, 1], [1, 0, 1],
                      [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], np.int64)
BASIS_COEF = np.array([1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, 1.0, 1.0, 1.0, 1.0])


def _moment_tables():
    exps = [(a, b, c) for a in range(5) for b in range(5) for c in range(5) if a + b + c <= 4]
    index = -np.ones((5, 5, 5), np.int64)
    for i, e in enumerate(exps):
        index[e] = i
    nb = len(BASIS_EXP)
    # Scatter: (z z')[r, s] = c_r c_s x^(e_r + e_s).
    m_idx = np.empty((nb, nb), np.int64)
    m_coef = np.empty((nb, nb))
    for r in range(nb):
        for s in range(nb):
            m_idx[r, s] = index[tuple(BASIS_EXP[r] + BASIS_EXP[s])]
            m_coef[r, s] = BASIS_COEF[r] * BASIS_COEF[s]
    # Metric: (J J')[r, s] = sum_d c_r c_s e_r[d] e_s[d] x^(e_r + e_s - 2 u_d).
    n_idx = np.zeros((nb - 1, nb - 1, 3), np.int64)
    n_coef = np.zeros((nb - 1, nb - 1, 3))
    for r in range(nb - 1):
        for s in range(nb - 1):
            for d in range(3):
                er, es = BASIS_EXP[r].copy(), BASIS_EXP[s].copy()
                if er[d] == 0 or es[d] == 0:
                    continue
                coef = BASIS_COEF[r] * BASIS_COEF[s] * er[d] * es[d]
                er[d] -= 1
                es[d] -= 1
                n_idx[r, s, d] = index[tuple(er + es)]
                n_coef[r, s, d] = coef
    return np.array(exps, np.int64), index, m_idx, m_coef, n_idx, n_coef


MOMENT_EXP, MOMENT_INDEX, M_IDX, M_COEF, N_IDX, N_COEF = _moment_tables()
N_MOMENTS = MOMENT_EXP.shape[0]


@njit(cache=True)
def moments4(xs):
    """Sums of x^a y^b z^c over points for all a + b + c <= 4, shape (35,), order MOMENT_EXP."""
    mom = np.zeros(N_MOMENTS)
    px = np.empty(5)
    py = np.empty(5)
    pz = np.empty(5)
    exps = MOMENT_EXP
    for i in range(xs.shape[0]):
        px[0] = py[0] = pz[0] = 1.0
        for e in range(1, 5):
            px[e] = px[e - 1] * xs[i, 0]
            py[e] = py[e - 1] * xs[i, 1]
            pz[e] = pz[e - 1] * xs[i, 2]
        for k in range(N_MOMENTS):
            mom[k] += px[exps[k, 0]] * py[exps[k, 1]] * pz[exps[k, 2]]
    return mom


@njit(cache=True)
def scatter_matrix(mom):
    """sum z z' over points for the 10 basis monomials, shape (10, 10)."""
    out = np.empty((10, 10))
    for r in range(10):
        for s in range(10):
            out[r, s] = M_COEF[r, s] * mom[M_IDX[r, s]]
    return out


@njit(cache=True)
def gradient_metric(mom):
    """sum J J' over points for the 9 non-constant monomials (Taubin's metric), shape (9, 9)."""
    out = np.zeros((9, 9))
    for r in range(9):
        for s in range(9):
            acc = 0.0
            for d in range(3):
                acc += N_COEF[r, s, d] * mom[N_IDX[r, s, d]]
            out[r, s] = acc
    return out
