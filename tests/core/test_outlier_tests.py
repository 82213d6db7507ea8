"""The outlier tests of the default estimator (curvature.fitting.outliers) on their own."""

from __future__ import annotations

import numpy as np

from curvature.fitting.outliers import ISOLATION_K, isolated
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
