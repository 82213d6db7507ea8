"""Faces beside rounded thin edges fitted without the edge (curvature.estimators.beside_edges)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import curvature
from curvature import synthetic
from curvature.estimators import auto, beside_edges


def _bent_wall(n=20000, seed=1, noise=0.1, inner=1.0, thickness=0.06, half_angle=0.6):
    """A thin wall bent round the z axis (faces of radius ``inner`` and ``inner +
    thickness``, from angle ``-half_angle`` to ``half_angle``) whose two ends are half-round
    rims, extruded over z in [0, 1]; noise per axis in % of the bounding box diagonal.

    Returns points (n, 3), exact outward normals (n, 3), the curvature across the wall (n,;
    the curvature along z is 0) and each point's part (0 outer face, 1 and 3 rims, 2 inner
    face).
    """
    rng = np.random.default_rng(seed)
    outer, rim, middle = inner + thickness, thickness / 2, inner + thickness / 2
    lengths = np.array([outer, 0.0, inner, 0.0]) * 2 * half_angle + np.array([0, 1, 0, 1]) * (
        np.pi * rim)
    part = rng.choice(4, size=n, p=lengths / lengths.sum())
    s, z = rng.random(n), rng.random(n)
    xy, nrm, k = np.empty((n, 2)), np.empty((n, 2)), np.empty(n)
    for p, radius, sign in ((0, outer, 1.0), (2, inner, -1.0)):
        m = part == p
        a = half_angle * (2 * s[m] - 1)
        xy[m] = radius * np.c_[np.cos(a), np.sin(a)]
        nrm[m] = sign * np.c_[np.cos(a), np.sin(a)]
        k[m] = sign / radius
    for p, end in ((1, 1.0), (3, -1.0)):
        m = part == p
        radial = np.array([np.cos(end * half_angle), np.sin(end * half_angle)])
        tangent = end * np.array([-radial[1], radial[0]])
        b = np.pi * (s[m] - 0.5)
        nrm[m] = np.outer(np.cos(b), tangent) + np.outer(np.sin(b), radial)
        xy[m] = middle * radial + rim * nrm[m]
        k[m] = 1.0 / rim
    points = np.c_[xy, z]
    diagonal = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    points = points + rng.normal(scale=noise / 100 * diagonal, size=points.shape)
    return points, np.c_[nrm, np.zeros(n)], k, part


def _junction_arc(points, part, inner=1.0, thickness=0.06, half_angle=0.6):
    """Each point's distance along the surface from the nearest junction of a rim and a
    face of :func:`_bent_wall` (n,), from its noisy position."""
    rim, middle = thickness / 2, inner + thickness / 2
    out = np.full(points.shape[0], np.inf)
    for p, end in ((1, 1.0), (3, -1.0)):
        m = part == p
        radial = np.array([np.cos(end * half_angle), np.sin(end * half_angle)])
        tangent = end * np.array([-radial[1], radial[0]])
        v = points[m, :2] - middle * radial
        turn = np.clip(np.arctan2(v @ tangent, v @ radial), 0.0, np.pi)
        out[m] = rim * np.minimum(turn, np.pi - turn)
    face = (part == 0) | (part == 2)
    out[face] = np.hypot(points[face, 0], points[face, 1]) * (
        half_angle - np.abs(np.arctan2(points[face, 1], points[face, 0])))
    return out


def _errors(points, normals, k):
    res = curvature.estimate(points, normals=normals)
    return np.fmax(np.abs(res.k1 - np.maximum(k, 0)), np.abs(res.k2 - np.minimum(k, 0))), res


def _without_beside(monkeypatch):
    monkeypatch.setattr(auto.AutoRun, "_beside_edges", lambda self, *args: None)


def test_without_drops_marked_entries_but_each_rows_first():
    indptr = np.array([0, 3, 5, 6], np.int64)
    indices = np.array([4, 1, 2, 1, 3, 2], np.int64)
    drop = np.zeros(5, bool)
    drop[[1, 2]] = True
    out_ptr, out_idx = beside_edges.without(indptr, indices, drop)
    np.testing.assert_array_equal(out_ptr, [0, 1, 3, 4])
    np.testing.assert_array_equal(out_idx, [4, 1, 3, 2])  # rows 2 and 3 keep their own point


def test_the_edge_left_out_is_widened_by_its_end_bands():
    # points on a line 0.01 apart; the edge point at 0, curvature 20 (radius 0.05): the end
    # band's arc is 25 degrees of it, 0.0218, widened twice: 0.0436
    points = np.c_[np.arange(0, 0.1, 0.01), np.zeros(10), np.zeros(10)]
    drop = beside_edges.edge_drop(cKDTree(points), points, np.array([0], np.int64),
                                  np.array([20.0]))
    np.testing.assert_array_equal(np.flatnonzero(drop), [0, 1, 2, 3, 4])


def _curled_sheet():
    """A flat grid (z = 0, x >= 0, spacing 0.01) continued for x < 0 by a curl of radius
    0.03 upwards (z = 0.03 - sqrt(0.03^2 - x^2)); the curl's points are the edge."""
    g = np.arange(-0.029, 0.2, 0.01)
    x, y = np.meshgrid(g, np.arange(0, 0.2, 0.01))
    x, y = x.ravel(), y.ravel()
    z = np.where(x < 0, 0.03 - np.sqrt(np.maximum(0.03 ** 2 - x ** 2, 0)), 0.0)
    return np.c_[x, y, z], x < 0


