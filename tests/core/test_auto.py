"""The default estimator, method "auto": accuracy, the branch it takes, invariance, errors."""

from __future__ import annotations

import numpy as np
import pytest

import curvature
from curvature import synthetic
from curvature.estimators.auto import AutoPlan, AutoRun, grid_cells, plan_auto
from curvature.neighborhoods.kdtree import build_tree


def mean_errors(cloud, res) -> tuple[float, float]:
    m = cloud.interior
    assert np.all(res.status[m] == 0)
    return (float(np.mean(np.abs(res.k1 - cloud.k1)[m])),
            float(np.mean(np.abs(res.k2 - cloud.k2)[m])))


def relative_errors(cloud, res) -> tuple[float, float]:
    e1, e2 = mean_errors(cloud, res)
    m = cloud.interior
    # a zero principal curvature (cylinder) is measured against the other one
    s1, s2 = np.mean(np.abs(cloud.k1[m])), np.mean(np.abs(cloud.k2[m]))
    return e1 / s1, e2 / (s2 if s2 > 1e-9 * s1 else s1)


CLEAN = [
    ("sphere", {}, 0.01), ("cylinder", {}, 0.01), ("ellipsoid", {"axes": (3, 2, 1)}, 0.01),
    ("torus", {}, 0.03), ("bezier_patch", {}, 0.03),
]


@pytest.mark.parametrize("shape, kwargs, limit", CLEAN, ids=[c[0] for c in CLEAN])
def test_noise_free_shapes_within_issue_limits(shape, kwargs, limit):
    cloud = synthetic.make(shape, 10_000, seed=3, **kwargs)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    assert res.info["method"] == "auto" and res.info["fit"] == "implicit"
    assert res.info["plan"]["clean"] and res.info["plan"]["noise"] < 0.001
    rel = relative_errors(cloud, res)
    assert max(rel) <= limit, rel
    # 24 neighbors, 16 or 12 only where the 24-point fit is far from exact (none here mostly);
    # inside, no other size; by the Bezier patch's border a few (10 of 10,000) implicit fits
    # the height quadric does not confirm take the anchored fits (curvature.fitting.height_check)
    assert set(np.unique(res.neighbor_count[cloud.interior])) <= {12, 16, 24}
    assert np.mean(~np.isin(res.neighbor_count, [12, 16, 24])) < 0.002
    assert np.mean(res.neighbor_count == 24) > 0.9


# Issue 6: at most half of MeshLab APSS's mean |k1| / |k2| errors at 0.5 % BBD noise.
NOISY = [
    ("torus", {}, (0.050, 0.052)),
    ("ellipsoid", {"axes": (3, 2, 1)}, (0.081, 0.071)),
    ("sphere", {}, (0.1605, 0.1605)),
    ("bezier_patch", {}, (0.22, 0.22)),
]


@pytest.mark.parametrize("shape, kwargs, limit", NOISY, ids=[c[0] for c in NOISY])
def test_noisy_shapes_meet_half_of_apss(shape, kwargs, limit):
    cloud = synthetic.make(shape, 10_000, noise=0.5, seed=1, **kwargs)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    assert res.info["fit"] == "nfr" and not res.info["plan"]["clean"]
    e1, e2 = mean_errors(cloud, res)
    assert e1 <= limit[0] and e2 <= limit[1], (e1, e2)
    # each anchor keeps the least noisy fit that agrees with the noisier ones: on smooth
    # shapes mostly the tops, over 384, 768 and (noise above wide_noise) 1536 neighbors
    assert set(np.unique(res.neighbor_count)) <= {24, 48, 96, 192, 384, 768, 1536}
    assert np.mean(res.neighbor_count >= 384) > 0.5


@pytest.mark.parametrize("shape, kwargs, forced", [
    ("ellipsoid", {"axes": (3, 2, 1)}, 1e6), ("torus", {}, 0.0)], ids=["ellipsoid", "torus"])
