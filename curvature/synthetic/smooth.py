"""Smooth analytic shapes: sphere, ellipsoid, cylinder, plane, saddle and torus.

Each is a parametric surface r(u, v) whose exact geometry comes from
:func:`~curvature.synthetic.base.surface_geometry`; conventions in :mod:`curvature.synthetic`.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .base import (
    _border_margin,
    _check_common,
    _check_positive,
    _finish,
    _rejection_sample,
    _square_interior,
    _uniform_box,
)


def _ellipsoid_parts(theta, phi, a, b, c):
    """Points and derivatives of r(theta, phi) = (a sin t cos p, b sin t sin p, c cos t).

    theta is the polar angle from +z, phi the azimuth; r_theta x r_phi points outward.
    """
    st, ct = np.sin(theta), np.cos(theta)
    sp, cp = np.sin(phi), np.cos(phi)
    zero = np.zeros_like(theta)
    clean = np.column_stack([a * st * cp, b * st * sp, c * ct])
    ru = np.column_stack([a * ct * cp, b * ct * sp, -c * st])
    rv = np.column_stack([-a * st * sp, b * st * cp, zero])
    ruu = -clean
    ruv = np.column_stack([-a * ct * sp, b * ct * cp, zero])
    rvv = np.column_stack([-a * st * cp, -b * st * sp, zero])
    return clean, (ru, rv, ruu, ruv, rvv)


def _ellipsoid_like(name, params, n, a, b, c, sampling, noise, noise_model, seed):
    rng = np.random.default_rng(seed)
    if sampling == "parameter":
        theta = np.pi * rng.random(n)
        phi = 2.0 * np.pi * rng.random(n)
    elif a == b == c:
        # Archimedes: z is uniform on [-r, r] for area-uniform points on a sphere.
        z = rng.uniform(-1.0, 1.0, n)
        phi = 2.0 * np.pi * rng.random(n)
        theta = np.arccos(z)
    else:
        # Uniform points s on the unit sphere mapped by A = diag(a, b, c): the area scale of a
        # linear map at a surface point with unit normal s is |det A| |A^-T s|
        # = abc sqrt(sx^2/a^2 + sy^2/b^2 + sz^2/c^2), at most abc / min(a, b, c); accept with
        # probability min(a, b, c) sqrt(...) <= 1 (exact rejection sampling).
        inv2 = np.array([1.0 / a**2, 1.0 / b**2, 1.0 / c**2])
        lo = min(a, b, c)

        def propose(rng_, m):
            return np.column_stack([rng_.uniform(-1.0, 1.0, m), 2.0 * np.pi * rng_.random(m)])

        def weight(zp):
            z, p = zp[:, 0], zp[:, 1]
            s2 = 1.0 - z * z
            return lo * np.sqrt(s2 * np.cos(p) ** 2 * inv2[0] + s2 * np.sin(p) ** 2 * inv2[1]
                                + z * z * inv2[2])

        zp = _rejection_sample(rng, n, propose, weight, 1.0)
        theta = np.arccos(zp[:, 0])
        phi = zp[:, 1]
    clean, derivs = _ellipsoid_parts(theta, phi, a, b, c)
    uv = np.column_stack([theta, phi])
    interior = np.ones(n, dtype=bool)
    return _finish(name, params, rng, uv, clean, derivs, False, interior, noise, noise_model,
                   seed)


def sphere(n=10000, radius=1.0, *, sampling="area", noise=0.0, noise_model="axis", seed=0):
    """Sphere of the given radius centred at the origin.

    Parametrisation r(theta, phi) = radius (sin t cos p, sin t sin p, cos t); ``uv`` holds
    (theta in [0, pi], phi in [0, 2 pi)). Exact values: k1 = k2 = 1/radius with outward
    normals; ``dir1``/``dir2`` are NaN (every point is umbilic). Area-uniform sampling uses
    Archimedes' theorem (z uniform).

    Parameters
    ----------
    n : int
        Number of points.
    radius : float
        Sphere radius (> 0).
    sampling : {"area", "parameter"}
        Area-uniform points, or uniform in (theta, phi) (denser at the poles).
    noise : float
        Noise std in percent of the bounding-box diagonal of the clean cloud.
    noise_model : {"axis", "direction"}
        Per-axis N(0, s^2), or a random unit direction times N(0, s^2).
    seed : int or None
        Seed for :func:`numpy.random.default_rng`.

    Returns
    -------
    SyntheticCloud
        With arrays of shape (n, 3) and (n,) as documented there.
    """
    n = _check_common(n, sampling, noise, noise_model)
    r = _check_positive("radius", radius)
    params = {"radius": r, "sampling": sampling}
    return _ellipsoid_like("sphere", params, n, r, r, r, sampling, noise, noise_model, seed)


def ellipsoid(n=10000, axes=(3.0, 2.0, 1.0), *, sampling="area", noise=0.0, noise_model="axis",
              seed=0):
    """Ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 with semi-axes ``axes = (a, b, c)``.

    Parametrisation r(theta, phi) = (a sin t cos p, b sin t sin p, c cos t); ``uv`` holds
    (theta in [0, pi], phi in [0, 2 pi)). Normals are outward, so k1 >= k2 > 0; the Gaussian
    curvature is K = 1 / (a^2 b^2 c^2 (x^2/a^4 + y^2/b^4 + z^2/c^4)^2). Area-uniform sampling
    is exact (uniform sphere points mapped by diag(a, b, c), thinned by the area ratio).

    Parameters
    ----------
    n : int
        Number of points.
    axes : tuple of 3 floats
        Semi-axes (a, b, c) along x, y, z (> 0).
    sampling, noise, noise_model, seed
        As in :func:`sphere`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    if len(axes) != 3:
        raise ParameterError(f"axes must have 3 entries, got {axes!r}")
    a, b, c = (_check_positive("axes", x) for x in axes)
    params = {"axes": (a, b, c), "sampling": sampling}
    return _ellipsoid_like("ellipsoid", params, n, a, b, c, sampling, noise, noise_model, seed)


