"""Tests for curvature.studies.peers.apss (MeshLab's APSS as a benchmark reference).

The pymeshlab-backed tests are skipped when pymeshlab is missing (it is only in the ``bench``
extra, so CI skips them). Expected values are closed forms written here: a sphere of radius
r has k1 = k2 = +1/r with outward normals; a torus (R, r) with outward normals has k1 = 1/r
everywhere, k2 = 1/(R + r) on the outer equator and k2 = -1/(R - r) on the inner one.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from curvature import synthetic
from curvature.errors import ParameterError
from curvature.studies.peers.apss import apss_curvature, principal_from_mean_gauss


@pytest.fixture(scope="module")
def pml():
    return pytest.importorskip(
        "pymeshlab", reason="pymeshlab not installed (optional: pip install 'curvature[bench]')")


@pytest.fixture(scope="module")
def sphere():
    return synthetic.sphere(3000, radius=2.0, seed=1)


@pytest.fixture(scope="module")
def torus():
    return synthetic.torus(4000, major=2.0, minor=1.0, seed=1)


# ------------------------------------------------------------------------------------------
# Without pymeshlab
# ------------------------------------------------------------------------------------------


def test_principal_from_mean_gauss_signed_order():
    k1_true = np.array([0.5, 1.0, -0.2, 0.3, 2.0])
    k2_true = np.array([0.5, -1.0, -0.7, 0.3, -3.0])
    k1, k2 = principal_from_mean_gauss(k1_true + k2_true, k1_true * k2_true)
    np.testing.assert_allclose(k1, k1_true, atol=1e-7)
    np.testing.assert_allclose(k2, k2_true, atol=1e-7)


def test_principal_from_mean_gauss_clamps_and_flags_failures():
    # Slightly negative discriminant (umbilic with rounding) -> k1 = k2 = H, not NaN.
    k1, k2 = principal_from_mean_gauss(np.array([1.0, 0.0]), np.array([0.25 + 1e-12, 0.0]))
    assert k1[0] == k2[0] == 0.5
    # Both outputs exactly 0 is MeshLab's failed point.
    assert np.isnan(k1[1]) and np.isnan(k2[1])


def test_missing_pymeshlab_raises_with_install_hint(monkeypatch, sphere):
    monkeypatch.setitem(sys.modules, "pymeshlab", None)  # makes `import pymeshlab` fail
    with pytest.raises(ImportError, match=r"pip install 'curvature\[bench\]'"):
        apss_curvature(sphere.points, sphere.normals)


def test_bad_shapes_rejected(sphere):
    with pytest.raises(ParameterError):
        apss_curvature(sphere.points[:, :2])
    with pytest.raises(ParameterError):
        apss_curvature(sphere.points, sphere.normals[:-1])


# ------------------------------------------------------------------------------------------
# With pymeshlab
# ------------------------------------------------------------------------------------------


def test_sphere_with_outward_normals_is_positive(pml, sphere):
    k1, k2 = apss_curvature(sphere.points, sphere.normals, filter_scale=8.0)
    assert np.all(k1 >= k2)
    np.testing.assert_allclose(k1, 0.5, rtol=0.02)
    np.testing.assert_allclose(k2, 0.5, rtol=0.02)


def test_sign_follows_given_normals(pml, sphere):
    k1, k2 = apss_curvature(sphere.points, -sphere.normals, filter_scale=8.0)
    np.testing.assert_allclose(k1, -0.5, rtol=0.02)
    np.testing.assert_allclose(k2, -0.5, rtol=0.02)


def test_estimated_normals_are_oriented_outward(pml, sphere):
    k1, k2 = apss_curvature(sphere.points, filter_scale=8.0)
    assert np.all(k1 >= k2)
    assert abs(np.median(k1) - 0.5) < 0.02 and abs(np.median(k2) - 0.5) < 0.02


def test_torus_signs_and_values_match_closed_form(pml, torus):
    k1, k2 = apss_curvature(torus.points, torus.normals, filter_scale=8.0)
    assert np.all(k1 >= k2)
    rho = np.hypot(torus.points[:, 0], torus.points[:, 1])
    outer = rho > 2.95  # R + r = 3
    inner = rho < 1.05  # R - r = 1
    assert outer.sum() > 50 and inner.sum() > 20
    assert abs(np.mean(k1[outer]) - 1.0) < 0.05
    assert abs(np.mean(k2[outer]) - 1.0 / 3.0) < 0.03
    assert abs(np.mean(k1[inner]) - 1.0) < 0.05
    assert abs(np.mean(k2[inner]) + 1.0) < 0.08
    # Everywhere: the estimate tracks the exact values, signs included.
    assert np.median(np.abs(k1 - torus.k1)) < 0.03
    assert np.median(np.abs(k2 - torus.k2)) < 0.03
    clear = np.abs(torus.k2) > 0.1
    assert np.mean(np.sign(k2[clear]) == np.sign(torus.k2[clear])) > 0.99
