"""Machined-part test shapes with exact curvature: flat faces, fillets, corners, thin walls.

Real inspection parts are not smooth synthetic surfaces: flat faces meet along fillets of a few
point spacings, walls are thin, leading edges small. Each shape here is built from pieces whose
curvature is known exactly (planes, cylinders, spheres, tori), joined with tangent continuity,
so the curvature jumps at the joints while normals stay continuous:

* :func:`filleted_box`: a box with every edge rounded by radius ``fillet`` (faces, quarter
  cylinders along the edges, sphere octants at the corners);
* :func:`filleted_cylinder`: a cylinder whose end faces meet the side through fillets (torus
  sections), optionally with a step (a shoulder with a convex and a concave fillet);
* :func:`blade`: an extruded blade profile, thick near a small leading-edge radius and thin
  towards a tiny trailing-edge radius, where both sides are a few spacings apart;
* :func:`thin_plate`: an extruded stadium, two flat faces ``thickness`` apart with half-round
  rims.

Every point gets a region label (``region`` indexes ``region_names``) and the geodesic distance
to the nearest curvature jump (``feature_distance``). Points closer to a jump than
``edge_zone`` mean spacings (spacing = sqrt(area / n)) form the region ``"edge_zone"``: there the
exact curvature changes within less than any fit's neighborhood, so errors are reported apart.
Noise as in :mod:`curvature.synthetic` (``"axis"``, ``"direction"`` or ``"view"``, the last a
scanner's range noise along one direction), and ``outliers``: that share of the points replaced by
points drawn uniformly in the bounding box grown by 10 %, with NaN curvature and region
``"outlier"``.

Normals point outward; principal directions are NaN where k1 == k2 (flat faces, sphere corners).
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .base import SyntheticCloud, _add_noise, _check_common, _check_positive, _cross
from .profiles import Profile, filleted_polygon

__all__ = ["PART_SHAPES", "blade", "filleted_box", "filleted_cylinder", "thin_plate"]

#: Default width of the edge zone, in mean point spacings.
EDGE_ZONE = 2.0


def _principal(normals, ka, da, kb, db):
    """Order two principal curvatures with their directions: k1 >= k2, dir2 = n x dir1.

    Parameters
    ----------
    normals : ndarray, shape (n, 3)
    ka, kb : ndarray, shape (n,)
    da, db : ndarray, shape (n, 3)
        Unit directions of ``ka`` and ``kb``.

    Returns
    -------
    k1, k2 : ndarray, shape (n,)
    dir1, dir2 : ndarray, shape (n, 3)
        NaN at umbilics (k1 == k2, e.g. flat points).
    """
    swap = kb > ka
    k1 = np.where(swap, kb, ka)
    k2 = np.where(swap, ka, kb)
    dir1 = np.where(swap[:, None], db, da)
    dir2 = _cross(normals, dir1)
    umbilic = (k1 - k2) <= 1e-9 * (np.abs(k1) + np.abs(k2))
    dir1[umbilic] = np.nan
    dir2[umbilic] = np.nan
    return k1, k2, dir1, dir2


def _allocate(rng, n: int, areas) -> np.ndarray:
    """Points per piece, multinomial in the pieces' areas, shape (pieces,)."""
    areas = np.asarray(areas, np.float64)
    return rng.multinomial(n, areas / areas.sum())


def _check_part(n, noise, noise_model, outliers, edge_zone):
    n = _check_common(n, "area", noise, noise_model)
    if not np.isfinite(outliers) or not 0.0 <= outliers < 1.0:
        raise ParameterError(f"outliers must be a share in [0, 1), got {outliers!r}")
    if not np.isfinite(edge_zone) or edge_zone < 0.0:
        raise ParameterError(f"edge_zone must be a number of spacings >= 0, got {edge_zone!r}")
    return n


