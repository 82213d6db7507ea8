"""The default's fits keep to their own face of a thin wall (parallel_sheets.own_sheet_lists)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from curvature.fitting.parallel_sheets import own_sheet_lists


def _kept(points, anchors, k, normal, test=None, excluded=None):
    """Each anchor's k nearest (itself left out) and which of them own_sheet_lists keeps."""
    _, nbr = cKDTree(points).query(points[anchors], k + 1)
    nbr = np.ascontiguousarray(nbr[:, 1:])
    keep = np.empty(nbr.size, bool)
    test = np.ones(anchors.size, bool) if test is None else test
    excluded = np.zeros(len(points), bool) if excluded is None else excluded
    own_sheet_lists(points, anchors, np.tile(normal, (len(points), 1)),
                    np.arange(0, (anchors.size + 1) * k, k, dtype=np.int64), nbr.ravel(), test,
                    excluded, keep)
    return nbr, keep.reshape(nbr.shape)


def _slab(rng, n=6000, thickness=0.06, noise=0.002):
    """Two noisy faces ``thickness`` apart over x, y in [0, 1] (cut open at the borders)."""
    xy = rng.uniform(0.0, 1.0, (n, 2))
    upper = rng.random(n) < 0.5
    z = np.where(upper, 0.5, -0.5) * thickness + rng.normal(0.0, noise, n)
    return np.ascontiguousarray(np.c_[xy, z]), upper


def test_a_list_at_a_thin_walls_open_border_keeps_only_the_anchors_face():
    # At the cut the nearest 384 points of a face point hold about 40 % of the other face;
    # measured: every other-face point left out, every own-face point kept, at all 40 anchors.
    rng = np.random.default_rng(4)
    pts, upper = _slab(rng)
    border = np.flatnonzero(pts[:, 0] < 0.01)[:40].astype(np.int64)
    nbr, keep = _kept(pts, border, 384, np.array([0.0, 0.0, 1.0]))
    same = upper[nbr] == upper[border][:, None]
    assert (~same).mean() > 0.2
    np.testing.assert_array_equal(keep, same)
    # untested anchors keep their lists whole
    _, whole = _kept(pts, border, 384, np.array([0.0, 0.0, 1.0]),
                     test=np.zeros(border.size, bool))
    assert whole.all()


def test_one_sheet_and_a_wedges_two_sheets_keep_their_lists():
    rng = np.random.default_rng(6)
    xy = rng.uniform(-1.0, 1.0, (6000, 2))
    side = rng.random(6000) < 0.5
    noise = rng.normal(0.0, 0.002, 6000)
    plane = np.ascontiguousarray(np.c_[xy, noise])
    # faces 12 degrees apart (the blade's wedge): two sheets, but not parallel
    wedge = np.ascontiguousarray(
        np.c_[xy, np.where(side, 1.0, -1.0) * (0.03 + np.tan(np.radians(6)) * xy[:, 0])
              + noise])
    up = np.array([0.0, 0.0, 1.0])
    anchors = np.flatnonzero(np.abs(xy[:, 0]) < 0.25)[:40].astype(np.int64)
    assert _kept(plane, anchors, 384, up)[1].all()
    assert _kept(wedge, anchors, 384, up)[1].all()


def test_an_outlier_inside_the_wall_takes_no_part_in_the_split_and_stays_listed():
    # Outliers spread through the wall's thickness fill the gap between the faces; left out
    # of the split (``excluded``) the faces are still told apart, and the outliers stay in
    # the lists (the fits leave them out on their own). 3,000 of them beside 6,000 face
    # points hide the gap (measured: 300 or 1,000 do not).
    rng = np.random.default_rng(8)
    pts, upper = _slab(rng)
    stray = np.c_[rng.uniform(0.0, 1.0, (3000, 2)), rng.uniform(-0.03, 0.03, 3000)]
    pts = np.ascontiguousarray(np.r_[pts, stray])
    excluded = np.r_[np.zeros(len(upper), bool), np.ones(3000, bool)]
    border = np.flatnonzero(pts[: len(upper), 0] < 0.01)[:40].astype(np.int64)
    up = np.array([0.0, 0.0, 1.0])
    nbr, keep = _kept(pts, border, 384, up, excluded=excluded)
    on = ~excluded[nbr]
    same = np.r_[upper, np.zeros(3000, bool)][nbr] == upper[border][:, None]
    np.testing.assert_array_equal(keep[on], same[on])
    assert keep[~on].all() and not keep.all()
    # not left out, they hide the gap and the lists stay whole
    assert _kept(pts, border, 384, up)[1].all()
