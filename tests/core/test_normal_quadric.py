"""The normal-constrained quadric: exact on quadrics at any size, safe on degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from curvature import synthetic
from curvature.fitting.normal_field import MODEL_FIELD, MODEL_QUADRIC, nfr_anchor_fits
from curvature.fitting.normal_quadric import (
    N_QUAD,
    curvature_from_quadric,
    regress_normal_quadric,
)
from curvature.status import Status


def fit_at(points, normals, p, k, query=None):
    """Fit around point ``p`` over its k nearest neighbors; curvature at ``query`` (default p)."""
    _, idx = cKDTree(points).query(points[p], k + 1)
    nbr = np.asarray([i for i in idx if i != p][:k], np.int64)
    quad = np.empty(N_QUAD)
    st, h, misfit, dist = regress_normal_quadric(points, normals, p, nbr, True, quad)
    q = p if query is None else query
    d = (points[q] - points[p]) / h
    cst, k1, k2, n, d1, d2 = curvature_from_quadric(quad, h, d, 4.0)
    return st, cst, misfit, dist, k1, k2, n, d1


# Quadric surfaces with exact normals: the model holds exactly, at any neighborhood size,
# including the ellipsoid's tips where the normal turns by more than a radian.
EXACT = [
    ("sphere", {"radius": 2.0}), ("cylinder", {}), ("ellipsoid", {"axes": (3, 2, 1)}),
]


@pytest.mark.parametrize("shape, kwargs", EXACT, ids=[s for s, _ in EXACT])
@pytest.mark.parametrize("k", [24, 384, 1500])
def test_exact_on_quadrics_at_any_size(shape, kwargs, k):
    cloud = synthetic.make(shape, 6000, seed=1, **kwargs)
    # the points of largest k1 (the ellipsoid's tips) and a few others
    for p in [int(np.argmax(cloud.k1)), 0, 17, 2024]:
        st, cst, misfit, dist, k1, k2, n, d1 = fit_at(cloud.points, cloud.normals, p, k)
        assert st == Status.OK and cst == Status.OK
        assert misfit < 1e-10 and dist < 1e-6
        np.testing.assert_allclose([k1, k2], [cloud.k1[p], cloud.k2[p]], rtol=1e-7, atol=1e-7)
        assert np.dot(n, cloud.normals[p]) > 1 - 1e-12


def test_read_at_another_points_foot_point():
    cloud = synthetic.ellipsoid(6000, axes=(3, 2, 1), seed=2)
    p = 100
    _, idx = cKDTree(cloud.points).query(cloud.points[p], 10)
    for q in idx[1:]:
        st, cst, _, _, k1, k2, n, _ = fit_at(cloud.points, cloud.normals, p, 200, query=q)
        np.testing.assert_allclose([k1, k2], [cloud.k1[q], cloud.k2[q]], rtol=1e-7)
        assert np.dot(n, cloud.normals[q]) > 1 - 1e-12


def test_sign_follows_the_centre_normal_and_neighbor_signs_do_not_matter():
    cloud = synthetic.sphere(3000, seed=3)
    flipped = cloud.normals * np.where(np.arange(3000) % 2 == 0, 1.0, -1.0)[:, None]
    out = fit_at(cloud.points, flipped, 0, 100)
    np.testing.assert_allclose(out[4:6], [1.0, 1.0], rtol=1e-7)
    inward = fit_at(cloud.points, -cloud.normals, 0, 100)
    np.testing.assert_allclose(inward[4:6], [-1.0, -1.0], rtol=1e-7)
    assert np.dot(inward[6], cloud.normals[0]) < -0.999


def test_rotation_and_translation_invariance():
    cloud = synthetic.torus(5000, noise=0.2, seed=4)
    normals = synthetic.torus(5000, seed=4).normals
    q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))
    base = fit_at(cloud.points, normals, 7, 200)
    moved = fit_at(cloud.points @ q.T + np.array([40.0, -3.0, 9.0]), normals @ q.T, 7, 200)
    np.testing.assert_allclose(moved[4:6], base[4:6], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(moved[6], base[6] @ q.T, atol=1e-8)


def test_plane_has_zero_curvature_and_few_or_unknown_normals_fail_cleanly():
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.random((500, 2)), np.zeros(500)])
    normals = np.tile([0.0, 0.0, 1.0], (500, 1))
    st, cst, misfit, _, k1, k2, n, _ = fit_at(pts, normals, 0, 100)
    assert st == Status.OK and cst == Status.OK
    assert abs(k1) < 1e-9 and abs(k2) < 1e-9 and abs(n[2]) > 1 - 1e-12
    quad = np.empty(N_QUAD)
    assert regress_normal_quadric(pts, normals, 0, np.arange(1, 8), True, quad)[0] == \
        Status.TOO_FEW_NEIGHBORS
    unknown = normals.copy()
    unknown[1:] = np.nan
    assert regress_normal_quadric(pts, unknown, 0, np.arange(1, 100), True, quad)[0] == \
        Status.TOO_FEW_NEIGHBORS
    unknown[0] = np.nan
    assert regress_normal_quadric(pts, unknown, 0, np.arange(1, 100), True, quad)[0] == \
        Status.DEGENERATE_FIT
    # all points in one spot: no scale
    same = np.zeros((50, 3))
    assert regress_normal_quadric(same, normals[:50], 0, np.arange(1, 50), True, quad)[0] == \
        Status.DEGENERATE_FIT


def anchor_models(cloud, k, nfr_ratio):
    """Model kept at 300 anchors of ``cloud`` (exact normals) and their status."""
    pts = cloud.points
    anchors = np.arange(0, len(pts), len(pts) // 300, dtype=np.int64)[:300]
    _, idx = cKDTree(pts).query(pts[anchors], k + 1)
    nbr = idx[:, 1:].astype(np.int32)
    a = anchors.shape[0]
    outs = dict(coef=np.empty((a, 2, 10)), scale=np.empty(a), frame=np.empty((a, 3, 3)),
                quad=np.empty((a, N_QUAD)), quad_scale=np.empty(a), model=np.empty(a, np.int8),
                residual=np.empty(a), status=np.empty(a, np.int8))
    nfr_anchor_fits(pts, cloud.normals, anchors, np.arange(0, (a + 1) * k, k, dtype=np.int64),
                    nbr.ravel(), nfr_ratio, *outs.values())
    return outs["model"], outs["status"]


def test_anchors_keep_the_quadric_on_quadrics_and_the_field_on_a_torus():
    ellipsoid = synthetic.ellipsoid(10_000, axes=(3, 2, 1), seed=6)
    model, status = anchor_models(ellipsoid, 384, 0.7)
    assert np.all(status == Status.OK) and np.all(model == MODEL_QUADRIC)
    # a torus is no quadric at 384 points (about a radian of its tube): the field fits better
    torus = synthetic.torus(10_000, seed=6)
    model, status = anchor_models(torus, 384, 0.7)
    assert np.all(status == Status.OK) and np.mean(model == MODEL_FIELD) > 0.9
    # the ratio's extremes force one model, except that an exact quadric fit is always kept
    assert np.all(anchor_models(torus, 384, 0.0)[0] == MODEL_QUADRIC)
    assert np.all(anchor_models(ellipsoid, 384, 1e6)[0] == MODEL_QUADRIC)
    noisy = synthetic.ellipsoid(10_000, axes=(3, 2, 1), noise=0.2, seed=6)
    noisy.normals[:] = ellipsoid.normals  # noisy positions, exact normals: no exact fit
    assert np.all(anchor_models(noisy, 384, 1e6)[0] == MODEL_FIELD)