def _finish_part(name, params, rng, geometry, labels, names, area, *, noise, noise_model,
                 outliers, edge_zone, seed):
    """Noise, outliers and regions for a sampled part; returns a SyntheticCloud.

    ``geometry`` is (clean, normals, k1, k2, dir1, dir2, uv, interior, feature_distance);
    ``labels`` the (n,) index of every point's region in ``names``.
    """
    clean, normals, k1, k2, dir1, dir2, uv, interior, fdist = geometry
    n = clean.shape[0]
    spacing = float(np.sqrt(area / n))
    names = tuple(names) + ("edge_zone", "outlier")
    region = np.asarray(labels, np.int8).copy()
    region[fdist < edge_zone * spacing] = names.index("edge_zone")
    points, sigma = _add_noise(rng, clean, noise, noise_model)
    count = int(round(outliers * n))
    if count:
        lo, hi = clean.min(axis=0), clean.max(axis=0)
        grow = 0.1 * (hi - lo)
        rows = rng.choice(n, size=count, replace=False)
        points[rows] = rng.uniform(lo - grow, hi + grow, size=(count, 3))
        region[rows] = names.index("outlier")
        for arr in (k1, k2):
            arr[rows] = np.nan
        interior = interior.copy()
        interior[rows] = False
    params = dict(params, sampling="area", spacing=spacing, edge_zone=edge_zone,
                  outliers=float(outliers))
    return SyntheticCloud(points=points, clean=clean, normals=normals, k1=k1, k2=k2, dir1=dir1,
                          dir2=dir2, uv=uv, interior=interior, name=name, params=params,
                          noise=float(noise), noise_model=noise_model, noise_sigma=sigma,
                          seed=seed, region=region, region_names=names,
                          feature_distance=fdist)


# --------------------------------------------------------------------------------------------
# Filleted box
# --------------------------------------------------------------------------------------------


def _box_faces(rng, counts, half, r):
    """Flat faces of the rounded box: the inner box's faces pushed out by the fillet.

    Each box piece is returned as (points, normals, principal directions or None, distance to
    the nearest curvature jump).
    """
    out = []
    for f, m in enumerate(counts):
        axis, sign = divmod(f, 2)
        sign = 1.0 if sign else -1.0
        j, k = [a for a in range(3) if a != axis]
        x = np.zeros((m, 3))
        x[:, axis] = sign * (half[axis] + r)
        x[:, j] = rng.uniform(-half[j], half[j], m)
        x[:, k] = rng.uniform(-half[k], half[k], m)
        nrm = np.zeros((m, 3))
        nrm[:, axis] = sign
        dist = np.minimum(half[j] - np.abs(x[:, j]), half[k] - np.abs(x[:, k]))
        out.append((x, nrm, None, dist))
    return out


def _box_fillets(rng, counts, half, r):
    """Quarter cylinders along the 12 edges: k = 1/r around, 0 along the edge."""
    out = []
    for e, m in enumerate(counts):
        axis, signs = divmod(e, 4)
        j, k = [a for a in range(3) if a != axis]
        sj = 1.0 if signs & 1 else -1.0
        sk = 1.0 if signs & 2 else -1.0
        t = rng.uniform(-half[axis], half[axis], m)
        alpha = rng.uniform(0.0, np.pi / 2.0, m)
        nrm = np.zeros((m, 3))
        nrm[:, j] = sj * np.cos(alpha)
        nrm[:, k] = sk * np.sin(alpha)
        base = np.zeros((m, 3))
        base[:, axis] = t
        base[:, j] = sj * half[j]
        base[:, k] = sk * half[k]
        around = np.zeros((m, 3))
        around[:, j] = -sj * np.sin(alpha)
        around[:, k] = sk * np.cos(alpha)
        along = np.zeros((m, 3))
        along[:, axis] = 1.0
        dist = np.minimum(np.minimum(alpha, np.pi / 2.0 - alpha) * r, half[axis] - np.abs(t))
        out.append((base + r * nrm, nrm, (around, along), dist))
    return out


