"""A sine wave over the unit square with its exact curvature: a smooth surface whose curvature
changes sign (inflection lines) and whose detail has a chosen size."""

from __future__ import annotations

import numpy as np


def sine_wave(seed, n=10_000, wavelength=0.2, slope=0.1, noise=0.0):
    """z = A sin(2 pi x / wavelength) over the unit square, sampled at random.

    Parameters
    ----------
    seed : int
    n : int
        Points (10,000: a spacing of about 0.01, so ``wavelength`` 0.2 is 20 spacings).
    wavelength, slope : float
        The wave's length and largest slope (A = slope wavelength / 2 pi).
    noise : float
        Gaussian noise per axis, in the square's units.

    Returns
    -------
    points, normals : ndarray, shape (n, 3)
        The (noisy) points and the exact unit normals (upwards) of the points they came from.
    k : ndarray, shape (n,)
        The exact curvature across the crests (the other is 0).
    k_max : float
        The largest |k|.
    inner : ndarray, shape (n,), bool
        Points off the border (the inner 90 % of the square).
    """
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    w = 2.0 * np.pi / wavelength
    amp = slope / w
    z = amp * np.sin(w * xy[:, 0])
    zx = amp * w * np.cos(w * xy[:, 0])
    k = -amp * w * w * np.sin(w * xy[:, 0]) / (1.0 + zx ** 2) ** 1.5
    normals = np.c_[-zx, np.zeros(n), np.ones(n)] / np.sqrt(1.0 + zx ** 2)[:, None]
    inner = (xy.min(axis=1) > 0.05) & (xy.max(axis=1) < 0.95)
    points = np.c_[xy, z] + rng.normal(0.0, noise, (n, 3)) if noise else np.c_[xy, z]
    return points, normals, k, amp * w * w, inner


def wave_errors(res, k):
    """Per point, the larger error of the two principal curvatures (either sign convention:
    the wave's two sides look alike), shape (n,)."""
    a1, a2 = np.minimum(res.k1, res.k2), np.maximum(res.k1, res.k2)
    c1, c2 = np.minimum(k, 0.0), np.maximum(k, 0.0)
    return np.minimum(np.maximum(np.abs(a1 - c1), np.abs(a2 - c2)),
                      np.maximum(np.abs(a2 + c1), np.abs(a1 + c2)))
