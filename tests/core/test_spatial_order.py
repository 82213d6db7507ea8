"""Z-order permutation used by the pipeline for memory locality."""

import numpy as np
import pytest

from curvature.pipeline.spatial_order import inverse_permutation, morton_order


def test_morton_order_is_a_permutation_and_local():
    rng = np.random.default_rng(0)
    pts = rng.random((20000, 3))
    order = morton_order(pts)
    assert np.array_equal(np.sort(order), np.arange(len(pts)))
    step = np.linalg.norm(np.diff(pts[order], axis=0), axis=1)
    random_step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    # Consecutive points along the curve are far closer than in random order.
    assert np.median(step) < 0.1 * np.median(random_step)


def test_morton_order_of_a_2x2x2_grid():
    grid = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    shuffled = grid[::-1]
    # Interleaved bits x0 y0 z0: key = x + 2y + 4z, so the curve visits the grid in that order.
    np.testing.assert_array_equal(shuffled[morton_order(shuffled)], grid)


def test_degenerate_cloud_keeps_input_order():
    pts = np.zeros((15, 3))
    np.testing.assert_array_equal(morton_order(pts), np.arange(15))


def test_inverse_permutation():
    order = np.random.default_rng(1).permutation(100)
    inv = inverse_permutation(order)
    np.testing.assert_array_equal(order[inv], np.arange(100))
    np.testing.assert_array_equal(inv[order], np.arange(100))


def test_bounding_box_is_numpys_min_and_max():
    from curvature.bounds import BOX_BLOCK, bounding_box

    for n in (1, 7, BOX_BLOCK, BOX_BLOCK + 1, 3 * BOX_BLOCK + 5):
        pts = np.random.default_rng(n).normal(size=(n, 3)) * [1.0, 1e-3, 1e3]
        lo, hi = bounding_box(pts)
        np.testing.assert_array_equal(lo, pts.min(axis=0))
        np.testing.assert_array_equal(hi, pts.max(axis=0))
        lo, hi = bounding_box(np.asfortranarray(pts[::-1]))  # any layout
        np.testing.assert_array_equal(lo, pts.min(axis=0))
    with pytest.raises(ValueError):
        bounding_box(np.empty((0, 3)))


def test_inside_box_is_the_closed_box():
    from curvature.bounds import inside_box

    pts = np.random.default_rng(3).normal(size=(50_000, 3))
    pts[:3] = [[0.5, 0.0, 0.0], [-0.5, 0.3, 2.0], [0.5000001, 0.0, 0.0]]  # on faces, just out
    lo, hi = np.array([-0.5, -1.0, -0.2]), np.array([0.5, 0.3, 2.0])
    got = inside_box(pts, lo, hi)
    np.testing.assert_array_equal(got, np.all((pts >= lo) & (pts <= hi), axis=1))
    assert got[:3].tolist() == [True, True, False]
    assert inside_box(pts, np.full(3, -np.inf), np.full(3, np.inf)).all()