def _box_corners(rng, counts, half, r):
    """Sphere octants at the 8 corners: k1 = k2 = 1/r."""
    out = []
    for c, m in enumerate(counts):
        signs = np.array([1.0 if c & (1 << a) else -1.0 for a in range(3)])
        u = np.abs(rng.normal(size=(m, 3)))
        u /= np.linalg.norm(u, axis=1)[:, None]
        nrm = u * signs
        dist = r * np.arcsin(np.clip(u.min(axis=1), 0.0, 1.0))
        out.append((signs * half + r * nrm, nrm, None, dist))
    return out


def filleted_box(n=12000, size=(2.0, 1.5, 1.0), fillet=0.2, *, noise=0.0, noise_model="axis",
                 outliers=0.0, edge_zone=EDGE_ZONE, seed=0) -> SyntheticCloud:
    """A box with all edges and corners rounded by radius ``fillet``, centred at the origin.

    Regions: ``"face"`` (k1 = k2 = 0), ``"fillet"`` (k1 = 1/fillet, k2 = 0), ``"corner"``
    (k1 = k2 = 1/fillet), ``"edge_zone"``, ``"outlier"``. With the defaults the mean spacing is
    about 0.031, so the fillet radius is about 6.5 spacings.

    Parameters
    ----------
    n : int
        Points.
    size : tuple of 3 float
        Full extents along x, y, z (each more than ``2 * fillet``).
    fillet : float
        Radius of the edge fillets and corner spheres.
    noise, noise_model, seed
        As for :func:`curvature.synthetic.sphere`; ``noise_model`` also takes ``"view"``.
    outliers : float
        Share of the points replaced by uniform outliers.
    edge_zone : float
        Width of the edge zone in mean spacings.

    Returns
    -------
    SyntheticCloud
        ``uv`` holds (piece index, 0): pieces 0-5 faces, 6-17 fillets, 18-25 corners.
    """
    n = _check_part(n, noise, noise_model, outliers, edge_zone)
    r = _check_positive("fillet", fillet)
    size = np.asarray(size, np.float64)
    if size.shape != (3,) or not np.all(np.isfinite(size)) or np.any(size <= 2.0 * r):
        raise ParameterError(f"size must be 3 extents each above 2 * fillet, got {size!r}")
    half = size / 2.0 - r
    face_area = [4.0 * half[j] * half[k] for f in range(6)
                 for j, k in [[a for a in range(3) if a != f // 2]]]
    fillet_area = [2.0 * half[e // 4] * np.pi * r / 2.0 for e in range(12)]
    corner_area = [np.pi * r * r / 2.0] * 8
    areas = face_area + fillet_area + corner_area
    rng = np.random.default_rng(seed)
    counts = _allocate(rng, n, areas)
    pieces = (_box_faces(rng, counts[:6], half, r) + _box_fillets(rng, counts[6:18], half, r)
              + _box_corners(rng, counts[18:], half, r))
    clean, normals, k1, k2, dir1, dir2, fdist, labels, piece = ([] for _ in range(9))
    inv = 1.0 / r
    for index, (x, nrm, dirs, dist) in enumerate(pieces):
        m = x.shape[0]
        if index < 6:
            kk = (np.zeros(m), np.zeros(m), np.full((m, 3), np.nan), np.full((m, 3), np.nan))
            label = 0
        elif index < 18:
            kk = _principal(nrm, np.full(m, inv), dirs[0], np.zeros(m), dirs[1])
            label = 1
        else:
            kk = (np.full(m, inv), np.full(m, inv), np.full((m, 3), np.nan),
                  np.full((m, 3), np.nan))
            label = 2
        clean.append(x)
        normals.append(nrm)
        for store, value in zip((k1, k2, dir1, dir2), kk, strict=True):
            store.append(value)
        fdist.append(dist)
        labels.append(np.full(m, label))
        piece.append(np.full(m, index))
    cat = np.concatenate
    uv = np.column_stack([cat(piece).astype(np.float64), np.zeros(n)])
    geometry = (cat(clean), cat(normals), cat(k1), cat(k2), cat(dir1), cat(dir2), uv,
                np.ones(n, bool), cat(fdist))
    params = {"size": tuple(float(s) for s in size), "fillet": r}
    return _finish_part("filleted_box", params, rng, geometry, cat(labels),
                        ("face", "fillet", "corner"), float(np.sum(areas)), noise=noise,
                        noise_model=noise_model, outliers=outliers, edge_zone=edge_zone,
                        seed=seed)


# --------------------------------------------------------------------------------------------
# Extrusions
# --------------------------------------------------------------------------------------------


def _extrude(name, params, profile: Profile, height, n, *, noise, noise_model, outliers,
             edge_zone, seed) -> SyntheticCloud:
    """Sample ``profile`` (closed, CCW in x-y) extruded along z over [0, height].

    The surface is open at z = 0 and z = height; ``interior`` excludes points within
    max(5 % of the height, 2 spacings) of those borders.
    """
    rng = np.random.default_rng(seed)
    length = profile.length
    s = rng.uniform(0.0, length, n)
    z = rng.uniform(0.0, height, n)
    p2, t2, n2, kappa, seg, joint = profile.evaluate(s)
    clean = np.column_stack([p2, z])
    normals = np.column_stack([n2, np.zeros(n)])
    tangent = np.column_stack([t2, np.zeros(n)])
    along = np.tile([0.0, 0.0, 1.0], (n, 1))
    k1, k2, dir1, dir2 = _principal(normals, kappa, tangent, np.zeros(n), along)
    area = length * height
    margin = max(0.05 * height, 2.0 * np.sqrt(area / n))
    interior = (z > margin) & (z < height - margin)
    names = profile.labels
    labels = np.array([names.index(seg_.label) for seg_ in profile.segments])[seg]
    geometry = (clean, normals, k1, k2, dir1, dir2, np.column_stack([s, z]), interior, joint)
    return _finish_part(name, params, rng, geometry, labels, names, area, noise=noise,
                        noise_model=noise_model, outliers=outliers, edge_zone=edge_zone,
                        seed=seed)


def blade(n=20000, chord=2.0, thickness=0.3, leading_radius=0.05, trailing_radius=0.01,
          crest_radius=1.0, crest=0.3, height=1.0, *, noise=0.0, noise_model="axis",
          outliers=0.0, edge_zone=EDGE_ZONE, seed=0) -> SyntheticCloud:
    """An extruded blade: a four-sided profile with filleted corners, extruded along z.

    The profile runs from the leading edge (x = 0) to the trailing edge (x = ``chord``), is
    ``thickness`` thick at ``x = crest * chord`` and tapers to the trailing edge, so near it
    both sides are a few spacings apart (a thin wall). Regions: ``"side"`` (flat),
    ``"crest"`` (convex fillets of ``crest_radius``), ``"leading_edge"``, ``"trailing_edge"``,
    ``"edge_zone"``, ``"outlier"``. Defaults: mean spacing about 0.014, leading-edge radius
    about 3.5 spacings, the sides 2 spacings apart 0.13 from the trailing edge.

    Parameters
    ----------
    n : int
    chord, thickness, height : float
        Profile length, largest thickness, extrusion height.
    leading_radius, trailing_radius, crest_radius : float
        Fillet radii of the profile's corners.
    crest : float
        Position of the thickest section as a share of the chord, in (0, 1).
    noise, noise_model, outliers, edge_zone, seed
        As for :func:`filleted_box`.

    Returns
    -------
    SyntheticCloud
        ``uv`` = (arc length along the profile from the leading edge's lower side, z).
    """
    n = _check_part(n, noise, noise_model, outliers, edge_zone)
    chord, thickness, height = (_check_positive(k, v) for k, v in
                                (("chord", chord), ("thickness", thickness), ("height", height)))
    radii = [_check_positive(k, v) for k, v in (("leading_radius", leading_radius),
                                                 ("crest_radius", crest_radius),
                                                 ("trailing_radius", trailing_radius))]
    if not 0.0 < crest < 1.0:
        raise ParameterError(f"crest must lie in (0, 1), got {crest!r}")
    h = thickness / 2.0
    vertices = [(0.0, 0.0), (crest * chord, -h), (chord, 0.0), (crest * chord, h)]
    profile = filleted_polygon(vertices, [radii[0], radii[1], radii[2], radii[1]],
                               ["side"] * 4,
                               ["leading_edge", "crest", "trailing_edge", "crest"])
    params = {"chord": chord, "thickness": thickness, "leading_radius": radii[0],
              "trailing_radius": radii[2], "crest_radius": radii[1], "crest": float(crest),
              "height": height}
    return _extrude("blade", params, profile, height, n, noise=noise, noise_model=noise_model,
                    outliers=outliers, edge_zone=edge_zone, seed=seed)


def thin_plate(n=20000, width=2.0, thickness=0.06, height=1.0, *, noise=0.0,
               noise_model="axis", outliers=0.0, edge_zone=EDGE_ZONE,
               seed=0) -> SyntheticCloud:
    """A thin wall: two flat faces ``thickness`` apart joined by half-round rims, extruded.

    Regions ``"face"``, ``"rim"`` (k1 = 2 / thickness), ``"edge_zone"``, ``"outlier"``. With
    the defaults the faces are about 4 mean spacings apart.

    Parameters
    ----------
    n : int
    width, thickness, height : float
        Extent along x (rim to rim), wall thickness (y), extrusion height (z).
    noise, noise_model, outliers, edge_zone, seed
        As for :func:`filleted_box`.

    Returns
    -------
    SyntheticCloud
    """
    n = _check_part(n, noise, noise_model, outliers, edge_zone)
    width, thickness, height = (_check_positive(k, v) for k, v in
                                (("width", width), ("thickness", thickness), ("height", height)))
    if width <= thickness:
        raise ParameterError("width must exceed thickness")
    h = thickness / 2.0
    vertices = [(0.0, -h), (width, -h), (width, h), (0.0, h)]
    profile = filleted_polygon(vertices, [h] * 4, ["face"] * 4, ["rim"] * 4)
    params = {"width": width, "thickness": thickness, "height": height}
    return _extrude("thin_plate", params, profile, height, n, noise=noise,
                    noise_model=noise_model, outliers=outliers, edge_zone=edge_zone, seed=seed)


# --------------------------------------------------------------------------------------------
# Revolutions
# --------------------------------------------------------------------------------------------


def _revolve(name, params, profile: Profile, n, *, noise, noise_model, outliers, edge_zone,
             seed) -> SyntheticCloud:
    """Sample an open (rho, z) ``profile`` revolved about the z axis, area-uniformly.

    Meridian curvature is the profile's; the parallel's is ``n_rho / rho`` (Meusnier).
    """
    rng = np.random.default_rng(seed)
    length = profile.length
    grid = np.linspace(0.0, length, 4097)
    rho_max = float(profile.evaluate(grid)[0][:, 0].max()) * 1.001
    kept = []
    count = 0
    while count < n:  # rejection on rho: the area element is rho ds dphi
        s = rng.uniform(0.0, length, 2 * (n - count) + 64)
        rho = profile.evaluate(s)[0][:, 0]
        s = s[rng.uniform(0.0, rho_max, s.size) < rho]
        kept.append(s)
        count += s.size
    s = np.concatenate(kept)[:n]
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    p2, t2, n2, kappa, seg, joint = profile.evaluate(s)
    c, sn = np.cos(phi), np.sin(phi)
    rho, z = p2[:, 0], p2[:, 1]
    clean = np.column_stack([rho * c, rho * sn, z])
    normals = np.column_stack([n2[:, 0] * c, n2[:, 0] * sn, n2[:, 1]])
    meridian = np.column_stack([t2[:, 0] * c, t2[:, 0] * sn, t2[:, 1]])
    parallel = np.column_stack([-sn, c, np.zeros(n)])
    k_par = np.divide(n2[:, 0], rho, out=np.zeros(n), where=rho > 1e-12)
    k1, k2, dir1, dir2 = _principal(normals, kappa, meridian, k_par, parallel)
    # Area: integral of 2 pi rho ds, by the trapezoid rule on a fine grid.
    rho_grid = profile.evaluate(grid)[0][:, 0]
    area = float(2.0 * np.pi * np.sum(0.5 * (rho_grid[1:] + rho_grid[:-1]) * np.diff(grid)))
    names = profile.labels
    labels = np.array([names.index(seg_.label) for seg_ in profile.segments])[seg]
    geometry = (clean, normals, k1, k2, dir1, dir2, np.column_stack([s, phi]),
                np.ones(n, bool), joint)
    return _finish_part(name, params, rng, geometry, labels, names, area, noise=noise,
                        noise_model=noise_model, outliers=outliers, edge_zone=edge_zone,
                        seed=seed)


def filleted_cylinder(n=20000, radius=1.0, height=2.0, fillet=0.15, step=None, *, noise=0.0,
                      noise_model="axis", outliers=0.0, edge_zone=EDGE_ZONE,
                      seed=0) -> SyntheticCloud:
    """A closed cylinder (axis z, from z = 0 to ``height``) with filleted end faces.

    With ``step=(radius2, z_step)`` the cylinder narrows to ``radius2`` above ``z_step``
    through a flat shoulder, with a convex fillet at its outer edge and a concave one (negative
    k) where it meets the narrow part. Regions: ``"cap"``, ``"side"``, ``"shoulder"`` (with a
    step), ``"fillet"`` (convex, torus sections), ``"inner_fillet"`` (concave), ``"edge_zone"``,
    ``"outlier"``.

    Parameters
    ----------
    n : int
    radius, height, fillet : float
    step : tuple of 2 float, optional
        ``(radius2, z_step)`` with ``fillet < radius2 < radius - 2 fillet`` and the step at
        least two fillets from either end.
    noise, noise_model, outliers, edge_zone, seed
        As for :func:`filleted_box`.

    Returns
    -------
    SyntheticCloud
        ``uv`` = (arc length along the meridian from the bottom centre, azimuth).
    """
    n = _check_part(n, noise, noise_model, outliers, edge_zone)
    radius, height, r = (_check_positive(k, v) for k, v in
                         (("radius", radius), ("height", height), ("fillet", fillet)))
    if step is None:
        if not (2.0 * r < height and r < radius):
            raise ParameterError("fillet must be below radius and half the height")
        vertices = [(0.0, 0.0), (radius, 0.0), (radius, height), (0.0, height)]
        profile = filleted_polygon(vertices, [0.0, r, r, 0.0], ["cap", "side", "cap"],
                                   ["", "fillet", "fillet", ""], closed=False)
        params = {"radius": radius, "height": height, "fillet": r, "step": None}
    else:
        radius2, z_step = (float(v) for v in step)
        if not (r < radius2 < radius - 2.0 * r and 2.0 * r <= z_step <= height - 2.0 * r):
            raise ParameterError(f"step {step!r} does not fit the cylinder and fillet")
        vertices = [(0.0, 0.0), (radius, 0.0), (radius, z_step), (radius2, z_step),
                    (radius2, height), (0.0, height)]
        profile = filleted_polygon(vertices, [0.0, r, r, r, r, 0.0],
                                   ["cap", "side", "shoulder", "side", "cap"],
                                   ["", "fillet", "fillet", "inner_fillet", "fillet", ""],
                                   closed=False)
        params = {"radius": radius, "height": height, "fillet": r,
                  "step": (radius2, z_step)}
    return _revolve("filleted_cylinder", params, profile, n, noise=noise,
                    noise_model=noise_model, outliers=outliers, edge_zone=edge_zone, seed=seed)


#: Part shapes by name (also reachable through :func:`curvature.synthetic.make`).
PART_SHAPES = {
    "filleted_box": filleted_box,
    "filleted_cylinder": filleted_cylinder,
    "blade": blade,
    "thin_plate": thin_plate,
}
