"""Tiled runs equal untiled runs bit for bit, for every method; halos grow when short."""

from __future__ import annotations

import numpy as np
import pytest

import curvature
from curvature import synthetic, tiling
from curvature.pipeline import resolve_request


def assert_identical(a, b):
    for name, arr in a.fields().items():
        np.testing.assert_array_equal(b.fields()[name], arr, err_msg=name)


@pytest.fixture(scope="module")
def torus():
    return synthetic.torus(8000, noise=0.3, seed=1).points


CASES = [
    ("auto", {}), ("knn", {"fit": "implicit"}), ("knn", {"fit": "monge", "k": 16}),
    ("knn", {"fit": "nfr", "k": 64, "normal_k": 24}), ("tc", {"fit": "implicit"}),
    ("tc", {"fit": "monge", "min_neighbors": 24}), ("egg", {"fit": "monge"}), ("mesh", {}),
]


@pytest.mark.parametrize("method, kwargs", CASES, ids=[f"{m}-{k}" for m, k in CASES])
def test_tiled_equals_untiled(torus, method, kwargs):
    whole = curvature.estimate(torus, method, tile_points=0, **kwargs)
    for tile_points in (1500, 4000):
        tiled = curvature.estimate(torus, method, tile_points=tile_points, **kwargs)
        assert tiled.info["tiles"] == -(-len(torus) // tile_points)
        assert_identical(whole, tiled)


def test_clean_cloud_auto_and_given_normals(torus):
    cloud = synthetic.ellipsoid(6000, axes=(3, 2, 1), seed=2)
    whole = curvature.estimate(cloud.points, normals=cloud.normals, tile_points=0)
    tiled = curvature.estimate(cloud.points, normals=cloud.normals, tile_points=1000)
    assert tiled.info["fit"] == "implicit" and tiled.info["tiles"] == 6
    assert_identical(whole, tiled)


def test_mesh_with_faces_on_the_bunny(shared_data):
    mesh = curvature.read(shared_data / "bun_zipper.ply")
    whole = curvature.estimate(mesh, "mesh", fit="monge", tile_points=0)
    tiled = curvature.estimate(mesh, "mesh", fit="monge", tile_points=5000)
    assert tiled.info["tiles"] == 8
    assert_identical(whole, tiled)
    np.testing.assert_array_equal(tiled.faces, mesh.faces)


def test_short_halos_grow_and_results_stay_identical(torus, monkeypatch):
    monkeypatch.setattr(tiling, "HALO_MARGIN", 0.05)
    monkeypatch.setattr(tiling, "AUTO_HALO", 0.5)
    for method, kwargs in (("auto", {}), ("tc", {}), ("knn", {"fit": "nfr", "k": 48})):
        whole = curvature.estimate(torus, method, tile_points=0, **kwargs)
        tiled = curvature.estimate(torus, method, tile_points=2000, **kwargs)
        assert tiled.info["regrown"] > 0, method
        assert_identical(whole, tiled)


def test_tiles_are_identical_for_any_workers_and_order(torus):
    ref = curvature.estimate(torus, tile_points=3000, workers=1)
    perm = np.random.default_rng(3).permutation(len(torus))
    other = curvature.estimate(torus[perm], tile_points=2500, workers=2, chunk_size=700)
    for name, arr in ref.fields().items():
        np.testing.assert_array_equal(other.fields()[name], arr[perm], err_msg=name)


def test_reach_of_knn_is_the_kth_distance(torus):
    req = resolve_request(None, "knn", "monge", {"k": 12}, None, None, None, 1, 1000)
    spts = np.ascontiguousarray(torus[:2000])
    block = curvature.pipeline.compute_block(spts, None, req, track_reach=True)
    d = np.linalg.norm(spts[:, None, :] - spts[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    np.testing.assert_allclose(block.reach, np.sort(d, axis=1)[:, 11], rtol=1e-12)


def test_restrict_graph_keeps_edges_inside():
    indptr = np.array([0, 2, 4, 6, 8])
    indices = np.array([1, 3, 0, 2, 1, 3, 0, 2])  # a 4-cycle 0-1-2-3-0
    ptr, idx = tiling.restrict_graph((indptr, indices), np.array([0, 1, 3]), 4)
    assert ptr.tolist() == [0, 2, 3, 4]
    assert idx.tolist() == [1, 2, 0, 0]


@pytest.mark.parametrize("bad", [-1, 2.5, True, "many"])
def test_bad_tile_points(torus, bad):
    with pytest.raises(curvature.ParameterError, match="tile_points"):
        curvature.estimate(torus[:100], "knn", tile_points=bad)