def test_normals_beside_the_edge_are_read_without_it():
    points, curl = _curled_sheet()
    query = np.flatnonzero((points[:, 0] > 0) & (points[:, 0] < 0.02)
                           & (np.abs(points[:, 1] - 0.1) < 0.05)).astype(np.int64)
    _, nbr = cKDTree(points).query(points[query], 49)
    field = np.full(points.shape, np.nan)
    plain = np.empty((query.size, 3))
    from curvature.fitting.normal_field import pca_normals

    pca_normals(points, query, np.arange(0, 48 * query.size + 1, 48),
                np.ascontiguousarray(nbr[:, 1:]).ravel().astype(np.int64), plain)
    replaced = beside_edges.one_sided_normals(points, query, nbr[:, 1:], curl, field)
    np.testing.assert_array_equal(replaced, query)
    tilt = np.degrees(np.arccos(np.abs(field[query, 2])))
    assert tilt.max() < 0.5 and np.degrees(np.arccos(np.abs(plain[:, 2]))).min() > 2.0


def test_a_fit_reaches_the_edge_where_its_radius_does():
    # anchors at x = 0.051 and 0.171 on the grid, 0.06 and 0.18 from the edge (x < 0);
    # stage-1 radius 0.04 (48 neighbors): a 192-neighbor fit reaches 0.08, a 768-neighbor one
    # 0.16, 1536 0.23
    points, curl = _curled_sheet()
    a = np.flatnonzero(np.isclose(points[:, 0], 0.051) & np.isclose(points[:, 1], 0.1))
    b = np.flatnonzero(np.isclose(points[:, 0], 0.171) & np.isclose(points[:, 1], 0.1))
    anchors = np.r_[a, b].astype(np.int64)
    owner = np.zeros(points.shape[0], np.int64)
    query = np.r_[a, b].astype(np.int64)
    owner[b] = 1
    r_normal = np.full(points.shape[0], 0.04)
    edge = np.flatnonzero(curl).astype(np.int64)
    none = np.empty(0, np.int64)
    own_sizes = np.full(points.shape[0], 48)
    hit = beside_edges.reached(points, query, anchors, owner, np.array([48, 48]), none,
                               own_sizes, r_normal, 48, edge)
    np.testing.assert_array_equal(hit, [False, False])
    hit = beside_edges.reached(points, query, anchors, owner, np.array([192, 768]), none,
                               own_sizes, r_normal, 48, edge)
    np.testing.assert_array_equal(hit, [True, False])
    # a point refitted on its own reads its own size
    own_sizes[b] = 1536
    hit = beside_edges.reached(points, query, anchors, owner, np.array([48, 48]), b,
                               own_sizes, r_normal, 48, edge)
    np.testing.assert_array_equal(hit, [False, True])