def test_choosing_the_model_per_anchor_beats_either_model_alone(shape, kwargs, forced):
    # the cubic field alone flattens the ellipsoid's tips (k1 = 3); the quadric alone is biased
    # on the torus at 384 points; the misfit rule keeps the better one (docs/accuracy.md)
    cloud = synthetic.make(shape, 10_000, noise=0.1, seed=2, **kwargs)
    # at one scale (scale_gamma=0, 384 neighbors), so that the model rule is measured alone
    chosen = mean_errors(cloud, curvature.estimate(cloud.points, normals=cloud.normals,
                                                   k=384, scale_gamma=0.0))
    alone = mean_errors(cloud, curvature.estimate(cloud.points, normals=cloud.normals,
                                                  k=384, nfr_ratio=forced, scale_gamma=0.0))
    assert chosen[0] < 0.6 * alone[0], (chosen, alone)


def test_small_clouds_cap_the_neighborhood_at_a_share_of_the_cloud():
    # 2,000 points on the torus: 384 neighbors would span more than its tube (radius 1)
    cloud = synthetic.torus(2000, noise=0.1, seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    # twice 4 % of 2,000, and a fit over 80 among the candidates (smaller where a feature asks)
    assert res.neighbor_count.max() == 160
    assert np.any(res.neighbor_count == 80)
    capped = mean_errors(cloud, res)
    assert capped[0] < 0.06 and capped[1] < 0.06, capped
    uncapped = mean_errors(cloud, curvature.estimate(cloud.points, normals=cloud.normals,
                                                     max_share=1.0))
    # measured k1 and k2 0.026 and 0.037 against 0.032 and 0.019 (before the 96-point
    # circular rung 0.049 against 0.032 in k1; 0.126 against 0.042 before smaller Monge rungs
    # could replace a biased kept fit, 0.33 before the per-anchor scale picked smaller fits)
    assert sum(uncapped) > 1.15 * sum(capped), (capped, uncapped)
    # never below 48 (and 96) neighbors; clouds of 9,600 points and more keep k
    tiny = curvature.estimate(synthetic.torus(600, noise=0.3, seed=2).points)
    assert tiny.neighbor_count.max() == 96
    assert tiny.info["plan"]["points"] == 600


def test_k_is_the_largest_neighborhood_from_24_up():
    # k = 24 (the size knn users know, and the clean-cloud fit's) is accepted and honoured:
    # no fit uses more; fewer neighbors average less noise away
    cloud = synthetic.torus(10_000, noise=0.5, seed=1)
    errors = {}
    for k in (24, 96):
        res = curvature.estimate(cloud.points, normals=cloud.normals, k=k)
        assert res.info["params"]["k"] == k and res.info["fit"] == "nfr"
        assert res.neighbor_count.max() == k
        assert set(np.unique(res.neighbor_count)) <= {24, 48, 96}
        errors[k] = mean_errors(cloud, res)
    # measured 0.352 and 0.087 (0.025 with the default k = 384)
    assert errors[24][0] > 2 * errors[96][0] and errors[96][0] < 0.12, errors
    assert errors[24][0] < 0.5, errors
    # below max_share's floor of 48 too: the small-cloud cap never raises k
    small = curvature.estimate(synthetic.torus(2000, noise=0.3, seed=2).points, k=24)
    assert small.neighbor_count.max() == 24
    # clean clouds: the implicit quadric over 24 neighbors whatever k (24 is its floor)
    clean = synthetic.sphere(2000, radius=2.0, seed=1)
    res = curvature.estimate(clean.points, k=24)
    assert res.info["plan"]["clean"] and np.allclose(res.k1, 0.5) and np.allclose(res.k2, 0.5)


def test_noisy_beats_the_paper_preset_by_far():
    cloud = synthetic.torus(10_000, noise=0.3, seed=2)
    auto = mean_errors(cloud, curvature.estimate(cloud.points, normals=cloud.normals))
    paper = curvature.estimate(cloud.points, preset="paper", normals=cloud.normals)
    m = cloud.interior & (paper.status == 0)
    paper_err = np.mean(np.abs(paper.k1 - cloud.k1)[m])
    assert auto[0] * 10 < paper_err


def test_point_order_workers_and_chunks_do_not_change_a_bit():
    cloud = synthetic.torus(6000, noise=0.3, seed=4)
    ref = curvature.estimate(cloud.points, workers=1)
    perm = np.random.default_rng(0).permutation(len(cloud.points))
    shuffled = curvature.estimate(cloud.points[perm], workers=2, chunk_size=777)
    for name, arr in ref.fields().items():
        np.testing.assert_array_equal(shuffled.fields()[name], arr[perm], err_msg=name)


def test_scaling_by_a_power_of_two_divides_curvature_exactly():
    cloud = synthetic.bezier_patch(5000, noise=0.2, seed=5)
    ref = curvature.estimate(cloud.points, normals=cloud.normals)
    big = curvature.estimate(cloud.points * 4.0, normals=cloud.normals)
    np.testing.assert_array_equal(big.k1 * 4.0, ref.k1)
    np.testing.assert_array_equal(big.k2 * 4.0, ref.k2)
    np.testing.assert_array_equal(big.status, ref.status)


def test_rotation_and_translation_change_only_the_noise_level_error():
    cloud = synthetic.torus(10_000, noise=0.3, seed=6)
    base = mean_errors(cloud, curvature.estimate(cloud.points, normals=cloud.normals))
    q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    moved = cloud.points @ q.T + np.array([100.0, -50.0, 7.0])
    res = curvature.estimate(moved, normals=cloud.normals @ q.T)
    turned = mean_errors(cloud, res)
    assert abs(turned[0] - base[0]) < 0.2 * base[0] and abs(turned[1] - base[1]) < 0.2 * base[1]
    # principal directions turn with the cloud
    m = cloud.interior
    assert np.median(np.abs(np.sum(res.dir1[m] @ q * cloud.dir1[m], axis=1))) > 0.95


def test_orientation_auto_points_outward_on_a_noisy_sphere():
    cloud = synthetic.sphere(8000, noise=0.3, seed=7)
    res = curvature.estimate(cloud.points)
    outward = np.sum(res.normals * cloud.points, axis=1) > 0
    assert outward.mean() > 0.999
    assert np.median(res.mean) == pytest.approx(1.0, rel=0.05)


def test_plane_and_collinear_points_never_raise():
    rng = np.random.default_rng(8)
    plane = np.column_stack([rng.random((2000, 2)), np.zeros(2000)])
    res = curvature.estimate(plane)
    assert np.all(res.status == 0)
    assert np.max(np.abs(res.k1)) < 1e-6 and np.max(np.abs(res.k2)) < 1e-6
    # a clean sphere plus a separate straight line: the line's fits are degenerate (status,
    # NaN); with the cloud judged clean the failed implicit fits fall back to normal fields
    sphere = synthetic.sphere(3000, seed=9).points
    line = np.column_stack([np.linspace(5, 6, 60), np.zeros(60), np.zeros(60)])
    res = curvature.estimate(np.vstack([sphere, line]))
    assert res.info["plan"]["clean"]
    assert np.all(res.status[3000:] != 0) and np.all(np.isnan(res.k1[3000:]))
    assert np.mean(res.status[:3000] == 0) > 0.99


def test_tiny_cloud():
    pts = synthetic.sphere(12, seed=10).points
    res = curvature.estimate(pts)
    assert res.k1.shape == (12,)
    assert set(np.unique(res.status)) <= {0, 1, 2, 3, 4}


def test_progress_reaches_its_total_and_cancels():
    cloud = synthetic.torus(5000, noise=0.3, seed=11)
    calls = []
    curvature.estimate(cloud.points, chunk_size=1000, progress=lambda d, t: calls.append((d, t)))
    done = [d for d, _ in calls]
    assert done == sorted(done) and calls[-1][0] == calls[-1][1] and len(calls) > 5

    class Stop(Exception):
        pass

    def cancel(done, total):
        raise Stop

    with pytest.raises(Stop):
        curvature.estimate(cloud.points, chunk_size=1000, progress=cancel)


def test_grid_cells_choose_the_point_nearest_each_cell_centre():
    pts = np.array([[0.1, 0.1, 0.1], [0.5, 0.5, 0.5], [0.45, 0.5, 0.5], [1.5, 0.2, 0.2],
                    [1.4, 0.6, 0.5]])
    reps, owner = grid_cells(pts, np.zeros(3), 1.0)
    np.testing.assert_array_equal(reps, [1, 4])
    np.testing.assert_array_equal(owner, [0, 0, 0, 1, 1])


@pytest.mark.parametrize("noise, model", [(0.02, "axis"), (0.05, "view"), (0.005, "axis")])
def test_slightly_noisy_clouds_get_the_noisy_branch(noise, model):
    """Noise far below what counted as noisy once (relative noise 0.0015 to 0.0075 against the
    old threshold 0.01) wrecks the 24-point implicit quadric: on this sphere it read median
    |k - 1| of 0.08 to 0.51; the normal fits read 0.006."""
    cloud = synthetic.sphere(10_000, noise=noise, noise_model=model, seed=1)
    res = curvature.estimate(cloud.points)
    assert not res.info["plan"]["clean"] and res.info["plan"]["noise"] >= 0.001
    err = 0.5 * (np.abs(res.k1 - 1.0) + np.abs(res.k2 - 1.0))
    assert np.nanmedian(err) < 0.015 and np.nanmean(err) < 0.02
    clean = curvature.estimate(cloud.points, noise_threshold=1.0)  # the implicit quadric
    assert np.nanmedian(0.5 * (np.abs(clean.k1 - 1.0) + np.abs(clean.k2 - 1.0))) > 0.03


def test_a_torus_at_low_noise_keeps_its_wide_fits():
    """The tops' patches wrap 0.7 of the tube's radius each way; the growth test reads their
    distance to a round shape of their curvature, which the paraboloid missed by its slope
    alone: then 57 % of the points kept 192-point fits or less and erred 0.0174 (mean of k1
    and k2); now 9 % and 0.0134."""
    cloud = synthetic.torus(10_000, noise=0.1, noise_model="view", seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    e1, e2 = mean_errors(cloud, res)
    assert np.mean(res.neighbor_count[cloud.interior] <= 192) < 0.2
    assert 0.5 * (e1 + e2) < 0.0155


def test_normals_refined_again_lower_a_smooth_patchs_error(monkeypatch):
    """Away from features the first pass's normals are refined once more before the second
    pass fits them (mean of the k1 and k2 errors, Bezier patch at 0.1 % view noise: 0.0093
    with one refinement, 0.0078 with two at stop 39; with stop 40's 1152 top 0.0086 and
    0.0077)."""
    cloud = synthetic.make("bezier", 10_000, noise=0.1, noise_model="view", seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    assert "refine again" in res.info["timings"]
    monkeypatch.setattr(AutoRun, "_refine_again",
                        lambda self, field, w, reps, *args: (w, np.zeros(reps.size, bool)))
    once = curvature.estimate(cloud.points, normals=cloud.normals)
    assert np.mean(mean_errors(cloud, res)) < 0.95 * np.mean(mean_errors(cloud, once))


def test_plan_measures_spacing_and_noise():
    clean = synthetic.sphere(20_000, seed=12).points
    noisy = synthetic.sphere(20_000, noise=0.5, seed=12).points
    p_clean = plan_auto(clean, build_tree(clean), 0.01)
    p_noisy = plan_auto(noisy, build_tree(noisy), 0.01)
    assert isinstance(p_clean, AutoPlan) and p_clean.clean and not p_noisy.clean
    # 24 neighbors of an area-uniform unit sphere lie within about sqrt(24 * 4 / n)
    assert p_clean.spacing == pytest.approx(np.sqrt(24 * 4 / 20_000), rel=0.15)
    # noise 0.5 % of the diagonal (2 * sqrt(3)) per axis is 0.0173; relative to the spacing
    assert p_noisy.noise == pytest.approx(0.0173 / p_noisy.spacing, rel=0.35)


@pytest.mark.parametrize("noise", [0.1, 0.25])
def test_a_thin_walls_other_face_does_not_count_as_noise(noise):
    """A thin plate's faces lie 3 spacings apart, so noise brings a few of the other face's
    points among a point's 24 nearest; the cubic fits of the noise measure leave them out
    (read 1.49 and 2.50 times the truth before, 1.26 to 1.28 on other shapes), and a
    sphere's reading stays where it was (1.24)."""
    for name, most in (("thin_plate", 1.3), ("sphere", 1.3)):
        cloud = synthetic.make(name, seed=1, noise=noise)
        plan = plan_auto(cloud.points, build_tree(cloud.points), 0.001)
        run = AutoRun(cloud.points, {}, 100_000, None, plan=plan)
        assert 1.1 < run._noise() / cloud.noise_sigma < most, name


def test_preset_paper_is_territory_claiming_with_ten_neighbors():
    cloud = synthetic.torus(3000, seed=13)
    paper = curvature.estimate(cloud.points, preset="paper")
    tc = curvature.estimate(cloud.points, "tc", fit="implicit", min_neighbors=10,
                            candidates=30)
    for name, arr in tc.fields().items():
        np.testing.assert_array_equal(paper.fields()[name], arr, err_msg=name)
    assert paper.info["preset"] == "paper" and paper.info["params"]["min_neighbors"] == 10
    grown = curvature.estimate(cloud.points, preset="paper", min_neighbors=16)
    assert grown.info["params"]["min_neighbors"] == 16


@pytest.mark.parametrize("kwargs, match", [
    ({"fit": "monge"}, "method 'auto' chooses its own fit"),
    ({"preset": "fast"}, "unknown preset"),
    ({"preset": "paper", "method": "knn"}, "contradicts"),
    ({"preset": "paper", "fit": "monge"}, "contradicts"),
    ({"k": 10}, "'k' must be >= 24, got 10; allowed: 24 to 4096"),
    ({"noise_threshold": -1}, "must be >= 0"),
    ({"min_neighbors": 10}, r"unknown parameter\(s\) \['min_neighbors'\]"),
    ({"method": "nope"}, "unknown method"),
])
def test_parameter_errors(kwargs, match):
    pts = synthetic.sphere(100, seed=14).points
    with pytest.raises(curvature.ParameterError, match=match):
        curvature.estimate(pts, **kwargs)


def test_coordinates_spread_over_hundreds_of_orders_of_magnitude_do_not_raise():
    """The API fuzzer's cloud: coordinates from 1e-300 to 1e284. The plan's cubic fits
    overflowed into a LinAlgError (an HTTP 500); now such neighborhoods measure nothing and
    every point gets a status."""
    rng = np.random.default_rng(4)
    pts = rng.choice([-1.0, 1.0], (28, 3)) * 10.0 ** rng.uniform(-300, 284, (28, 3))
    pts[:8] = rng.normal(size=(8, 3)) * 1e16
    res = curvature.estimate(pts)
    assert len(res.status) == 28 and not res.info["plan"]["clean"]
    ok = res.status == 0
    assert np.isfinite(res.k1[ok]).all() and np.isnan(res.k1[~ok]).all()


def test_plan_sample_is_the_coarse_grids_representatives():
    from curvature.estimators.auto import PLAN_CELLS, coarse_cell, grid_cells, plan_sample

    grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0), [0.0]), -1).reshape(-1, 3)
    for pts in (synthetic.make("torus", 50_000, noise=0.1, seed=2).points,
                synthetic.filleted_box(noise=0.05, seed=1).points, grid):  # grid: ties
        ref, _ = grid_cells(pts, pts.min(axis=0), coarse_cell(pts, PLAN_CELLS))
        np.testing.assert_array_equal(plan_sample(pts), ref)
