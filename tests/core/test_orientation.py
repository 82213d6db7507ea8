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
    CIRCLE_TOL,
    MIRROR_BELOW,
    MIRROR_CIRCLE_BELOW,
    ORIENT_K,
    _children,
    _cut_votes,
    _flip_subtree,
    _sign_agreement,
    forest_signs,
    relative_signs,
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


def _sphere_polyhedron(vertices, graph_k):
    """Points at the unit vectors ``vertices``, their outward normals, each joined to its
    ``graph_k`` nearest others."""
    points = np.asarray(vertices, float)
    points /= np.linalg.norm(points, axis=1)[:, None]
    return points, points.copy(), knn_graph(points, graph_k)


@pytest.mark.parametrize("vertices, graph_k", [
    # a tetrahedron's normals are 109.5 degrees apart (ni . nj = -1/3), a triangle's 120
    ([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], 3),
    ([[1, 0, 0], [-0.5, 0.75 ** 0.5, 0], [-0.5, -(0.75 ** 0.5), 0]], 2),
])
def test_normals_far_apart_keep_their_signs_by_the_mirror(vertices, graph_k):
    """Beyond 90 degrees ni . nj calls consistent normals opposite; mirrored across the
    plane bisecting the chord, the normals of two points of a circle or sphere coincide."""
    points, normals, graph = _sphere_polyhedron(vertices, graph_k)
    assert (normals @ normals.T)[~np.eye(len(points), dtype=bool)].max() < 0.0
    for flips in ([1, 1, 1, 1], [1, -1, 1, -1], [-1, -1, 1, 1]):
        flips = np.array(flips[:len(points)], float)
        signs = signs_auto(points, normals * flips[:, None], graph)
        np.testing.assert_array_equal(signs, flips.astype(np.int8))


def _agreement(a, b, chord):
    return _sign_agreement(*a, *b, *chord)


@pytest.mark.parametrize("turn_deg", [30.0, 60.0, 100.0, 140.0, 150.0])
def test_two_points_of_a_circle_agree_however_far_their_normals_turn(turn_deg):
    t = np.radians(turn_deg)
    a, b = np.array([0.0, 0.0, 1.0]), np.array([np.sin(t), 0.0, np.cos(t)])
    chord = b - a  # the points of a unit circle whose normals they are
    assert _agreement(a, b, chord) > 0.0
    assert _agreement(a, -b, chord) < 0.0
    if turn_deg > 90.0:
        assert a @ b < 0.0  # which ni . nj alone would call opposite


def test_a_chord_off_the_circle_leaves_the_sign_to_the_dot_product():
    """Normals 30 degrees apart (between the thresholds), the chord 33 degrees from one of
    them as between a surface and one behind it (PCL's milk scene had such an edge): no
    circle through both points has these normals, so ni . nj decides, and the mirror (which
    would say opposite) does not."""
    t = np.radians(30.0)
    a, b = np.array([0.0, 0.0, 1.0]), np.array([np.sin(t), 0.0, np.cos(t)])
    chord = -b + [0.0, 0.65, 0.0]
    assert MIRROR_BELOW <= a @ b < MIRROR_CIRCLE_BELOW
    along = (a @ chord) * (b @ chord) / (chord @ chord)
    assert min(abs(along + (1 - a @ b) / 2), abs(along - (1 + a @ b) / 2)) > CIRCLE_TOL
    assert a @ b - 2 * along < 0.0
    assert _agreement(a, b, chord) > 0.0
    assert _agreement(a, -b, chord) < 0.0


def test_near_parallel_normals_keep_their_own_dot_product():
    """Two planes one behind the other, facing the same way as in a single view, joined by
    chords along their normals: the mirror would call them opposite; within 46 degrees
    ni . nj decides, so both keep the sign they share."""
    rng = np.random.default_rng(5)
    front = np.column_stack([rng.uniform(0, 1, (2, 200)).T, np.full(200, 0.05)])
    back = front + [0.0, 0.0, -0.05]
    points = np.vstack([front, back])
    normals = np.tile([0.0, 0.3, 1.0], (400, 1)) / np.hypot(0.3, 1.0)
    flips = rng.choice([-1.0, 1.0], 400)
    signs = signs_auto(points, normals * flips[:, None], knn_graph(points))
    relative = (signs * flips).astype(int)
    assert np.all(relative == relative[0])


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


def test_cut_votes_are_the_weights_across_each_subtrees_cut():
    """The weights across each tree edge's cut (lowest common ancestors, subtree sums) equal
    a brute-force count over the graph's edges with one end in the subtree (a graph of
    mutual edges: each is read once, at its later end)."""
    cloud = synthetic.make("thin_plate", seed=3, noise=0.25)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(cloud.points), 1500, replace=False)
    points = cloud.points[pick]
    normals = cloud.normals[pick] + rng.normal(0.0, 0.3, (1500, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    near = knn_graph(points)
    mutual = (near[near] == np.arange(1500)[:, None, None]).any(axis=2)
    graph = np.where(mutual, near, -1).astype(np.int32)
    parent, order, valid = forest(points, normals, graph)
    rel = relative_signs(points, normals, parent, order)
    rel[rng.choice(1500, 300, replace=False)] *= -1  # some disagreement
    agree, disagree = _cut_votes(points, normals, graph, valid, parent, order,
                                 *_children(parent, order), rel)
    i, j = np.array(sorted({(min(a, b), max(a, b)) for a in range(1500) for b in graph[a]
                            if b >= 0})).T
    chord = points[j] - points[i]
    val = np.array([_sign_agreement(*normals[a], *normals[b], *d)
                    for a, b, d in zip(i, j, chord, strict=True)])
    u = chord / np.linalg.norm(chord, axis=1)[:, None]
    along = np.abs(np.einsum("ij,ij->i", u, normals[i]) * np.einsum("ij,ij->i", u, normals[j]))
    weight = np.minimum(np.abs(val), 1.0) * (1.0 - np.minimum(along, 1.0))
    consistent = (val >= 0) == (rel[i] == rel[j])
    for c in rng.choice(order[parent[order] >= 0], 40, replace=False):
        inside = np.ones(1500, np.int8)
        _flip_subtree(parent, order, inside, c)
        cross = (inside[i] < 0) != (inside[j] < 0)
        assert agree[c] == pytest.approx(weight[cross & consistent].sum(), abs=1e-9)
        assert disagree[c] == pytest.approx(weight[cross & ~consistent].sum(), abs=1e-9)


def test_a_wall_crossed_by_the_forest_is_repaired_by_its_rims():
    """On a thin plate at 0.25 % noise two points of its opposite faces come within each
    other's nearest neighbors, their chord along both normals: the forest crosses the wall
    there (one edge costs less than the rim's turn), and that edge turned one face inward
    (half the plate). The rims' edges across the same cut disagree, and the subtree is
    flipped back; faces one behind the other keep their shared sign (the test above)."""
    import curvature

    cloud = synthetic.make("thin_plate", seed=3, noise=0.25)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    flips = np.random.default_rng(3).choice([-1.0, 1.0], len(cloud.points))
    normals = res.normals * flips[:, None]
    graph = knn_graph(cloud.points)
    parent, order, valid = forest(cloud.points, normals, graph)
    unrepaired = (forest_signs(cloud.points, normals, parent, order) * flips < 0)[valid]
    assert min(unrepaired.sum(), (~unrepaired).sum()) > 0.4 * valid.sum()  # the case exists
    wrong = (signs_auto(cloud.points, normals, graph) * flips < 0)[valid]
    assert wrong.sum() < 0.01 * valid.sum()
