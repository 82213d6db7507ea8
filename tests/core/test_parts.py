"""Machined-part test shapes: their exact geometry, regions, noise models and outliers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import curvature
from curvature import synthetic
from curvature.errors import ParameterError
from curvature.synthetic.profiles import filleted_polygon

PARTS = ["filleted_box", "filleted_cylinder", "blade", "thin_plate"]


@pytest.mark.parametrize("name", PARTS)
def test_part_fields_are_consistent(name):
    c = synthetic.make(name, 4000, seed=3)
    n = len(c)
    assert c.points.shape == (n, 3) and c.region.shape == (n,)
    np.testing.assert_allclose(np.linalg.norm(c.normals, axis=1), 1.0, atol=1e-12)
    assert np.all(c.k1 >= c.k2)
    assert set(np.unique(c.region)) <= set(range(len(c.region_names)))
    # the edge zone is exactly the points within edge_zone spacings of a curvature jump
    near = c.feature_distance < c.params["edge_zone"] * c.params["spacing"]
    np.testing.assert_array_equal(c.region_mask("edge_zone"), near)
    # principal directions, where defined, form a right-handed frame with the normal
    ok = np.isfinite(c.dir1[:, 0])
    np.testing.assert_allclose(np.cross(c.dir1[ok], c.dir2[ok]), c.normals[ok], atol=1e-9)


def test_filleted_box_is_a_rounded_box():
    c = synthetic.filleted_box(6000, size=(2.0, 1.5, 1.0), fillet=0.2, seed=1)
    half = np.array([1.0, 0.75, 0.5]) - 0.2
    inner = np.clip(c.clean, -half, half)
    # every point is at the fillet radius from the inner box, along its outward normal
    np.testing.assert_allclose(np.linalg.norm(c.clean - inner, axis=1), 0.2, atol=1e-12)
    np.testing.assert_allclose((c.clean - inner) / 0.2, c.normals, atol=1e-9)
    expect = {"face": (0.0, 0.0), "fillet": (5.0, 0.0), "corner": (5.0, 5.0)}
    for region, (k1, k2) in expect.items():
        # regions are labelled by their piece (edge-zone points of each piece as well)
        piece = c.uv[:, 0]
        m = {"face": piece < 6, "fillet": (piece >= 6) & (piece < 18), "corner": piece >= 18}[
            region]
        np.testing.assert_allclose(c.k1[m], k1)
        np.testing.assert_allclose(c.k2[m], k2)
    # area-uniform: the share of face points matches the faces' share of the area
    face_area = 2 * (1.6 * 1.1 + 1.6 * 0.6 + 1.1 * 0.6)
    total = face_area + 4 * (1.6 + 1.1 + 0.6) * np.pi * 0.2 / 2 + 4 * np.pi * 0.04
    assert abs(np.mean(c.uv[:, 0] < 6) - face_area / total) < 0.02


@pytest.mark.parametrize("name", ["blade", "thin_plate", "filleted_cylinder"])
def test_exact_curvature_matches_a_fit_away_from_joints(name):
    # planes and cylinders are quadrics: the implicit fit over a few neighbors is exact on the
    # curved pieces, a Monge fit on the flat ones (an implicit fit of a plane is ill-posed)
    c = synthetic.make(name, 20000, seed=2)
    implicit = curvature.estimate(c.points, "knn", k=12, normals=c.normals)
    monge = curvature.estimate(c.points, "knn", k=12, fit="monge", normals=c.normals)
    far = (c.feature_distance > 4 * c.params["spacing"]) & c.interior
    if name == "filleted_cylinder":  # torus sections are no quadric
        far &= c.region_mask("side") | c.region_mask("cap")
    # where a wall is thin, 12 neighbors reach its other side: checked in test_auto_parts
    nbr = cKDTree(c.points).query(c.points, 13)[1]
    far &= np.all(np.einsum("nkd,nd->nk", c.normals[nbr], c.normals) > 0.5, axis=1)
    flat = (c.k1 == 0) & (c.k2 == 0)
    assert far.sum() > 0.3 * len(c)
    for res, rows in ((implicit, far & ~flat), (monge, far & flat)):
        np.testing.assert_allclose(res.k1[rows], c.k1[rows], atol=1e-5)
        np.testing.assert_allclose(res.k2[rows], c.k2[rows], atol=1e-5)


def test_stepped_cylinder_has_a_concave_fillet():
    c = synthetic.filleted_cylinder(8000, radius=1.0, height=2.0, fillet=0.1, step=(0.6, 1.0),
                                    edge_zone=0.0, seed=1)
    inner = c.region_mask("inner_fillet")
    assert inner.any()
    assert np.allclose(np.minimum(c.k1, c.k2)[inner], -10.0)  # bends toward the normal
    assert np.all(c.k1[c.region_mask("fillet")] == pytest.approx(10.0))


def test_blade_is_thin_near_its_trailing_edge():
    c = synthetic.blade(20000, seed=1)
    s = c.params["spacing"]
    near_te = c.clean[:, 0] > c.clean[:, 0].max() - 0.1
    # the two sides there are a few spacings apart (a thin wall)
    assert np.ptp(c.clean[near_te, 1]) < 3 * s
    assert c.params["leading_radius"] / s > 3


def test_view_noise_moves_points_along_the_view_direction():
    c = synthetic.filleted_box(3000, noise=0.5, noise_model="view", seed=1)
    d = c.points - c.clean
    view = np.asarray(synthetic.VIEW_DIRECTION) / np.linalg.norm(synthetic.VIEW_DIRECTION)
    np.testing.assert_allclose(np.cross(d, view), 0.0, atol=1e-12)
    assert np.std(d @ view) == pytest.approx(c.noise_sigma, rel=0.1)


def test_outliers_replace_a_share_of_points_with_nan_truth():
    c = synthetic.thin_plate(5000, outliers=0.02, seed=4)
    out = c.region_mask("outlier")
    assert out.sum() == 100
    assert np.all(np.isnan(c.k1[out])) and not np.any(np.isnan(c.k1[~out]))
    assert not np.any(c.interior[out])


@pytest.mark.parametrize("call", [
    lambda: synthetic.filleted_box(100, size=(1.0, 1.0, 0.3), fillet=0.2),
    lambda: synthetic.filleted_box(100, outliers=1.5),
    lambda: synthetic.blade(100, crest=1.2),
    lambda: synthetic.thin_plate(100, width=0.05, thickness=0.06),
    lambda: synthetic.filleted_cylinder(100, step=(0.95, 1.0)),
    lambda: synthetic.filleted_box(100, noise_model="sideways"),
])
def test_bad_part_parameters_are_refused(call):
    with pytest.raises(ParameterError):
        call()


def test_profile_fillets_that_overlap_are_refused():
    with pytest.raises(ParameterError, match="overlap"):
        filleted_polygon([(0, 0), (1, 0), (1, 1), (0, 1)], [0.8] * 4, ["f"] * 4, ["r"] * 4)


def test_cli_writes_part_shapes(tmp_path):
    out = tmp_path / "box.ply"
    assert synthetic.main(["filleted_box", "--n", "500", "--noise", "0.1", "-o", str(out)]) == 0
    assert curvature.read(out).points.shape == (500, 3)
