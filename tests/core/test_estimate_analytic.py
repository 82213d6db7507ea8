"""Curvature of noise-free analytic shapes against the exact answer, for both fit models."""

import numpy as np
import pytest

import curvature
from curvature import synthetic

FITS = ["implicit", "monge"]


def errors(res, cloud, mask=None):
    """Absolute errors of k1 and k2, over ``mask`` (all points by default)."""
    ok = res.status == 0
    if mask is not None:
        ok &= mask
    return np.abs(res.k1 - cloud.k1)[ok], np.abs(res.k2 - cloud.k2)[ok], ok


def run(cloud, fit, **kw):
    return curvature.estimate(cloud.points, "knn", fit=fit, normals=cloud.normals, **kw)


@pytest.mark.parametrize("fit", FITS)
def test_sphere(fit):
    cloud = synthetic.sphere(10000, radius=2.0, seed=1)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud)
    assert ok.all()
    assert e1.max() < 0.01 * 0.5 and e2.max() < 0.01 * 0.5
    assert np.allclose(res.mean[ok], 0.5, rtol=0.01)
    assert np.allclose(res.gaussian[ok], 0.25, rtol=0.02)


@pytest.mark.parametrize("fit", FITS)
def test_cylinder(fit):
    cloud = synthetic.cylinder(10000, radius=1.5, height=4.0, seed=2)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud)
    assert ok.mean() > 0.999
    assert e1.max() < 0.01 / 1.5 and e2.max() < 0.01 / 1.5
    # The zero curvature runs along the axis.
    axial = np.abs(res.dir2[ok, 2])
    assert np.median(axial) > 0.999


@pytest.mark.parametrize("fit", FITS)
def test_plane(fit):
    cloud = synthetic.plane(3000, size=2.0, seed=3)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud)
    assert ok.mean() > 0.999
    # Exact zero up to rounding, measured against the sampling scale (1/spacing ~ 30).
    assert e1.max() < 1e-6 and e2.max() < 1e-6
    assert np.abs(res.normals[ok, 2]).min() > 0.999999


@pytest.mark.parametrize("fit", FITS)
def test_saddle(fit):
    cloud = synthetic.saddle(4000, size=2.0, seed=4)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud)
    assert ok.mean() > 0.999
    scale = np.maximum(np.abs(cloud.k1), np.abs(cloud.k2))[ok]
    if fit == "implicit":  # the saddle is a quadric: exact everywhere
        assert np.all(e1 <= 0.01 * scale) and np.all(e2 <= 0.01 * scale)
    else:  # a tilted saddle is no quadratic height function: close on average
        assert np.mean(e1 / scale) < 0.01 and np.mean(e2 / scale) < 0.01
    # At the origin k1 = +1, k2 = -1 with the upward normal.
    i = np.argmin(np.linalg.norm(cloud.clean[:, :2], axis=1))
    assert res.k1[i] == pytest.approx(1.0, abs=0.02)
    assert res.k2[i] == pytest.approx(-1.0, abs=0.02)


@pytest.mark.parametrize("fit", FITS)
def test_torus_within_three_percent(fit):
    cloud = synthetic.torus(10000, major=2.0, minor=1.0, seed=5)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud)
    assert ok.mean() > 0.999
    # |k1| = 1/r = 1 is the curvature scale of the torus.
    assert e1.mean() < 0.03 and e2.mean() < 0.03
    assert np.percentile(e1, 95) < 0.1 and np.percentile(e2, 95) < 0.1


@pytest.mark.parametrize("fit", FITS)
def test_bezier_patch_within_three_percent(fit):
    cloud = synthetic.bezier_patch(10000, seed=6)
    res = run(cloud, fit)
    e1, e2, ok = errors(res, cloud, cloud.interior)
    assert ok.sum() > 0.8 * cloud.interior.sum()
    scale = np.percentile(np.maximum(np.abs(cloud.k1), np.abs(cloud.k2))[cloud.interior], 90)
    assert e1.mean() < 0.03 * scale and e2.mean() < 0.03 * scale


def test_algebraic_solver_is_exact_on_quadrics():
    cloud = synthetic.sphere(3000, radius=0.5, seed=7)
    res = run(cloud, "implicit", solver="algebraic")
    e1, e2, ok = errors(res, cloud)
    assert ok.all() and e1.max() < 1e-6 and e2.max() < 1e-6


def test_principal_directions_on_torus():
    cloud = synthetic.torus(10000, seed=8)
    res = run(cloud, "implicit")
    ok = (res.status == 0) & np.isfinite(cloud.dir1).all(axis=1)
    # Away from umbilics the k1 direction is the tube's meridian direction (up to sign).
    gap = np.abs(cloud.k1 - cloud.k2) > 0.3
    sel = ok & gap
    cos = np.abs(np.einsum("ij,ij->i", res.dir1[sel], cloud.dir1[sel]))
    assert np.median(cos) > 0.999
    # Frames are orthonormal and d2 = n x d1.
    np.testing.assert_allclose(np.cross(res.normals[sel], res.dir1[sel]), res.dir2[sel],
                               atol=1e-9)
