"""Tests for curvature.studies.peers.cgal (CGAL's jet fitting as a benchmark reference).

Input checks and the missing-header path run everywhere; the fits are skipped with the reason
when CGAL's headers or a C++ compiler are missing (``.ci/run`` installs them). Expected values
are closed forms: a sphere of radius r has k1 = k2 = +1/r with outward normals, a cylinder of
radius r has 1/r and 0, a plane 0 and 0; the saddle's come from ``curvature.synthetic``.
"""

from __future__ import annotations

import numpy as np
import pytest

from curvature import synthetic
from curvature.errors import CurvatureInputError, ParameterError
from curvature.studies.peers import cgal as reference_cgal
from curvature.studies.peers.cgal import (
    CgalBuildError,
    build_cgal_jet,
    cgal_available,
    cgal_jet_curvature,
    cgal_unavailable_reason,
)

needs_cgal = pytest.mark.skipif(not cgal_available(),
                                reason=f"CGAL reference unavailable: {cgal_unavailable_reason()}")


@pytest.fixture(scope="module")
def driver():
    """The compiled driver (built once per cache; about 20 s on a cold cache)."""
    return build_cgal_jet()


@pytest.fixture(scope="module")
def sphere():
    return synthetic.sphere(3000, radius=2.0, seed=1)


def _dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


# ------------------------------------------------------------------------------------------
# Without CGAL
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, match", [
    ({"k": 14, "degree": 4}, "at least 15"),
    ({"k": 5}, "at least 6"),
    ({"k": 24.0}, "k must be an integer"),
    ({"degree": 1}, "degree must be one of"),
    ({"degree": 5}, "degree must be one of"),
    ({"workers": 0}, "workers must be a positive integer"),
])
def test_bad_parameters_name_the_parameter(sphere, kwargs, match):
    with pytest.raises(ParameterError, match=match):
        cgal_jet_curvature(sphere.points, sphere.normals, **kwargs)


def test_bad_points_and_normals_are_named(sphere):
    pts = sphere.points.copy()
    pts[7, 1] = np.nan
    with pytest.raises(CurvatureInputError, match="points must be finite; row 7"):
        cgal_jet_curvature(pts)
    with pytest.raises(CurvatureInputError, match=r"points must have shape \(n, 3\)"):
        cgal_jet_curvature(sphere.points[:, :2])
    with pytest.raises(CurvatureInputError, match="normals must have shape"):
        cgal_jet_curvature(sphere.points, sphere.normals[:-1])
    with pytest.raises(CurvatureInputError, match="at least 10 points"):
        cgal_jet_curvature(sphere.points[:9])


def test_missing_headers_give_a_reason_and_a_build_error(monkeypatch, tmp_path):
    monkeypatch.setattr(reference_cgal, "_include_dirs", lambda: [tmp_path])
    monkeypatch.setattr(reference_cgal, "_compiler", lambda: "/usr/bin/c++")
    assert not cgal_available()
    reason = cgal_unavailable_reason()
    assert "CGAL headers not found" in reason and "libcgal-dev" in reason
    with pytest.raises(CgalBuildError, match="CGAL headers not found"):
        build_cgal_jet(tmp_path)
    (tmp_path / "CGAL").mkdir()
    (tmp_path / "CGAL" / "Monge_via_jet_fitting.h").write_text("")
    assert "Eigen headers not found" in cgal_unavailable_reason()


def test_missing_compiler_is_the_reason(monkeypatch):
    monkeypatch.setattr(reference_cgal, "_compiler", lambda: None)
    assert "no C++ compiler" in cgal_unavailable_reason()


# ------------------------------------------------------------------------------------------
# With CGAL
# ------------------------------------------------------------------------------------------

@needs_cgal
def test_compiler_errors_are_reported(monkeypatch, tmp_path):
    broken = tmp_path / "jet_fitting.cpp"
    broken.write_text("int main() { return undeclared_name_here; }\n")
    monkeypatch.setattr(reference_cgal, "CGAL_SOURCE", broken)
    with pytest.raises(CgalBuildError, match="undeclared_name_here"):
        build_cgal_jet(tmp_path / "cache")


@needs_cgal
def test_build_is_cached(driver):
    assert build_cgal_jet() == driver
    assert driver.is_file()


