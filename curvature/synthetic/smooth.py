"""Analytic test shapes with exact normals, principal curvatures and principal directions.

Every shape is a parametric surface r(u, v). Points are sampled either uniformly with respect
to surface area (``sampling="area"``) or uniformly in the parameters (``sampling="parameter"``),
and the exact differential geometry is computed at every sample from the analytic derivatives
r_u, r_v, r_uu, r_uv, r_vv by one shared routine (:func:`surface_geometry`), so all shapes use
the same code path. Optional Gaussian noise, with standard deviation given in percent of the
bounding-box diagonal (BBD) of the clean cloud, is added afterwards (DESIGN.md section 8).

Sign convention (DESIGN.md section 3): a curvature is positive where the surface bends away
from the oriented normal, so a sphere with outward normals has k1 = k2 = +1/r; k1 >= k2
(signed order). All normals returned here point outward (closed shapes) or have a positive
z component (height-field-like shapes: plane, saddle, Bezier patch).

Examples
--------
>>> from curvature import synthetic
>>> cloud = synthetic.torus(10_000, noise=0.25, seed=1)
>>> cloud.points.shape, cloud.k1.shape
((10000, 3), (10000,))

Command line::

    curvature synthetic torus --n 10000 --noise 0.25 --noise-model direction \
        --seed 1 -o torus.ply
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ParameterError

__all__ = [
    "BEZIER_DEFAULT_HEIGHTS",
    "SHAPES",
    "SyntheticCloud",
    "bezier_control_net",
    "bezier_patch",
    "blade",
    "cylinder",
    "ellipsoid",
    "filleted_box",
    "filleted_cylinder",
    "main",
    "make",
    "plane",
    "saddle",
    "sphere",
    "surface_geometry",
    "thin_plate",
    "torus",
]

SAMPLINGS = ("area", "parameter")
NOISE_MODELS = ("axis", "direction", "view")
#: Direction of the ``"view"`` noise model: a scanner's range noise acts along its line of sight,
#: here one fixed direction (an orthographic scanner looking down and sideways).
VIEW_DIRECTION = (0.36, -0.48, -0.8)

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

# Rejection sampling proposes this many extra candidates above the expected need.
_OVERSAMPLE = 1.1


# --------------------------------------------------------------------------------------------
# Result container
# --------------------------------------------------------------------------------------------


@dataclass
class SyntheticCloud:
    """A sampled analytic surface with exact differential geometry.

    Attributes
    ----------
    points : ndarray, shape (n, 3), float64
        Sample points, with noise when ``noise > 0`` (else equal to ``clean``).
    clean : ndarray, shape (n, 3), float64
        Noise-free points, exactly on the surface.
    normals : ndarray, shape (n, 3), float64
        Exact unit normals at ``clean``: outward for closed shapes and the cylinder, positive z
        component for the plane, saddle and Bezier patch.
    k1, k2 : ndarray, shape (n,), float64
        Exact principal curvatures at ``clean``, ``k1 >= k2``, positive where the surface bends
        away from ``normals`` (DESIGN.md section 3).
    dir1, dir2 : ndarray, shape (n, 3), float64
        Exact unit principal directions for ``k1`` and ``k2``; ``(dir1, dir2, normals)`` is a
        right-handed orthonormal frame. NaN at umbilic points (``k1 == k2`` up to rounding),
        where every tangent direction is principal: everywhere on the sphere and the plane, and
        at the four umbilics of a triaxial ellipsoid (a set of measure zero).
    uv : ndarray, shape (n, 2), float64
        Surface parameters of each point (see each shape's docstring for their meaning).
    interior : ndarray, shape (n,), bool
        True for points at least ``max(5 % of the parameter range, 2 mean point spacings)``
        from the border of an open surface; all True for closed surfaces.
    name : str
        Shape name (a key of :data:`SHAPES`).
    params : dict
        Shape parameters (e.g. ``{"major": 2.0, "minor": 1.0}``) plus ``"sampling"``.
    noise : float
        Noise level in percent of the BBD of ``clean``.
    noise_model : str
        ``"axis"`` (independent N(0, s^2) on x, y and z), ``"direction"`` (a random unit
        direction times one N(0, s^2) length) or ``"view"`` (one N(0, s^2) length along the
        fixed :data:`VIEW_DIRECTION`, like a scanner's range noise).
    noise_sigma : float
        The absolute standard deviation ``s = noise / 100 * BBD(clean)``.
    seed : int or None
        Seed passed to :func:`numpy.random.default_rng`.
    region : ndarray, shape (n,), int8, or None
        Part shapes (:mod:`curvature.synthetic.parts`): index into ``region_names`` of every
        point's region (face, fillet, corner, edge zone, outlier ...); None for smooth shapes.
    region_names : tuple of str
        Names of the region codes.
    feature_distance : ndarray, shape (n,), or None
        Part shapes: geodesic distance of each clean point to the nearest line where the exact
        curvature jumps (a face meeting a fillet); inf where there is none.
    """

    points: np.ndarray
    clean: np.ndarray
    normals: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    dir1: np.ndarray
    dir2: np.ndarray
    uv: np.ndarray
    interior: np.ndarray
    name: str
    params: dict[str, Any] = field(default_factory=dict)
    noise: float = 0.0
    noise_model: str = "axis"
    noise_sigma: float = 0.0
    seed: int | None = 0
    region: np.ndarray | None = None
    region_names: tuple = ()
    feature_distance: np.ndarray | None = None

    def region_mask(self, name: str) -> np.ndarray:
        """Points of region ``name``, shape (n,) bool (all False for an unknown name)."""
        if self.region is None or name not in self.region_names:
            return np.zeros(len(self), bool)
        return self.region == self.region_names.index(name)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def mean(self) -> np.ndarray:
        """Exact mean curvature H = (k1 + k2) / 2, shape (n,)."""
        return 0.5 * (self.k1 + self.k2)

    @property
    def gaussian(self) -> np.ndarray:
        """Exact Gaussian curvature K = k1 * k2, shape (n,)."""
        return self.k1 * self.k2

    @property
    def bbd(self) -> float:
        """Bounding-box diagonal of the clean cloud."""
        return _bbd(self.clean)

    def to_point_cloud(self):
        """Return a :class:`curvature.PointCloud` with the (noisy) points and exact normals."""
        from ..cloud import PointCloud

        return PointCloud(points=self.points, normals=self.normals)


# --------------------------------------------------------------------------------------------
# Shared differential geometry
# --------------------------------------------------------------------------------------------


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (n, 3) arrays, shape (n,)."""
    return np.einsum("ij,ij->i", a, b)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (faster than np.cross for tall arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def surface_geometry(ru, rv, ruu, ruv, rvv, *, flip=False):
    """Exact normals, principal curvatures and directions from parametric derivatives.

    With N = r_u x r_v / |r_u x r_v| (negated when ``flip``), the first and second fundamental
    forms are I = [[E, F], [F, G]] = [[r_u.r_u, r_u.r_v], [r_u.r_v, r_v.r_v]] and
    II = [[e, f], [f, g]] = [[r_uu.N, r_uv.N], [r_uv.N, r_vv.N]] (do Carmo, *Differential
    Geometry of Curves and Surfaces*, 1976, sections 2-5 and 3-3). The principal curvatures in
    do Carmo's convention are the eigenvalues of the Weingarten matrix I^-1 II; this library's
    convention (DESIGN.md section 3: positive where the surface bends away from N) is their
    negative, k = -eig(I^-1 II), which gives +1/r on a sphere with outward normals.

    Rather than solving the quadratic k^2 - 2Hk + K = 0 (which loses accuracy near umbilics),
    the shape operator is written in the orthonormal tangent frame t1 = r_u / |r_u|,
    t2 = N x t1. With J = [[|r_u|, r_v.t1], [0, r_v.t2]] (the columns are r_u and r_v in that
    frame, so I = J^T J), the shape operator there is the symmetric matrix
    S = -J^-T II J^-1, whose eigenvalues are the principal curvatures and whose eigenvectors are
    the principal directions (Rodrigues: dN(w) = k w for a principal direction w, in this sign
    convention). For a symmetric 2x2 matrix [[a, b], [b, c]] the eigenvalues are
    (a + c)/2 +- sqrt(((a - c)/2)^2 + b^2) and the larger one's eigenvector makes the angle
    theta = atan2(2b, a - c) / 2 with t1.

    Parameters
    ----------
    ru, rv : array_like, shape (n, 3)
        First partial derivatives of r(u, v).
    ruu, ruv, rvv : array_like, shape (n, 3)
        Second partial derivatives of r(u, v).
    flip : bool, optional
        Use -r_u x r_v as the normal (the parametrisation has the wrong handedness).

    Returns
    -------
    normals : ndarray, shape (n, 3)
        Unit normals.
    k1, k2 : ndarray, shape (n,)
        Principal curvatures, ``k1 >= k2``.
    dir1, dir2 : ndarray, shape (n, 3)
        Unit principal directions, ``dir2 = normals x dir1``; NaN at umbilics, i.e. where
        ``k1 - k2 <= 1e-9 * (|k1| + |k2|)`` (including flat points with k1 = k2 = 0).
    """
    ru, rv, ruu, ruv, rvv = (np.asarray(a, dtype=np.float64) for a in (ru, rv, ruu, ruv, rvv))
    cross = _cross(ru, rv)
    area = np.linalg.norm(cross, axis=1)
    normals = cross / area[:, None]
    if flip:
        normals = -normals
    # Second fundamental form coefficients (do Carmo 3-3, eq. (3)).
    e = _dot(ruu, normals)
    f = _dot(ruv, normals)
    g = _dot(rvv, normals)
    # Orthonormal tangent frame and the upper-triangular J with I = J^T J.
    len_u = np.linalg.norm(ru, axis=1)
    t1 = ru / len_u[:, None]
    t2 = _cross(normals, t1)
    j11 = len_u
    j12 = _dot(rv, t1)
    j22 = _dot(rv, t2)  # = +-|r_u x r_v| / |r_u|, nonzero on a regular surface
    # J^-1 = [[1/j11, -j12/(j11 j22)], [0, 1/j22]];  S = -J^-T II J^-1 (symmetric).
    i11 = 1.0 / j11
    i12 = -j12 / (j11 * j22)
    i22 = 1.0 / j22
    a = -(e * i11 * i11)
    b = -(i11 * (e * i12 + f * i22))
    c = -(e * i12 * i12 + 2.0 * f * i12 * i22 + g * i22 * i22)
    half_sum = 0.5 * (a + c)
    radius = np.hypot(0.5 * (a - c), b)
    k1 = half_sum + radius
    k2 = half_sum - radius
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    dir1 = np.cos(theta)[:, None] * t1 + np.sin(theta)[:, None] * t2
    dir2 = _cross(normals, dir1)
    umbilic = (k1 - k2) <= 1e-9 * (np.abs(k1) + np.abs(k2))
    dir1[umbilic] = np.nan
    dir2[umbilic] = np.nan
    return normals, k1, k2, dir1, dir2


# --------------------------------------------------------------------------------------------
# Sampling and noise helpers
# --------------------------------------------------------------------------------------------


def _check_common(n, sampling, noise, noise_model):
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ParameterError(f"n must be a positive integer, got {n!r}")
    if sampling not in SAMPLINGS:
        raise ParameterError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
    if noise_model not in NOISE_MODELS:
        raise ParameterError(f"noise_model must be one of {NOISE_MODELS}, got {noise_model!r}")
    if not np.isfinite(noise) or noise < 0:
        raise ParameterError(f"noise must be a finite percentage >= 0, got {noise!r}")
    return int(n)


def _check_positive(name, value):
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ParameterError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def _rejection_sample(rng, n, propose, weight, wmax):
    """Draw ``n`` parameter samples with density proportional to ``weight``.

    Candidates from ``propose(rng, m) -> (m, 2)`` (uniform in the parameter domain) are kept
    with probability ``weight(uv) / wmax``; batches are drawn until ``n`` are kept, so the
    work is vectorized over the batch. The batch size comes from the acceptance rate measured
    on a pilot batch drawn from a fixed private generator (the caller's generator is not
    touched by it). If a candidate's weight exceeds ``wmax`` (a bound that may have been
    estimated on a grid), the bound is raised and sampling restarts from the same generator
    state, so the result stays a deterministic function of the seed.
    """
    pilot = propose(np.random.default_rng(20240917), 4096)
    state = rng.bit_generator.state
    while True:
        rate = max(float(np.mean(weight(pilot))) / wmax, 1e-3)
        kept = []
        count = 0
        exceeded = 0.0
        while count < n:
            m = int(np.ceil((n - count) / rate * _OVERSAMPLE)) + 64
            uv = propose(rng, m)
            w = weight(uv)
            exceeded = max(exceeded, float(w.max()))
            keep = rng.random(m) * wmax < w
            kept.append(uv[keep])
            count += int(keep.sum())
        if exceeded <= wmax:
            return np.concatenate(kept)[:n]
        wmax = exceeded * 1.05
        rng.bit_generator.state = state


def _uniform_box(lo, hi):
    """A proposal ``(rng, m) -> (m, 2)`` uniform on the box [lo[0], hi[0]] x [lo[1], hi[1]]."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)

    def propose(rng, m):
        return lo + (hi - lo) * rng.random((m, 2))

    return propose


def _grid_max(weight, lo, hi, steps=129):
    """Maximum of ``weight`` on a regular grid over the box, with a 5 % safety margin."""
    su = np.linspace(lo[0], hi[0], steps)
    sv = np.linspace(lo[1], hi[1], steps)
    uu, vv = np.meshgrid(su, sv, indexing="ij")
    return 1.05 * float(weight(np.column_stack([uu.ravel(), vv.ravel()])).max())


def _bbd(points: np.ndarray) -> float:
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _add_noise(rng, clean, noise, noise_model):
    """Return ``(points, sigma)`` with sigma = noise % of the BBD of ``clean``."""
    sigma = noise / 100.0 * _bbd(clean)
    if sigma == 0.0:
        return clean.copy(), 0.0
    n = clean.shape[0]
    if noise_model == "axis":
        disp = rng.normal(0.0, sigma, size=(n, 3))
    elif noise_model == "view":
        view = np.asarray(VIEW_DIRECTION) / np.linalg.norm(VIEW_DIRECTION)
        disp = rng.normal(0.0, sigma, size=n)[:, None] * view
    else:
        d = rng.normal(size=(n, 3))
        norm = np.linalg.norm(d, axis=1)
        norm[norm == 0.0] = 1.0  # probability zero; keeps the result finite
        disp = d / norm[:, None] * rng.normal(0.0, sigma, size=n)[:, None]
    return clean + disp, sigma


def _border_margin(extent, area, n):
    """Distance from the border (in parameter units along ``extent``) of the interior mask.

    ``max(5 % of extent, 2 mean spacings)``; the mean spacing is estimated as sqrt(area / n),
    which assumes the parameter has roughly unit speed (true for the shapes here up to a
    factor of ~2).
    """
    return max(0.05 * extent, 2.0 * np.sqrt(area / n))


def _finish(name, params, rng, uv, clean, derivs, flip, interior, noise, noise_model, seed):
    normals, k1, k2, dir1, dir2 = surface_geometry(*derivs, flip=flip)
    points, sigma = _add_noise(rng, clean, noise, noise_model)
    return SyntheticCloud(
        points=points,
        clean=clean,
        normals=normals,
        k1=k1,
        k2=k2,
        dir1=dir1,
        dir2=dir2,
        uv=uv,
        interior=interior,
        name=name,
        params=params,
        noise=float(noise),
        noise_model=noise_model,
        noise_sigma=sigma,
        seed=seed,
    )


# --------------------------------------------------------------------------------------------
# Shapes
# --------------------------------------------------------------------------------------------


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


def _square_interior(uv, lo, hi, n):
    extent = hi - lo
    margin = _border_margin(extent, extent * extent, n)
    return np.all((uv >= lo + margin) & (uv <= hi - margin), axis=1)


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


#: Shape name -> sampling function.
SHAPES: dict[str, Callable[..., SyntheticCloud]] = {
    "sphere": sphere,
    "ellipsoid": ellipsoid,
    "cylinder": cylinder,
    "plane": plane,
    "saddle": saddle,
    "torus": torus,
    "bezier": bezier_patch,
}


# Part shapes live in their own module, which needs the helpers above.
from .parts import PART_SHAPES  # noqa: E402

SHAPES.update(PART_SHAPES)
blade, filleted_box, filleted_cylinder, thin_plate = (
    PART_SHAPES[k] for k in ("blade", "filleted_box", "filleted_cylinder", "thin_plate"))


def make(name, n=10000, **kwargs):
    """Sample the shape called ``name`` (a key of :data:`SHAPES`).

    Parameters
    ----------
    name : str
        Shape name; ``"bezier_patch"`` is accepted as an alias of ``"bezier"``.
    n : int
        Number of points.
    **kwargs
        Passed to the shape function (e.g. ``noise=0.25, seed=3, major=3.0``).

    Returns
    -------
    SyntheticCloud
    """
    key = "bezier" if name == "bezier_patch" else name
    try:
        fn = SHAPES[key]
    except KeyError:
        raise ParameterError(
            f"unknown shape {name!r}; known shapes: {', '.join(sorted(SHAPES))}"
        ) from None
    return fn(n, **kwargs)


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    """``curvature synthetic SHAPE --n N --noise PCT ... -o OUT``.

    Writes the (noisy) points and exact normals with :func:`curvature.write`; an ``.npy``
    output holds only the (n, 3) points, saved with :func:`numpy.save`.
    """
    parser = argparse.ArgumentParser(
        prog="curvature synthetic",
        description="Sample an analytic test shape (exact curvature known) and write it.",
    )
    parser.add_argument("shape", choices=sorted(SHAPES), help="shape to sample")
    parser.add_argument("--n", type=int, default=10000, help="number of points (10000)")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="noise std in percent of the bounding-box diagonal (0)")
    parser.add_argument("--noise-model", choices=NOISE_MODELS, default="axis",
                        help="per-axis Gaussian, or random direction times Gaussian (axis)")
    parser.add_argument("--sampling", choices=SAMPLINGS, default="area",
                        help="area-uniform or parameter-uniform sampling (area; part shapes "
                             "are always area-uniform)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    parser.add_argument("-o", "--output", required=True,
                        help="output file (.ply, .csv, .npz, ...; .npy saves the points only)")
    args = parser.parse_args(argv)
    try:
        options = {} if args.shape in PART_SHAPES else {"sampling": args.sampling}
        cloud = make(args.shape, args.n, noise=args.noise, noise_model=args.noise_model,
                     seed=args.seed, **options)
        if str(args.output).lower().endswith(".npy"):
            np.save(args.output, cloud.points)
        else:
            import curvature

            curvature.write(args.output, cloud.to_point_cloud())
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(cloud)} points ({cloud.name}, noise {cloud.noise}% BBD = "
          f"{cloud.noise_sigma:.6g}, {cloud.noise_model}) to {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