def cylinder(n=10000, radius=1.0, height=4.0, *, sampling="area", noise=0.0, noise_model="axis",
             seed=0):
    """Open circular cylinder (side surface only) around the z axis, z in [-h/2, h/2].

    Parametrisation r(u, v) = (radius cos u, radius sin u, v); ``uv`` holds (u in [0, 2 pi),
    v = z). Exact values with outward normals: k1 = 1/radius (dir1 around the circle),
    k2 = 0 (dir2 along the axis). Parameter sampling is already area-uniform here.
    ``interior`` excludes points near the two rims.

    Parameters
    ----------
    n : int
        Number of points.
    radius, height : float
        Cylinder radius and length (> 0).
    sampling, noise, noise_model, seed
        As in :func:`sphere`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    r = _check_positive("radius", radius)
    h = _check_positive("height", height)
    rng = np.random.default_rng(seed)
    u = 2.0 * np.pi * rng.random(n)
    v = rng.uniform(-0.5 * h, 0.5 * h, n)
    cu, su = np.cos(u), np.sin(u)
    zero = np.zeros(n)
    one = np.ones(n)
    clean = np.column_stack([r * cu, r * su, v])
    ru = np.column_stack([-r * su, r * cu, zero])
    rv = np.column_stack([zero, zero, one])
    ruu = np.column_stack([-r * cu, -r * su, zero])
    rzero = np.zeros((n, 3))
    margin = _border_margin(h, 2.0 * np.pi * r * h, n)
    interior = np.abs(v) <= 0.5 * h - margin
    params = {"radius": r, "height": h, "sampling": sampling}
    return _finish("cylinder", params, rng, np.column_stack([u, v]), clean,
                   (ru, rv, ruu, rzero, rzero), False, interior, noise, noise_model, seed)


def plane(n=10000, size=2.0, *, sampling="area", noise=0.0, noise_model="axis", seed=0):
    """Flat square z = 0 over [-size/2, size/2]^2 with normal +z.

    ``uv`` = (x, y). Exact values: k1 = k2 = 0; ``dir1``/``dir2`` are NaN (flat = umbilic).

    Parameters
    ----------
    n : int
        Number of points.
    size : float
        Side length of the square (> 0).
    sampling, noise, noise_model, seed
        As in :func:`sphere` (both samplings coincide for the plane).

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    s = _check_positive("size", size)
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-0.5 * s, 0.5 * s, (n, 2))
    clean = np.column_stack([uv, np.zeros(n)])
    ru = np.tile([1.0, 0.0, 0.0], (n, 1))
    rv = np.tile([0.0, 1.0, 0.0], (n, 1))
    rzero = np.zeros((n, 3))
    interior = _square_interior(uv, -0.5 * s, 0.5 * s, n)
    params = {"size": s, "sampling": sampling}
    return _finish("plane", params, rng, uv, clean, (ru, rv, rzero, rzero, rzero), False,
                   interior, noise, noise_model, seed)


