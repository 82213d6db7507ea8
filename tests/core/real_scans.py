"""Decimated real scans for tests: still single-view range scans, small enough to be quick."""

from __future__ import annotations

import numpy as np

import curvature
from curvature.cloud import PointCloud


def decimated(path, step: int) -> PointCloud:
    """``path`` read and thinned: every ``step``-th row and column of an organized grid, or
    every ``step``-th point otherwise; viewpoint and attributes kept."""
    cloud = curvature.read(path)
    index = cloud.input_index()
    if cloud.grid is not None:
        width = cloud.grid[0]
        keep = ((index // width) % step == 0) & ((index % width) % step == 0)
    else:
        keep = index % step == 0
    return PointCloud(points=cloud.points[keep], index=index[keep], grid=cloud.grid,
                      properties={k: v[keep] for k, v in cloud.properties.items()},
                      viewpoint=cloud.viewpoint, viewpoint_source=cloud.viewpoint_source,
                      source=cloud.source)


def sign_agreement(a: np.ndarray, b: np.ndarray) -> float:
    """Share of points where two (n, 3) normal fields point the same way (both finite)."""
    dot = np.einsum("ij,ij->i", a, b)
    ok = np.isfinite(dot)
    return float(np.mean(dot[ok] > 0))
