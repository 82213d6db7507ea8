"""The outlier tests of the default estimator (curvature.fitting.outliers) on their own."""

from __future__ import annotations

import numpy as np

from curvature.fitting.outliers import ISOLATION_K, isolated, off_sheets, sheet_limit
from curvature.neighborhoods.kdtree import build_tree, knn_parallel


def _isolation_reach(points, tree, rows):
    d2 = np.empty((rows.size, ISOLATION_K))
    knn_parallel(points, tree, rows, ISOLATION_K, np.empty((rows.size, ISOLATION_K), np.int64),
                 d2)
    return np.sqrt(d2[:, -1])


def test_isolated_points_are_flagged_whether_every_point_or_some_are_tested():
    rng = np.random.default_rng(2)
    g = np.arange(60) * 0.1
    plane = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    plane = np.c_[plane + rng.normal(0, 0.01, plane.shape), rng.normal(0, 0.005, len(plane))]
    lone = np.array([[3.0, 3.0, 2.0], [1.0, 5.0, -1.5], [7.5, 7.5, 0.0]])  # far off the sheet
    pts = np.ascontiguousarray(np.r_[plane, lone])
    tree = build_tree(pts)
    every = np.arange(len(pts), dtype=np.int64)
    flags = np.zeros(len(pts), bool)
    isolated(pts, tree, _isolation_reach(pts, tree, every), flags)
    np.testing.assert_array_equal(np.flatnonzero(flags), len(plane) + np.arange(3))
    # a subset (as the dense branch tests only its thinned points): the same verdicts there,
    # the neighbors' reach measured on demand
    rows = np.r_[every[:len(plane):3], every[len(plane):]]
    some = np.zeros(rows.size, bool)
    isolated(pts, tree, _isolation_reach(pts, tree, rows), some, rows=rows)
    np.testing.assert_array_equal(some, flags[rows])


def test_points_inside_a_thin_wall_or_past_a_wedge_tip_lie_on_no_sheet():
    # Two noisy faces 3 spacings apart (spacing 0.1, noise 0.005 across them); a point
    # between them is within 0.15 of both faces' centroid plane, so the offset test cannot
    # see it, but it lies on neither face. Past the tip of a wedge (faces at +-6 degrees
    # meeting at x = 15.4) the faces' planes, carried on, pass near a point in its middle
    # plane: only neighbors near enough count.
    rng = np.random.default_rng(3)
    g = np.arange(60) * 0.1
    uv = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    noise = 0.005
    lower = np.c_[uv, rng.normal(0.0, noise, len(uv))]
    upper = np.c_[uv, 0.3 + rng.normal(0.0, noise, len(uv))]
    inside = np.array([[3.0, 3.0, 0.15], [1.05, 4.55, 0.13], [4.2, 1.7, 0.165]])
    slope = np.tan(np.radians(6.0))
    x = uv[:, 0] * 0.9 + 10.0  # a wedge from x = 10 (1.1 thick) to x = 15.3 (0.02)
    wedge = np.r_[np.c_[x, uv[:, 1], (15.4 - x) * slope],
                  np.c_[x, uv[:, 1], -(15.4 - x) * slope]]
    wedge[:, 2] += rng.normal(0.0, noise, len(wedge))
    past = np.array([[15.75, 3.0, 0.0], [15.7, 1.2, 0.01]])  # 4 to 5 spacings past it
    pts = np.ascontiguousarray(np.r_[lower, upper, wedge, inside, past])
    up = np.array([0.0, 0.0, 1.0])
    tilt = np.array([slope, 0.0, 1.0]) / np.hypot(slope, 1.0)
    normals = np.r_[np.tile(up, (2 * len(uv), 1)), np.tile(tilt, (len(uv), 1)),
                    np.tile(tilt * [1, 1, -1], (len(uv), 1)), np.full((5, 3), np.nan)]
    tree = build_tree(pts)
    every = np.arange(len(pts), dtype=np.int64)
    nbr = np.empty((len(pts), 8), np.int64)  # the point itself not listed
    knn_parallel(pts, tree, every, 8, nbr, np.empty((len(pts), 8)))
    reach = _isolation_reach(pts, tree, every)
    flags = np.zeros(len(pts), bool)
    limit = sheet_limit(noise, 0.3)  # the plan's spacing: about its 24th neighbor's distance
    off_sheets(pts, every, nbr, normals, reach, np.zeros(len(pts), bool), limit, flags)
    np.testing.assert_array_equal(np.flatnonzero(flags), len(pts) - 5 + np.arange(5))
    # a point whose neighbors have no plane (degenerate PCA) is not judged
    lone = normals.copy()
    lone[nbr[1000]] = np.nan
    off_sheets(pts, every, nbr, lone, reach, np.zeros(len(pts), bool), limit, flags)
    assert not flags[1000] and flags[-5:].all()
    # without the cloud's noise there is no test
    assert sheet_limit(0.0, 0.3) == np.inf and sheet_limit(np.nan, 0.3) == np.inf