def saddle(n=10000, size=2.0, *, sampling="area", noise=0.0, noise_model="axis", seed=0):
    """Hyperbolic paraboloid z = (x^2 - y^2) / 2 over the square [-size/2, size/2]^2.

    ``uv`` = (x, y); normals have a positive z component, (-x, y, 1) / sqrt(1 + x^2 + y^2).
    At the origin k1 = +1 (along y, bending down away from the normal) and k2 = -1 (along x).
    Area-uniform sampling rejects on the area element sqrt(1 + x^2 + y^2).

    Parameters
    ----------
    n : int
        Number of points.
    size : float
        Side length of the square (> 0).
    sampling, noise, noise_model, seed
        As in :func:`sphere`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    s = _check_positive("size", size)
    rng = np.random.default_rng(seed)
    lo, hi = (-0.5 * s, -0.5 * s), (0.5 * s, 0.5 * s)
    propose = _uniform_box(lo, hi)
    if sampling == "parameter":
        uv = propose(rng, n)
    else:

        def weight(p):
            return np.sqrt(1.0 + p[:, 0] ** 2 + p[:, 1] ** 2)

        wmax = float(np.sqrt(1.0 + 0.5 * s * s))  # attained at the corners
        uv = _rejection_sample(rng, n, propose, weight, wmax)
    x, y = uv[:, 0], uv[:, 1]
    zero = np.zeros(n)
    one = np.ones(n)
    clean = np.column_stack([x, y, 0.5 * (x * x - y * y)])
    ru = np.column_stack([one, zero, x])
    rv = np.column_stack([zero, one, -y])
    ruu = np.tile([0.0, 0.0, 1.0], (n, 1))
    rvv = np.tile([0.0, 0.0, -1.0], (n, 1))
    interior = _square_interior(uv, -0.5 * s, 0.5 * s, n)
    params = {"size": s, "sampling": sampling}
    return _finish("saddle", params, rng, uv, clean, (ru, rv, ruu, np.zeros((n, 3)), rvv), False,
                   interior, noise, noise_model, seed)


def torus(n=10000, major=2.0, minor=1.0, *, sampling="area", noise=0.0, noise_model="axis",
          seed=0):
    """Ring torus around the z axis with major radius R and tube radius r (R > r).

    Parametrisation r(u, v) = ((R + r cos v) cos u, (R + r cos v) sin u, r sin v); ``uv`` holds
    (u in [0, 2 pi) around the z axis, v in [0, 2 pi) around the tube; v = 0 on the outer
    equator). With outward normals (DESIGN.md section 3): k1 = 1/r (dir1 around the tube),
    k2 = cos v / (R + r cos v) (dir2 along the u circles). Area-uniform sampling is exact
    rejection on the area element r (R + r cos v), bounded by r (R + r).

    Parameters
    ----------
    n : int
        Number of points.
    major, minor : float
        R and r, with R > r > 0.
    sampling, noise, noise_model, seed
        As in :func:`sphere`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_common(n, sampling, noise, noise_model)
    big = _check_positive("major", major)
    small = _check_positive("minor", minor)
    if not big > small:
        raise ParameterError(f"major ({big}) must exceed minor ({small}) for a ring torus")
    rng = np.random.default_rng(seed)
    propose = _uniform_box((0.0, 0.0), (2.0 * np.pi, 2.0 * np.pi))
    if sampling == "parameter":
        uv = propose(rng, n)
    else:

        def weight(p):
            return big + small * np.cos(p[:, 1])

        uv = _rejection_sample(rng, n, propose, weight, big + small)
    u, v = uv[:, 0], uv[:, 1]
    cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
    w = big + small * cv
    zero = np.zeros(n)
    clean = np.column_stack([w * cu, w * su, small * sv])
    ru = np.column_stack([-w * su, w * cu, zero])
    rv = np.column_stack([-small * sv * cu, -small * sv * su, small * cv])
    ruu = np.column_stack([-w * cu, -w * su, zero])
    ruv = np.column_stack([small * sv * su, -small * sv * cu, zero])
    rvv = np.column_stack([-small * cv * cu, -small * cv * su, -small * sv])
    params = {"major": big, "minor": small, "sampling": sampling}
    return _finish("torus", params, rng, uv, clean, (ru, rv, ruu, ruv, rvv), False,
                   np.ones(n, dtype=bool), noise, noise_model, seed)

