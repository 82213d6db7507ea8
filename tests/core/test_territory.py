"""Territory Claiming (DESIGN.md 4.1) against a plain-Python reference and hand-built cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from curvature.errors import ParameterError
from curvature.neighborhoods import FINDERS, neighbors
from curvature.neighborhoods.kdtree import build_tree, knn_rows
from curvature.neighborhoods.territory import TerritoryFinder, beta_values

# ---------------------------------------------------------------- plain reference


def ref_sorted_pool(points, p):
    """All points but p, by increasing squared distance, ties by index (float64 as the doc)."""
    x = points - points[p]
    d2 = x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1] + x[:, 2] * x[:, 2]
    pool = sorted((i for i in range(len(points)) if i != p), key=lambda i: (d2[i], i))
    return pool, x, d2


def ref_claims(a, x, beta):
    aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
    ax = a[0] * x[0] + a[1] * x[1] + a[2] * x[2]
    xx = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
    return aa < beta * ax and aa - (2 - beta) * ax + (1 - beta) * xx < 0


def ref_one_beta(cands, x, beta):
    accepted = []
    for c in cands:
        if not any(ref_claims(x[q], x[c], beta) for q in accepted):
            accepted.append(c)
    return accepted


def ref_tc(points, p, candidates=30, beta_min=1.0, beta_max=2.0, beta_step=0.1,
           min_neighbors=10):
    """Steps 1-4 of DESIGN.md 4.1, one beta at a time, one ring at a time."""
    pool, x, d2 = ref_sorted_pool(points, p)
    betas = []
    i = 0
    while round(beta_min + i * beta_step, 10) <= round(beta_max, 10):
        betas.append(round(beta_min + i * beta_step, 10))
        i += 1
    gathered = []
    while len(gathered) < min_neighbors:
        pool = [i for i in pool if i not in gathered]
        cands = pool[:candidates]
        if not cands:
            break
        best, best_mean = None, None
        for beta in betas:  # increasing, so "<=" hands ties to the larger beta
            acc = ref_one_beta(cands, x, beta)
            mean = sum(math.sqrt(d2[i]) for i in acc) / len(acc)
            if best is None or mean <= best_mean:
                best, best_mean = acc, mean
        gathered += best
    return gathered


def tc_of(points, p, **params):
    finder = TerritoryFinder(np.asarray(points, dtype=np.float64), **params)
    return finder.query(np.array([p]))[0].tolist()


# ---------------------------------------------------------------- against the reference


def test_registered():
    assert FINDERS["tc"] is TerritoryFinder


def test_candidates_are_exact_nearest_with_index_ties():
    rng = np.random.default_rng(3)
    # a grid with triplicated points: many exact distance ties
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(5.0), [0.0, 1.0]), -1).reshape(-1, 3)
    for pts in (np.repeat(g, 3, axis=0), rng.normal(size=(500, 3))):
        tree = build_tree(pts)
        nbr, d2 = knn_rows(pts, tree, np.arange(len(pts)), 17)
        for p in range(0, len(pts), 7):
            pool, _, dd = ref_sorted_pool(pts, p)
            assert nbr[p].tolist() == pool[:17]
            assert np.array_equal(d2[p], dd[pool[:17]])


def test_nearest_on_a_deep_tree():
    # clusters at wildly different scales: a deep, unbalanced tree that outgrows its first
    # node arrays (leaf size 1)
    rng = np.random.default_rng(8)
    pts = np.r_[rng.normal(size=(3000, 3)) * 1e-6, rng.normal(size=(50, 3)) * 1e3,
                2.0 ** -np.arange(600)[:, None] * np.ones((1, 3))]
    tree = build_tree(pts, 1)
    assert tree[9] > 100
    nbr, _ = knn_rows(pts, tree, np.arange(len(pts)), 8)
    for p in range(0, len(pts), 29):
        assert nbr[p].tolist() == ref_sorted_pool(pts, p)[0][:8]


@pytest.mark.parametrize("seed", range(200))
def test_matches_reference_on_random_clouds(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(12, 80))
    kind = seed % 3
    if kind == 0:
        pts = rng.uniform(-1, 1, (n, 3))
    elif kind == 1:  # noisy sheet: the surface case
        pts = np.c_[rng.uniform(-1, 1, (n, 2)), 0.05 * rng.normal(size=n)]
    else:
        pts = rng.normal(size=(n, 3)) * [3.0, 1.0, 0.2]
    ncand = int(rng.integers(4, 31))
    params = dict(candidates=ncand, min_neighbors=int(rng.integers(1, ncand + 1)))
    if seed % 4 == 1:
        params.update(beta_min=0.5, beta_max=2.5, beta_step=0.25)
    elif seed % 4 == 2:
        params.update(beta_min=1.3, beta_max=1.3)
    finder = TerritoryFinder(pts, **params)
    queries = rng.choice(n, size=min(n, 6), replace=False)
    got = finder.query(queries)
    for j, p in enumerate(queries):
        assert got[j].tolist() == ref_tc(pts, int(p), **params), (seed, int(p), params)


@pytest.mark.parametrize("params", [{}, {"min_neighbors": 10, "candidates": 30}])
def test_default_and_paper_parameters_match_reference(params):
    rng = np.random.default_rng(11)
    pts = np.c_[rng.uniform(-1, 1, (400, 2)), 0.02 * rng.normal(size=400)]
    finder = TerritoryFinder(pts, **params)
    queries = np.arange(0, 400, 9)
    got = finder.query(queries)
    for j, p in enumerate(queries):
        assert got[j].tolist() == ref_tc(pts, int(p), **dict(finder.params))


# ---------------------------------------------------------------- hand-built cases


FIG1 = [
    (0.0, 0.0, 0.0),  # 0: p
    (1.0, 0.0, 0.0),  # 1: nearest, always accepted
    (0.0, 1.1, 0.0),  # 2: at right angles to 1: a.x = 0, never claimed
    (-1.2, 0.0, 0.0),  # 3: opposite side
    (0.0, -1.3, 0.0),  # 4
    (0.9, 1.0, 0.0),  # 5: between 1 and 2; claimed by 1 only for beta > 1.11, by 2 for > 1.15
    (2.0, 0.0, 0.0),  # 6: straight behind 1: claimed by 1 for every beta > 0.5
    (1.5, 1.5, 0.0),  # 7: behind 1 and 2: claimed by 1 for beta > 0.83
    (-2.5, 0.2, 0.0),  # 8: behind 3: claimed by 3 for beta > 0.53
]


def test_fig1_like_configuration():
    # beta 1.0 and 1.1 accept {1,2,3,4,5} (mean 1.189), beta >= 1.2 accept {1,2,3,4}
    # (mean 1.15): the smaller mean wins; 6, 7, 8 are inside territories for all betas.
    assert tc_of(FIG1, 0, candidates=8, min_neighbors=4) == [1, 2, 3, 4]
    # with only beta in {1.0, 1.1}, point 5 is outside every territory
    assert tc_of(FIG1, 0, candidates=8, min_neighbors=4, beta_max=1.1) == [1, 2, 3, 4, 5]
    # the Gabriel test alone (beta = 1) and the relative-neighborhood test alone (beta = 2)
    assert tc_of(FIG1, 0, candidates=8, min_neighbors=4, beta_min=1.0,
                 beta_max=1.0) == [1, 2, 3, 4, 5]
    assert tc_of(FIG1, 0, candidates=8, min_neighbors=4, beta_min=2.0,
                 beta_max=2.0) == [1, 2, 3, 4]


def test_lune_is_strict():
    # x = (5, 12): |a|^2 = 25 = 1.0 * a.x and the second expression is exactly 0 at beta = 1
    pts = [(0, 0, 0), (5, 0, 0), (5, 12, 0)]
    assert tc_of(pts, 0, candidates=2, min_neighbors=2, beta_max=1.0) == [1, 2]
    assert tc_of(pts, 0, candidates=2, min_neighbors=1, beta_min=1.1, beta_max=1.1) == [1]
    # beta = 2, a = (2,0), x = (1,2): |a|^2 = 4 = beta (a.x) exactly, second test holds (4 < 5)
    rng2 = dict(candidates=2, min_neighbors=1, beta_min=2.0, beta_max=2.0)
    assert tc_of([(0, 0, 0), (2, 0, 0), (1, 2, 0)], 0, **rng2) == [1, 2]
    assert tc_of([(0, 0, 0), (2, 0, 0), (1.01, 2, 0)], 0, **rng2) == [1]
    # beta = 2, a = (3,4), x = (5,0): first test holds (25 < 30), second is exactly 0
    assert tc_of([(0, 0, 0), (3, 4, 0), (5, 0, 0)], 0, **rng2) == [1, 2]
    assert tc_of([(0, 0, 0), (3, 4, 0), (5.01, 0, 0)], 0, **rng2) == [1]


def test_beta_tie_goes_to_larger_beta():
    # beta 1.0-1.3: {(4,0), (3,-4), (0,6)} at distances 4, 5, 6: mean 5.
    # beta 1.4-2.0: (4,0) claims (3,-4) (threshold 4/3): {(4,0), (0,6)}: mean 5 as well.
    pts = [(0, 0, 0), (4, 0, 0), (3, -4, 0), (0, 6, 0), (23, 0, 0)]
    assert tc_of(pts, 0, candidates=4, min_neighbors=1) == [1, 3]
    assert ref_tc(np.asarray(pts, float), 0, candidates=4, min_neighbors=1) == [1, 3]
    assert tc_of(pts, 0, candidates=4, min_neighbors=1, beta_max=1.3) == [1, 2, 3]


def test_rings_grow_from_the_remaining_pool():
    # p at 0 on a line; 1, 2, 3 on one side, -1.5, -2.5, -3.5 on the other.
    xs = [0.0, 1.0, 2.0, 3.0, 4.0, -1.5, -2.5, -3.5, -4.5]
    pts = [(v, 0.0, 0.0) for v in xs]
    # ring 1 (4 candidates: 1, -1.5, 2, -2.5): 1 and -1.5 claim what lies behind them
    assert tc_of(pts, 0, candidates=4, min_neighbors=2) == [1, 5]
    # ring 2 takes its candidates from the pool without 1 and -1.5; the rejected 2 and -2.5
    # come back, and the points of ring 1 do not claim territory any more
    assert tc_of(pts, 0, candidates=4, min_neighbors=4) == [1, 5, 2, 6]
    assert tc_of(pts, 0, candidates=4, min_neighbors=3) == [1, 5, 2, 6]
    assert tc_of(pts, 0, candidates=5, min_neighbors=5) == [1, 5, 2, 6, 3, 7]


def test_pool_runs_out():
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(12, 3))
    got = tc_of(pts, 4, candidates=40, min_neighbors=40)
    assert sorted(got) == [i for i in range(12) if i != 4]
    assert got == ref_tc(pts, 4, candidates=40, min_neighbors=40)


def test_duplicates_of_the_query_point():
    pts = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [2, 0, 0]], float)
    got = tc_of(pts, 0, candidates=5, min_neighbors=4)
    assert got == ref_tc(pts, 0, candidates=5, min_neighbors=4)
    assert 0 not in got and 1 in got


# ---------------------------------------------------------------- on a torus


def torus(n, seed=0, R=2.0, r=1.0):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 2 * np.pi, (2, n))
    return np.c_[(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)]


def test_torus_sizes():
    pts = torus(10_000)
    params = TerritoryFinder(pts).params  # the defaults
    low, cand = params["min_neighbors"], params["candidates"]
    nb = neighbors(pts, "tc")
    sizes = nb.sizes()
    assert len(nb) == 10_000
    assert sizes.min() >= low
    assert low <= sizes.mean() <= 1.6 * low
    assert sizes.max() <= cand + low - 1
    for j in range(0, 10_000, 97):
        row = nb[j]
        assert j not in row
        assert len(set(row.tolist())) == row.size


def test_chunking_and_workers_do_not_change_results():
    pts = torus(3000, seed=1)
    pts += np.random.default_rng(2).normal(scale=0.01, size=pts.shape)
    finder = TerritoryFinder(pts, candidates=20, min_neighbors=8)
    whole = finder.query(np.arange(3000), workers=1)
    order = np.random.default_rng(4).permutation(3000)
    for workers in (1, 2):
        parts = [TerritoryFinder(pts, candidates=20, min_neighbors=8).query(c, workers=workers)
                 for c in np.array_split(order, 7)]
        for chunk, part in zip(np.array_split(order, 7), parts, strict=True):
            for j, p in enumerate(chunk):
                assert np.array_equal(part[j], whole[p])
    again = finder.query(np.arange(3000), workers=2)
    assert np.array_equal(again.indptr, whole.indptr)
    assert np.array_equal(again.indices, whole.indices)


def test_empty_query():
    nb = TerritoryFinder(torus(50)).query(np.zeros(0, np.int64))
    assert len(nb) == 0 and nb.indices.size == 0


# ---------------------------------------------------------------- parameters


def test_beta_values():
    assert beta_values(1.0, 2.0, 0.1).tolist() == [1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7, 1.8,
                                                   1.9, 2.0]
    assert beta_values(1.0, 1.95, 0.1).size == 10
    assert beta_values(1.5, 1.5, 0.1).tolist() == [1.5]


@pytest.mark.parametrize("params, message", [
    (dict(beta_min=2.5, beta_max=2.0), "method 'tc': beta_min (2.5) must be <= beta_max (2.0)"),
    (dict(candidates=8), "method 'tc': candidates (8) must be >= min_neighbors (24)"),
    (dict(beta_min=1.0, beta_max=9.0, beta_step=0.01), "more than 62 beta values"),
    (dict(candidates=0), "parameter 'candidates' must be >= 2"),
    (dict(beta_step=0), "parameter 'beta_step' must be >= 0.001"),
    (dict(min_neighbors=2.5), "parameter 'min_neighbors' must be a whole number"),
    (dict(radius=1.0), "unknown parameter(s) ['radius']"),
])
def test_parameter_errors(params, message):
    with pytest.raises(ParameterError) as err:
        TerritoryFinder(torus(20), **params)
    assert message in str(err.value)
