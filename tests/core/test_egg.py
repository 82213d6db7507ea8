"""Elliptic Gabriel Graph neighbors (DESIGN.md 4.2) against a plain reference and geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from curvature.errors import ParameterError
from curvature.neighborhoods import FINDERS, neighbors
from curvature.neighborhoods.egg import EggFinder, alpha_values

# ---------------------------------------------------------------- plain reference


def ref_blocks(xr, xq, alpha):
    """r blocks q (coordinates relative to p), as DESIGN.md 4.2 words it."""
    length = math.sqrt(xq[0] * xq[0] + xq[1] * xq[1] + xq[2] * xq[2])
    if length == 0:
        return False
    d = 0.5 * length
    e = [xq[0] / length, xq[1] / length, xq[2] / length]
    rm = [xr[i] - 0.5 * xq[i] for i in range(3)]
    u = rm[0] * e[0] + rm[1] * e[1] + rm[2] * e[2]
    w2 = max(rm[0] * rm[0] + rm[1] * rm[1] + rm[2] * rm[2] - u * u, 0.0)
    return u * u + w2 / (alpha * alpha) < d * d


def ref_egg(points, p, candidates=30, alpha_start=0.7, alpha_step=0.05, min_neighbors=10):
    x = points - points[p]
    d2 = x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1] + x[:, 2] * x[:, 2]
    pool = sorted((i for i in range(len(points)) if i != p), key=lambda i: (d2[i], i))
    cands = pool[:candidates]
    alphas = []
    i = 0
    while round(alpha_start - i * alpha_step, 10) >= round(alpha_step, 10):
        alphas.append(round(alpha_start - i * alpha_step, 10))
        i += 1
    for alpha in alphas:
        found = [q for j, q in enumerate(cands)
                 if not any(ref_blocks(x[r], x[q], alpha) for r in cands[:j])]
        if len(found) >= min_neighbors:
            break
    return found


def egg_of(points, p, **params):
    return EggFinder(np.asarray(points, dtype=np.float64), **params).query(
        np.array([p]))[0].tolist()


def test_registered():
    assert FINDERS["egg"] is EggFinder


@pytest.mark.parametrize("seed", range(120))
def test_matches_reference_on_random_clouds(seed):
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(12, 70))
    if seed % 2:
        pts = np.c_[rng.uniform(-1, 1, (n, 2)), 0.05 * rng.normal(size=n)]
    else:
        pts = rng.normal(size=(n, 3))
    ncand = int(rng.integers(3, 31))
    params = dict(candidates=ncand, min_neighbors=int(rng.integers(1, ncand + 1)))
    if seed % 3 == 1:
        params.update(alpha_start=1.0, alpha_step=0.1)
    elif seed % 3 == 2:
        params.update(alpha_start=0.35, alpha_step=0.03)
    finder = EggFinder(pts, **params)
    queries = rng.choice(n, size=min(n, 6), replace=False)
    got = finder.query(queries)
    for j, p in enumerate(queries):
        assert got[j].tolist() == ref_egg(pts, int(p), **params), (seed, int(p), params)


def test_spheroid_against_focal_definition():
    # prolate spheroid with semi-axes d (along pq) and alpha*d: inside iff the distances to
    # the foci m +- f e, f = d sqrt(1 - alpha^2), add up to less than 2d
    rng = np.random.default_rng(7)
    alpha = 0.6
    checked = 0
    for _ in range(400):
        p, q = rng.normal(size=(2, 3))
        m, d = (p + q) / 2, np.linalg.norm(q - p) / 2
        e = (q - p) / (2 * d)
        f = d * math.sqrt(1 - alpha * alpha)
        r = m + rng.normal(size=3) * d * 0.6
        s = np.linalg.norm(r - (m + f * e)) + np.linalg.norm(r - (m - f * e))
        if abs(s - 2 * d) < 1e-9 * d:
            continue
        pts = np.array([p, q, r])
        got = egg_of(pts, 0, candidates=2, min_neighbors=2, alpha_start=alpha, alpha_step=alpha)
        assert (1 in got) == (s >= 2 * d)
        checked += 1
    assert checked > 350


# ---------------------------------------------------------------- the alpha schedule


def test_alpha_values():
    a = alpha_values(0.7, 0.05)
    assert a.size == 14 and a[0] == 0.7 and a[-1] == 0.05
    assert np.all(np.diff(a) < 0)
    assert alpha_values(0.72, 0.05)[-1] == 0.07
    assert alpha_values(0.3, 0.3).tolist() == [0.3]


SCHEDULE = [
    (0.0, 0.0, 0.0),  # 0: p
    (1.0, 0.0, 0.0),  # 1: nearest, nothing can block it
    (2.0, 0.3, 0.0),  # 2: blocked by 1 for alpha > 0.1467
    (3.0, 0.0, 0.0),  # 3: 1 lies on the segment: blocked for every alpha
    (2.5, -0.22, 0.0),  # 4: blocked by 1 for alpha > 0.0714
]


def test_alpha_is_lowered_until_enough():
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=1) == [1]  # alpha 0.7
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=2) == [1, 2]  # alpha 0.10
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=3) == [1, 2, 4]  # alpha 0.05
    # never enough: the set of the last alpha (= alpha_step)
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=4) == [1, 2, 4]
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=4, alpha_step=0.1) == [1, 2]
    assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=1, alpha_start=0.1) == [1, 2]
    for mn in range(1, 5):
        assert egg_of(SCHEDULE, 0, candidates=4, min_neighbors=mn) == ref_egg(
            np.array(SCHEDULE), 0, candidates=4, min_neighbors=mn)


def test_rejected_candidates_block_too():
    # 1 blocks 2, and 2 (not a neighbor) blocks 3, which 1 alone would not block
    pts = [(0, 0, 0), (0.62, 0, 0.625), (1.5, 0, 0.6), (3.0, 0, 0)]
    one = dict(candidates=3, min_neighbors=1, alpha_start=0.5, alpha_step=0.5)
    assert egg_of(pts, 0, **one) == [1]
    assert egg_of([pts[0], pts[1], pts[3]], 0, candidates=2, min_neighbors=1,
                  alpha_start=0.5, alpha_step=0.5) == [1, 2]


# ---------------------------------------------------------------- sizes and determinism


def torus(n, seed=0, R=2.0, r=1.0):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 2 * np.pi, (2, n))
    return np.c_[(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)]


def test_torus_sizes():
    pts = torus(10_000)
    params = EggFinder(pts).params  # the defaults: at least min_neighbors of the candidates
    nb = neighbors(pts, "egg")
    sizes = nb.sizes()
    assert sizes.min() >= params["min_neighbors"] and sizes.max() <= params["candidates"]
    assert params["min_neighbors"] <= sizes.mean() <= 2 * params["min_neighbors"]
    for j in range(0, 10_000, 101):
        assert j not in nb[j]


def test_chunking_and_workers_do_not_change_results():
    pts = torus(3000, seed=1)
    pts += np.random.default_rng(2).normal(scale=0.01, size=pts.shape)
    whole = EggFinder(pts).query(np.arange(3000))
    order = np.random.default_rng(4).permutation(3000)
    for workers in (1, 2):
        finder = EggFinder(pts)
        for chunk in np.array_split(order, 5):
            part = finder.query(chunk, workers=workers)
            for j, p in enumerate(chunk):
                assert np.array_equal(part[j], whole[p])


@pytest.mark.parametrize("params, message", [
    (dict(alpha_step=0.8), "method 'egg': alpha_step (0.8) must be <= alpha_start (0.7)"),
    (dict(candidates=8), "method 'egg': candidates (8) must be >= min_neighbors (24)"),
    (dict(alpha_start=1.5), "parameter 'alpha_start' must be <= 1.0"),
    (dict(alpha_step=0.0), "parameter 'alpha_step' must be >= 0.001"),
    (dict(candidates="many"), "parameter 'candidates' must be int"),
])
def test_parameter_errors(params, message):
    with pytest.raises(ParameterError) as err:
        EggFinder(torus(20), **params)
    assert message in str(err.value)
