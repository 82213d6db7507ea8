"""Invariance, determinism, orientation and status codes of curvature.estimate."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import curvature
from curvature import synthetic


@pytest.fixture(scope="module")
def torus():
    return synthetic.torus(4000, seed=11, noise=0.1)


# The implicit quadric is ill-conditioned on noisy patches (DESIGN.md 4.5): rounding differences
# are amplified there, so its invariance is checked on clean data, Monge's on noisy data.
CASES = [("implicit", 0.0), ("monge", 0.1)]


def cloud_for(noise):
    return synthetic.torus(4000, seed=11, noise=noise)


def same(a, b, rtol=1e-7, atol=1e-9):
    np.testing.assert_array_equal(a.status, b.status)
    for name in ("k1", "k2", "mean", "gaussian"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=rtol, atol=atol)


@pytest.mark.parametrize("fit, noise", CASES)
def test_rotation_and_translation_invariance(fit, noise):
    torus = cloud_for(noise)
    base = curvature.estimate(torus.points, "knn", fit=fit)
    rot = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    moved = torus.points @ rot.T + np.array([1000.0, -250.0, 42.0])
    res = curvature.estimate(moved, "knn", fit=fit)
    same(base, res, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(res.normals, base.normals @ rot.T, atol=1e-6)


@pytest.mark.parametrize("fit, noise", CASES)
def test_scale_divides_curvature(fit, noise):
    torus = cloud_for(noise)
    base = curvature.estimate(torus.points, "knn", fit=fit)
    s = 25.0
    res = curvature.estimate(torus.points * s, "knn", fit=fit)
    np.testing.assert_array_equal(base.status, res.status)
    np.testing.assert_allclose(res.k1 * s, base.k1, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(res.k2 * s, base.k2, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(res.residual / s, base.residual, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("fit, noise", CASES)
def test_point_order_invariance(fit, noise):
    torus = cloud_for(noise)
    base = curvature.estimate(torus.points, "knn", fit=fit)
    perm = np.random.default_rng(3).permutation(len(torus.points))
    res = curvature.estimate(torus.points[perm], "knn", fit=fit)
    np.testing.assert_array_equal(res.status, base.status[perm])
    np.testing.assert_allclose(res.k1, base.k1[perm], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.k2, base.k2[perm], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.normals, base.normals[perm], atol=1e-12)


def test_identical_for_any_workers_and_chunking(torus):
    ref = curvature.estimate(torus.points, "knn", workers=1)
    for workers, chunk in [(2, 32768), (1, 333), (2, 1000)]:
        res = curvature.estimate(torus.points, "knn", workers=workers, chunk_size=chunk)
        for name, arr in ref.fields().items():
            np.testing.assert_array_equal(getattr(res, name), arr, err_msg=name)


@pytest.mark.parametrize("shape", ["sphere", "ellipsoid", "torus"])
def test_auto_orientation_points_outward(shape):
    cloud = synthetic.make(shape, 20000, seed=12)
    res = curvature.estimate(cloud.points, "knn", fit="monge")
    outward = np.einsum("ij,ij->i", res.normals, cloud.normals) > 0
    assert outward.mean() >= 0.999
    assert res.info["orientation"] == "auto"


def test_sign_convention_sphere_and_flip():
    cloud = synthetic.sphere(3000, radius=4.0, seed=13)
    res = curvature.estimate(cloud.points, "knn", normals=cloud.normals)
    assert np.allclose(res.k1, 0.25, rtol=1e-3) and np.allclose(res.k2, 0.25, rtol=1e-3)
    inward = curvature.estimate(cloud.points, "knn", normals=-cloud.normals)
    np.testing.assert_allclose(inward.k1, -res.k2, rtol=1e-12)
    np.testing.assert_allclose(inward.k2, -res.k1, rtol=1e-12)
    np.testing.assert_allclose(inward.gaussian, res.gaussian, rtol=1e-12)
    assert np.all(inward.k1 >= inward.k2)


def test_viewpoint_orientation_faces_scanner():
    cloud = synthetic.plane(2000, seed=14)
    res = curvature.estimate(cloud.points, "knn", viewpoint=[0.0, 0.0, -10.0])
    assert res.info["orientation"] == "viewpoint"
    assert np.all(res.normals[:, 2] < 0)


def test_degenerate_points_get_status_not_exception():
    rng = np.random.default_rng(5)
    cloud = synthetic.sphere(500, seed=15).points
    # A far-away cluster of identical points and a collinear row: no surface to fit.
    dup = np.tile([[50.0, 50.0, 50.0]], (30, 1))
    line = np.c_[np.linspace(0, 1, 30), np.zeros(30), np.zeros(30)] + [-50.0, 0, 0]
    pts = np.vstack([cloud, dup, line + rng.normal(scale=0, size=line.shape)])
    for fit in ("implicit", "monge"):
        res = curvature.estimate(pts, "knn", fit=fit, k=10)
        bad = res.status[500:]
        assert np.all(bad != 0), fit
        assert np.all(np.isnan(res.k1[500:])) and np.all(np.isnan(res.mean[500:]))
        assert np.mean(res.status[:500] == 0) > 0.99


def test_too_few_neighbors_status():
    pts = synthetic.sphere(100, seed=16).points
    # 6 points < 9 needed by the implicit quadric
    res = curvature.estimate(pts, "knn", k=5, fit="implicit")
    assert np.all(res.status == curvature.Status.TOO_FEW_NEIGHBORS)
    assert np.all(np.isnan(res.k1))
    ok = curvature.estimate(pts, "knn", k=5, fit="monge")
    assert np.mean(ok.status == 0) > 0.9
    # the adaptive fit (the default) falls back to the height function, which needs 6
    adaptive = curvature.estimate(pts, "knn", k=5)
    np.testing.assert_array_equal(adaptive.k1, ok.k1)


def test_result_fields_and_counts(torus):
    res = curvature.estimate(torus.points, "knn", k=16)
    n = len(torus.points)
    assert res.k1.shape == (n,) and res.normals.shape == (n, 3)
    assert res.status.dtype == np.int8
    assert np.all(res.neighbor_count == 16)
    ok = res.status == 0
    assert np.all(res.k1[ok] >= res.k2[ok])
    np.testing.assert_allclose(res.mean, (res.k1 + res.k2) / 2)
    np.testing.assert_allclose(np.linalg.norm(res.normals[ok], axis=1), 1.0)
    assert np.all(res.residual[ok] >= 0)
    assert res.info["params"] == {"k": 16}
    assert sum(res.status_counts().values()) == n


def test_progress_is_reported():
    pts = synthetic.sphere(5000, seed=17).points
    calls = []
    curvature.estimate(pts, "knn", chunk_size=1000, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(d, 5000) for d in (1000, 2000, 3000, 4000, 5000)]


def test_progress_exception_aborts():
    pts = synthetic.sphere(5000, seed=18).points

    def cancel(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        curvature.estimate(pts, "knn", chunk_size=1000, progress=cancel)


@pytest.mark.parametrize("points, match", [
    (np.zeros((0, 3)), "empty"),
    (np.zeros((20, 2)), r"shape \(n, 3\)"),
    (np.zeros((5, 3)), "at least 10"),
    (np.r_[np.random.default_rng(0).random((20, 3)), [[np.nan, 0, 0]]], "row 20"),
    (np.r_[np.random.default_rng(0).random((20, 3)), [[np.inf, 0, 0]]], "NaN or Inf"),
    ([["a", "b", "c"]] * 20, "not a numeric array"),
])
def test_bad_cloud_errors(points, match):
    with pytest.raises(curvature.CurvatureInputError, match=match):
        curvature.estimate(points)


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "nope"}, "unknown method"),
    ({"fit": "cubic"}, "unknown fit"),
    ({"k": 2}, "'k' must be >= 5"),
    ({"k": 2.5}, "'k' must be a whole number"),
    ({"kk": 3}, r"unknown parameter\(s\) \['kk'\]"),
    ({"orientation": "normals"}, "needs per-point normals"),
    ({"orientation": "sideways"}, "unknown orientation"),
    ({"viewpoint": [1, 2]}, "three finite numbers"),
    ({"workers": 0}, "workers must be"),
    ({"solver": "qr"}, "must be one of"),
    ({"fit": "monge", "solver": "algebraic"}, "applies to fit .implicit. and .adaptive. only"),
    ({"normals": np.zeros((3, 3))}, r"expected shape \(50, 3\)"),
    ({"faces": [[0, 1, 99]]}, "outside 0..49"),
])
def test_bad_parameters(kwargs, match):
    pts = synthetic.sphere(50, seed=19).points
    with pytest.raises(curvature.ParameterError if "normals" not in kwargs and
                       "faces" not in kwargs else curvature.CurvatureInputError, match=match):
        curvature.estimate(pts, **{"method": "knn", **kwargs})


def test_errors_are_value_errors():
    assert issubclass(curvature.ParameterError, ValueError)
    assert issubclass(curvature.FormatError, ValueError)