def test_the_blades_sides_beside_its_leading_edge_read_flat(monkeypatch):
    # 20,000-point blade at 0.1 % noise (leading edge k = 20): side points 2 to 3 spacings
    # past the edge's curvature jump read 1.74 (seed 1), 0.65 now; their fits held the edge
    # and normals it bent. The sides' mean error over their median was 3.10, 2.61 now (issue
    # 15: at most 3); the one-sided fits, off centre, raise the median by 1.7 %. (Both runs
    # without the last pass's sphere fits, which read many side points afresh.)
    monkeypatch.setattr(auto, "umbilic_pass", lambda *args, **kwargs: 0)
    blade = synthetic.blade(noise=0.1, seed=1)

    def errors():
        res = curvature.estimate(blade.points, normals=blade.normals)
        return np.fmax(np.abs(res.k1 - blade.k1), np.abs(res.k2 - blade.k2))

    worst = errors()
    with monkeypatch.context() as m:
        _without_beside(m)
        before = errors()
    side = blade.region_mask("side") & blade.interior
    beside = side & (blade.points[:, 0] < 0.24)
    assert beside.sum() > 150
    assert worst[beside].mean() < 0.8 and before[beside].mean() > 1.5
    assert worst[side].mean() < 2.8 * np.median(worst[side])
    assert np.median(worst[side]) < 1.04 * np.median(before[side])
    lead = blade.region_mask("leading_edge") & blade.interior
    np.testing.assert_array_equal(worst[lead], before[lead])  # no edge point is refitted


def test_a_bent_walls_faces_beside_its_rims_and_the_rims_themselves(monkeypatch):
    # A wall bent round an axis (faces k = +0.94 and -1, rims k = 33 of 2.6 spacings): the
    # faces within 0.15 of a rim read 2.31 without the refits (seed 1; median 0.66), 0.81
    # with them (median 0.054; 1.62 while the faces left out with the edge were not fitted
    # again). Rim points a spacing or more from a face keep their reads. Within a spacing of
    # a rim's junction with a face (either side) the curvature jumps by 33: there the mean
    # error is 4.6 with the refits and 8.5 without (medians 0.45 and 8.4), though rim points
    # next to a face may read the face's curvature (rim side 2.8 against 2.0).
    points, normals, k, part = _bent_wall()
    inside = (points[:, 2] > 0.05) & (points[:, 2] < 0.95)
    near = np.abs(np.arctan2(points[:, 1], points[:, 0])) > 0.45
    face = inside & near & ((part == 0) | (part == 2))
    rim = inside & ((part == 1) | (part == 3))
    spacing = 0.0115  # (the wall's area over its points, square-rooted)
    junction = inside & (_junction_arc(points, part) < spacing)
    with_refits, _ = _errors(points, normals, k)
    with monkeypatch.context() as m:
        _without_beside(m)
        before, _ = _errors(points, normals, k)
    assert face.sum() > 1000 and (rim & ~junction).sum() > 800 and junction.sum() > 500
    assert with_refits[face].mean() < 0.7 * before[face].mean()
    far = inside & ~near & ((part == 0) | (part == 2))
    np.testing.assert_allclose(with_refits[far].mean(), before[far].mean(), rtol=0.02)
    assert np.nanmax(np.abs(with_refits[rim & ~junction] - before[rim & ~junction])) < 1e-9
    assert with_refits[junction].mean() < 0.95 * before[junction].mean()


@pytest.mark.parametrize("change", ["order", "tiles"])
def test_the_refits_do_not_depend_on_order_or_tiles(change):
    points, normals, k, _ = _bent_wall(n=12000, seed=2)
    res = curvature.estimate(points, normals=normals)
    if change == "order":
        perm = np.random.default_rng(0).permutation(len(points))
        other = curvature.estimate(points[perm], normals=normals[perm])
        np.testing.assert_array_equal(other.k1, res.k1[perm])
        np.testing.assert_array_equal(other.k2_std, res.k2_std[perm])
        return
    other = curvature.estimate(points, normals=normals, tile_points=4000)
    assert other.info["tiles"] > 1
    np.testing.assert_array_equal(other.k1, res.k1)
    np.testing.assert_array_equal(other.k2_std, res.k2_std)
