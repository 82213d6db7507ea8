"""What every synthetic shape family shares: the sampled cloud (:class:`SyntheticCloud`), exact
differential geometry from parametric derivatives (:func:`surface_geometry`), sampling, noise
and parameter checks. Conventions in :mod:`curvature.synthetic`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ParameterError

SAMPLINGS = ("area", "parameter")
NOISE_MODELS = ("axis", "direction", "view")
#: Direction of the ``"view"`` noise model: a scanner's range noise acts along its line of sight,
#: here one fixed direction (an orthographic scanner looking down and sideways).
VIEW_DIRECTION = (0.36, -0.48, -0.8)

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


def _square_interior(uv, lo, hi, n):
    extent = hi - lo
    margin = _border_margin(extent, extent * extent, n)
    return np.all((uv >= lo + margin) & (uv <= hi - margin), axis=1)

