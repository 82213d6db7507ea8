"""The k-d tree's k nearest neighbors equal a brute-force reference exactly (indices and
squared distances), sorted by (d2, index), whatever the query order, the starting radii and
the number of ties and duplicates."""

from __future__ import annotations

import numpy as np
import pytest

from curvature.neighborhoods.kdtree import (
    build_tree,
    knn_parallel,
    knn_point_within,
    knn_rows,
    knn_scratch,
)


def brute_force(points, idx, k):
    """Rows of the k points q != p with the smallest (d2, q), d2 in float64 as documented."""
    n = points.shape[0]
    nbr = np.empty((len(idx), k), np.int64)
    d2 = np.empty((len(idx), k))
    for r, p in enumerate(idx):
        x = points - points[p]
        d = x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1] + x[:, 2] * x[:, 2]
        order = np.lexsort((np.arange(n), d))
        order = order[order != p][:k]
        nbr[r] = order
        d2[r] = d[order]
    return nbr, d2


def cloud(kind, rng):
    if kind == "grid":  # every distance shared by many points: ties everywhere
        g = np.arange(14, dtype=np.float64)
        pts = np.stack(np.meshgrid(g, g, g[:8], indexing="ij"), -1).reshape(-1, 3)
        return pts[rng.permutation(len(pts))]
    if kind == "duplicates":  # a few positions, each held by many points
        base = rng.uniform(-1, 1, (40, 3))
        return base[rng.integers(0, 40, 1600)]
    if kind == "grid_sheet":  # a flat grid plus copies of some of its points
        g = np.arange(40, dtype=np.float64) * 0.5
        pts = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
        pts = np.c_[pts, np.zeros(len(pts))]
        return np.r_[pts, pts[rng.integers(0, len(pts), 300)]]
    # a noisy surface, the common case
    u = rng.uniform(0, 2 * np.pi, (2000, 2))
    return np.c_[np.cos(u[:, 0]) * (2 + np.cos(u[:, 1])), np.sin(u[:, 0]) * (2 + np.cos(u[:, 1])),
                 np.sin(u[:, 1])] + 0.01 * rng.normal(size=(2000, 3))


KINDS = ["grid", "duplicates", "grid_sheet", "surface"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("k", [1, 24, 48, 384])
@pytest.mark.parametrize("order", ["coherent", "random", "reversed"])
def test_batch_queries_match_brute_force(kind, k, order):
    rng = np.random.default_rng(len(kind) * 1000 + k)
    pts = cloud(kind, rng)
    n = len(pts)
    tree = build_tree(pts)
    if order == "coherent":  # tree order: every query seeded by a near one
        idx = np.argsort(tree[1])[::3].astype(np.int64)
    elif order == "random":  # consecutive queries far apart: seeds far too wide or too tight
        idx = rng.choice(n, size=min(n, 400), replace=False).astype(np.int64)
    else:
        idx = np.arange(n - 1, -1, -5, dtype=np.int64)
    ref_nbr, ref_d2 = brute_force(pts, idx, k)
    nbr, d2 = knn_rows(pts, tree, idx, k)
    assert np.array_equal(nbr, ref_nbr)
    assert np.array_equal(d2, ref_d2)
    pnbr = np.empty((len(idx), k), np.int32)
    pd2 = np.empty((len(idx), k))
    knn_parallel(pts, tree, idx, k, pnbr, pd2)
    assert np.array_equal(pnbr, ref_nbr)
    assert np.array_equal(pd2, ref_d2)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("k", [1, 24, 40, 384])
def test_any_starting_radii_give_the_exact_answer(kind, k):
    # radii of zero, far too small, about right and huge: a radius only saves time
    rng = np.random.default_rng(k + 7)
    pts = cloud(kind, rng)
    tree = build_tree(pts)
    idx = rng.choice(len(pts), 60, replace=False)
    ref_nbr, ref_d2 = brute_force(pts, idx, k)
    snode, sdist, bufd, bufi = knn_scratch(tree, k)
    ds = np.empty(k)
    ids = np.empty(k, np.int64)
    for r, p in enumerate(idx):
        kth = ref_d2[r, -1]
        for guess, safe in ((0.0, 0.0), (0.5 * kth, 0.9 * kth), (kth, kth), (0.0, kth),
                            (kth * 1.01, 4.0 * kth + 1.0), (np.inf, np.inf), (1e300, 1e300)):
            assert knn_point_within(pts, tree, p, k, guess, safe, ds, ids, snode, sdist, bufd,
                                    bufi) == k
            assert ids.tolist() == ref_nbr[r].tolist(), (p, guess, safe)
            assert np.array_equal(ds, ref_d2[r])


def test_scratch_for_a_larger_k_serves_smaller_queries():
    # callers size the scratch once for their largest k (e.g. fitting.shifted)
    rng = np.random.default_rng(3)
    pts = cloud("grid", rng)
    tree = build_tree(pts)
    scratch = knn_scratch(tree, 400)
    ds = np.empty(400)
    ids = np.empty(400, np.int64)
    for k in (1, 5, 33, 100, 400):
        ref_nbr, ref_d2 = brute_force(pts, [17], k)
        assert knn_point_within(pts, tree, 17, k, np.inf, np.inf, ds, ids, *scratch) == k
        assert ids[:k].tolist() == ref_nbr[0].tolist()
        assert np.array_equal(ds[:k], ref_d2[0])


def test_more_neighbors_asked_than_other_points():
    pts = np.random.default_rng(0).uniform(size=(30, 3))
    tree = build_tree(pts)
    for k in (29, 40):
        snode, sdist, bufd, bufi = knn_scratch(tree, k)
        ds = np.empty(k)
        ids = np.empty(k, np.int64)
        assert knn_point_within(pts, tree, 3, k, 0.01, 0.02, ds, ids, snode, sdist, bufd,
                                bufi) == 29
        assert ids[:29].tolist() == brute_force(pts, [3], 29)[0][0].tolist()


@pytest.mark.parametrize("leaf", [1, 4, 32, 200])
def test_leaf_size_does_not_change_the_answer(leaf):
    rng = np.random.default_rng(leaf)
    pts = cloud("grid_sheet", rng)
    idx = np.arange(0, len(pts), 7, dtype=np.int64)
    ref = brute_force(pts, idx, 60)
    got = knn_rows(pts, build_tree(pts, leaf), idx, 60)
    assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