@needs_cgal
@pytest.mark.parametrize("degree, tol", [(4, 1e-3), (2, 1e-2)])
def test_sphere_outward_normals_give_plus_one_over_r(driver, sphere, degree, tol):
    # Degree 2 cannot represent the sphere's quartic term, so it overestimates 1/r slightly.
    k1, k2, normals, status = cgal_jet_curvature(sphere.points, sphere.normals, degree=degree)
    assert (status == 0).all()
    np.testing.assert_allclose(k1, 0.5, atol=tol)
    np.testing.assert_allclose(k2, 0.5, atol=tol)
    assert (k1 >= k2).all()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    assert _dots(normals, sphere.normals).min() > 0.999


@needs_cgal
def test_flipped_normals_flip_the_signs(driver, sphere):
    k1, k2, normals, _ = cgal_jet_curvature(sphere.points, sphere.normals, degree=4)
    f1, f2, fnormals, _ = cgal_jet_curvature(sphere.points, -sphere.normals, degree=4)
    np.testing.assert_allclose(f1, -k2, atol=1e-12)
    np.testing.assert_allclose(f2, -k1, atol=1e-12)
    np.testing.assert_allclose(fnormals, -normals, atol=1e-12)
    np.testing.assert_allclose(f1, -0.5, atol=1e-3)


@needs_cgal
def test_without_normals_only_the_orientation_is_arbitrary(driver, sphere):
    k1, k2, normals, _ = cgal_jet_curvature(sphere.points, degree=4)
    np.testing.assert_allclose(k1 * k2, 0.25, atol=1e-3)
    np.testing.assert_allclose(np.abs(k1 + k2), 1.0, atol=2e-3)
    # Curvature signs follow the returned normal: positive exactly where it points outward.
    outward = _dots(normals, sphere.normals) > 0
    assert ((k1 > 0) == outward).all()


@needs_cgal
def test_cylinder_gives_one_over_r_and_zero(driver):
    cyl = synthetic.cylinder(3000, radius=0.5, height=3.0, seed=2)
    k1, k2, _, status = cgal_jet_curvature(cyl.points, cyl.normals, degree=4)
    inner = cyl.interior
    assert (status[inner] == 0).all()
    np.testing.assert_allclose(k1[inner], 2.0, atol=1e-2)
    np.testing.assert_allclose(k2[inner], 0.0, atol=1e-2)


@needs_cgal
@pytest.mark.parametrize("degree", [2, 4])
def test_plane_is_flat(driver, degree):
    plane = synthetic.plane(1500, seed=3)
    k1, k2, normals, status = cgal_jet_curvature(plane.points, plane.normals, k=30, degree=degree)
    assert (status == 0).all()
    np.testing.assert_allclose(k1, 0.0, atol=1e-8)
    np.testing.assert_allclose(k2, 0.0, atol=1e-8)
    np.testing.assert_allclose(normals, plane.normals, atol=1e-8)


@needs_cgal
def test_saddle_matches_the_exact_curvatures(driver):
    saddle = synthetic.saddle(4000, size=1.0, seed=4)
    k1, k2, _, status = cgal_jet_curvature(saddle.points, saddle.normals, degree=4)
    inner = saddle.interior
    assert (status[inner] == 0).all()
    assert k1[inner].min() > 0 > k2[inner].max()
    np.testing.assert_allclose(k1[inner], saddle.k1[inner], atol=5e-3)
    np.testing.assert_allclose(k2[inner], saddle.k2[inner], atol=5e-3)


@needs_cgal
def test_workers_do_not_change_the_result(driver):
    torus = synthetic.torus(2000, noise=0.5, seed=5)
    one = cgal_jet_curvature(torus.points, torus.normals, k=30, workers=1)
    two = cgal_jet_curvature(torus.points, torus.normals, k=30, workers=2)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)


@needs_cgal
def test_degenerate_neighborhoods_fail_per_point(driver):
    line = np.column_stack([np.linspace(0.0, 1.0, 40), np.zeros(40), np.zeros(40)])
    blob = np.random.default_rng(6).random((40, 3)) + 5.0
    k1, k2, normals, status = cgal_jet_curvature(np.vstack([line, blob]), k=24)
    assert (status[:40] == 2).all()
    assert np.isnan(k1[:40]).all() and np.isnan(k2[:40]).all() and np.isnan(normals[:40]).all()
    assert (status[40:] == 0).all() and np.isfinite(k1[40:]).all()
