"""Normal orientation over a minimum spanning forest (Prim's algorithm on the neighbor table)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import cKDTree

from curvature import synthetic
from curvature.orientation import (
    CHORD_CAP,
    CHORD_WEIGHT,
    ORIENT_K,
    forest_signs,
    reverse_edges,
    signs_auto,
    spanning_forest,
)


def knn_graph(points, k=ORIENT_K):
    _, idx = cKDTree(points).query(points, k + 1)
    return idx[:, 1:].astype(np.int32)


def forest(points, normals, graph):
    valid = np.isfinite(normals).all(axis=1)
    parent, order, count = spanning_forest(points, graph, *reverse_edges(graph, valid),
                                           normals, valid)
    return parent, order[:count], valid


def edge_weights(points, normals, rows, cols):
    """1 - |ni . nj| plus CHORD_WEIGHT |u . ni| |u . nj| (at most CHORD_CAP) of the unit
    chord u, edge by edge."""
    chord = points[cols] - points[rows]
    chord /= np.linalg.norm(chord, axis=1)[:, None]
    along = np.abs(np.einsum("ij,ij->i", chord, normals[rows]))
    along *= np.abs(np.einsum("ij,ij->i", chord, normals[cols]))
    parallel = np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols]))
    return 1.0 - parallel + np.minimum(CHORD_WEIGHT * along, CHORD_CAP)


def scipy_mst_weight(points, normals, graph, valid):
    rows = np.repeat(np.arange(len(graph)), graph.shape[1])
    cols = graph.ravel()
    keep = valid[rows] & valid[cols]
    rows, cols = rows[keep], cols[keep]
    w = edge_weights(points, normals, rows, cols) + 1.0  # > 0: scipy drops zero edges
    tree = minimum_spanning_tree(csr_matrix((w, (rows, cols)), shape=(len(graph),) * 2))
    return tree.sum() - tree.nnz, tree.nnz


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forest_is_a_minimum_spanning_forest(seed):
    cloud = synthetic.torus(1500, noise=0.5, seed=seed)
    rng = np.random.default_rng(seed)
    normals = cloud.normals * rng.choice([-1.0, 1.0], len(cloud))[:, None]
    normals[rng.choice(len(cloud), 40, replace=False)] = np.nan  # failed points stay out
    graph = knn_graph(cloud.points)
    parent, order, valid = forest(cloud.points, normals, graph)
    assert set(order.tolist()) == set(np.flatnonzero(valid).tolist())
    position = np.empty(len(cloud), np.int64)
    position[order] = np.arange(len(order))
    child = order[parent[order] >= 0]
    assert np.all(position[parent[child]] < position[child])  # parents join first
    weight = edge_weights(cloud.points, normals, child, parent[child]).sum()
    expected, edges = scipy_mst_weight(cloud.points, normals, graph, valid)
    assert len(child) == edges
    assert weight == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_signs_make_a_closed_surface_point_outward_whatever_the_input_signs():
    cloud = synthetic.ellipsoid(3000, axes=(3, 2, 1), noise=0.2, seed=4)
    rng = np.random.default_rng(4)
    flips = rng.choice([-1.0, 1.0], len(cloud))
    signs = signs_auto(cloud.points, cloud.normals * flips[:, None], knn_graph(cloud.points))
    np.testing.assert_array_equal(signs, flips.astype(np.int8))


def test_each_component_is_seeded_outward_on_its_own():
    a = synthetic.sphere(800, radius=1.0, seed=1)
    b = synthetic.sphere(800, radius=1.0, seed=2)
    points = np.vstack([a.points, b.points + [10.0, 0.0, 0.0]])
    normals = -np.vstack([a.normals, b.normals])  # all inward
    graph = knn_graph(points)
    parent, order, valid = forest(points, normals, graph)
    assert np.sum(parent[order] < 0) == 2  # two trees
    signs = forest_signs(points, normals, parent, order)
    assert np.all(signs == -1)


def test_invalid_points_keep_their_sign_and_break_no_tree():
    cloud = synthetic.sphere(500, seed=3)
    normals = cloud.normals.copy()
    normals[::7] = np.nan
    signs = signs_auto(cloud.points, -normals, knn_graph(cloud.points))
    assert np.all(signs[::7] == 1)
    ok = np.isfinite(normals).all(axis=1)
    assert np.all(signs[ok] == -1)


def test_one_viewpoint_per_point():
    """A viewpoint row per point (several scans): each normal faces its own viewpoint."""
    import curvature
    from curvature.errors import ParameterError

    cloud = synthetic.sphere(3000, seed=4)
    upper = cloud.points[:, 2] > 0
    # upper half seen from the centre (normals in), lower half from far below (normals out)
    views = np.where(upper[:, None], 0.0, np.array([0.0, 0.0, -10.0]))
    res = curvature.estimate(cloud.points, "knn", viewpoint=views, workers=1)
    ok = res.status == 0
    radial = np.einsum("ij,ij->i", res.normals, cloud.points)
    # from (0, 0, -10) the outer side of the unit sphere shows below z = -0.1 (some margin)
    below = cloud.points[:, 2] < -0.2
    assert np.all(radial[ok & upper] < 0) and np.all(radial[ok & below] > 0)
    assert res.info["orientation"] == "viewpoint" and "viewpoint" not in res.info
    with pytest.raises(ParameterError, match=r"shape \(3000, 3\).*got \(2999, 3\)"):
        curvature.estimate(cloud.points, "knn", viewpoint=views[1:])
    views[17] = np.nan
    with pytest.raises(ParameterError, match="viewpoint of point 17 is not finite"):
        curvature.estimate(cloud.points, "knn", viewpoint=views)


@pytest.mark.parametrize("shape, seed", [("thin_plate", 1), ("thin_plate", 2), ("blade", 2)])
def test_a_thin_wall_does_not_flip_one_side(shape, seed):
    """Across a wall 2 to 3 spacings thick the two sides' normals are parallel up to sign, so
    1 - |ni . nj| alone weighs an edge across it 0, and that one edge flipped a whole side of
    these clouds (half their points). The chord's run along both normals weighs it up."""
    cloud = synthetic.make(shape, seed=seed, noise=0.1)
    ok = np.isfinite(cloud.normals).all(axis=1)
    points, normals = cloud.points[ok], cloud.normals[ok]
    flips = np.random.default_rng(seed).choice([-1.0, 1.0], len(points))
    signs = signs_auto(points, normals * flips[:, None], knn_graph(points))
    np.testing.assert_array_equal(signs, flips.astype(np.int8))
