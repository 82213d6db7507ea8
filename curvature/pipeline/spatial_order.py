"""Space-filling-curve order of a cloud, for memory locality.

Neighbor searches and fits read the coordinates of nearby points; when consecutive points are
also near in space those reads hit the cache. Scans and random samples often arrive in an order
unrelated to space, which makes large clouds several times slower.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..bounds import bounding_box

BITS = 21  # per axis: 3 * 21 = 63 bits fit an unsigned 64-bit key


@njit(cache=True, inline="always")
def _spread_bits(v):
    """Insert two zero bits between each of the low 21 bits of ``v`` (uint64)."""
    v = v & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


@njit(parallel=True, cache=True)
def morton_keys(points, lo, scale):
    """Z-order key of every point, shape (n,), uint64: each coordinate quantized to 21 bits
    as ``uint64((x - lo) * scale)``, the bits interleaved x, y, z from the lowest."""
    n = points.shape[0]
    key = np.empty(n, np.uint64)
    for i in prange(n):
        qx = np.uint64((points[i, 0] - lo[0]) * scale)
        qy = np.uint64((points[i, 1] - lo[1]) * scale)
        qz = np.uint64((points[i, 2] - lo[2]) * scale)
        key[i] = _spread_bits(qx) | (_spread_bits(qy) << np.uint64(1)) \
            | (_spread_bits(qz) << np.uint64(2))
    return key


def morton_order(points: np.ndarray) -> np.ndarray:
    """Permutation that sorts points along a Morton (Z-order) curve.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64

    Returns
    -------
    ndarray, shape (n,), int64
        ``points[order]`` is in Z-order; equal keys keep their input order (stable sort).
    """
    lo, hi = bounding_box(points)
    span = float(np.max(hi - lo))
    if not span > 0.0:
        return np.arange(points.shape[0], dtype=np.int64)
    key = morton_keys(points, lo, (2**BITS - 1) / span)
    return np.argsort(key, kind="stable").astype(np.int64)


def inverse_permutation(order: np.ndarray) -> np.ndarray:
    """``inv`` with ``inv[order] = arange(n)``, shape (n,), int64."""
    inv = np.empty_like(order)
    inv[order] = np.arange(order.shape[0], dtype=order.dtype)
    return inv


@njit(parallel=True, cache=True)
def _take_scalars(src, idx, out):
    for i in prange(idx.shape[0]):
        out[i] = src[idx[i]]


@njit(parallel=True, cache=True)
def _take_vectors(src, idx, out):
    for i in prange(idx.shape[0]):
        for d in range(3):
            out[i, d] = src[idx[i], d]


def take_rows(src: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``src[idx]`` along the first axis; float64 fields (n,) and (n, 3), most of a result's
    bytes, on every numba thread (numpy's gather runs on one: a 1M-point result's return to
    input order took 0.25 s).

    Parameters
    ----------
    src : ndarray, shape (n,) or (n, c)
    idx : ndarray, shape (m,), int64

    Returns
    -------
    ndarray, shape (m,) or (m, c)
    """
    if src.dtype == np.float64 and src.flags.c_contiguous and (
            src.ndim == 1 or (src.ndim == 2 and src.shape[1] == 3)):
        out = np.empty((idx.shape[0],) + src.shape[1:])
        (_take_scalars if src.ndim == 1 else _take_vectors)(src, idx, out)
        return out
    return src[idx]
