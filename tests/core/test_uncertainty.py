"""Standard errors of k1, k2 and H (issue 16): calibrated, NaN exactly where no estimate."""

import numpy as np
import pytest

import curvature
import curvature.io
from curvature import synthetic
from curvature.uncertainty import (
    BIAS_WEIGHT,
    MODEL_BIAS,
    SHEETS_SIGMA_POWER,
    THIN_NEIGHBORS,
    UNCERTAIN_SHARE,
    anchored_std,
    uncertain,
)


def coverage(res, cloud, which="k1"):
    """Share of the ok points whose true error is within 2 standard errors."""
    truth = {"k1": cloud.k1, "k2": cloud.k2, "mean": 0.5 * (cloud.k1 + cloud.k2)}[which]
    ok = res.status == 0
    err = np.abs(getattr(res, which) - truth)[ok]
    return float(np.mean(err <= 2.0 * getattr(res, f"{which}_std")[ok]))


@pytest.mark.parametrize("shape", ["sphere", "cylinder"])
@pytest.mark.parametrize("method", ["auto", "knn"])
def test_coverage_on_noisy_shapes_within_bounds(shape, method):
    # Averaged over three clouds: one cloud's coverage is a share of correlated errors (the
    # default's k2 on the cylinder, 0 along a straight generator, errs half as much as its
    # k1 under one fit's standard error and covered 0.974 / 0.971 / 1.000 on seeds 1 / 2 / 4
    # since stop 39's second refinement of the normals; mean 0.982).
    kw = {"k": 24, "fit": "monge"} if method == "knn" else {}
    covs = []
    for seed in (1, 2, 4):
        cloud = getattr(synthetic, shape)(10_000, noise=0.3, seed=seed)
        res = curvature.estimate(cloud.points, method, normals=cloud.normals, **kw)
        covs.append([coverage(res, cloud, which) for which in ("k1", "k2", "mean")])
    for which, cov in zip(("k1", "k2", "mean"), np.mean(covs, axis=0), strict=True):
        assert 0.88 <= cov <= 0.995, (which, cov)


def test_std_shrinks_as_one_over_sqrt_k_on_a_plane():
    """Same patch, four times the points: half the standard error (and half the error)."""
    stds, errors = [], []
    for n, k in ((2_000, 24), (8_000, 96), (32_000, 384)):
        cloud = synthetic.plane(n, noise=0.2, seed=7)
        res = curvature.estimate(cloud.points, "knn", k=k, fit="monge", normals=cloud.normals)
        inner = cloud.interior & (res.status == 0)
        stds.append(np.median(res.k1_std[inner]))
        errors.append(np.sqrt(np.mean(res.k1[inner] ** 2 + res.k2[inner] ** 2) / 2))
    ratios = np.array(stds[1:]) / np.array(stds[:-1])
    np.testing.assert_allclose(ratios, 0.5, rtol=0.12)
    # and the standard error follows the measured error
    np.testing.assert_allclose(np.array(stds) / np.array(errors), 1.0, rtol=0.35)


@pytest.mark.parametrize("method,kw", [("knn", {"k": 10, "fit": "implicit"}),
                                       ("knn", {"k": 10, "fit": "monge"}), ("auto", {})])
def test_nan_exactly_where_status_is_not_ok(method, kw):
    rng = np.random.default_rng(5)
    cloud = synthetic.sphere(2000, noise=0.2, seed=15).points
    dup = np.tile([[50.0, 50.0, 50.0]], (30, 1))
    line = np.c_[np.linspace(0, 1, 30), np.zeros(30), np.zeros(30)] + [-50.0, 0, 0]
    pts = rng.permutation(np.vstack([cloud, dup, line]))
    res = curvature.estimate(pts, method, **kw)
    bad = res.status != 0
    assert bad.any() and (~bad).any()
    for name in ("k1_std", "k2_std", "mean_std"):
        values = getattr(res, name)
        np.testing.assert_array_equal(np.isnan(values), bad, err_msg=name)
        assert np.all(values[~bad] >= 0.0), name
    assert np.all(res.uncertain[bad] == 1)


def test_standard_errors_follow_k1_and_k2_when_the_normal_flips():
    cloud = synthetic.cylinder(4000, noise=0.2, seed=3)
    out = curvature.estimate(cloud.points, "knn", k=24, fit="monge", normals=cloud.normals)
    inward = curvature.estimate(cloud.points, "knn", k=24, fit="monge", normals=-cloud.normals)
    ok = out.status == 0
    assert not np.allclose(out.k1_std[ok], out.k2_std[ok])  # a test that can fail
    np.testing.assert_allclose(inward.k1_std[ok], out.k2_std[ok])
    np.testing.assert_allclose(inward.k2_std[ok], out.k1_std[ok])
    np.testing.assert_allclose(inward.mean_std[ok], out.mean_std[ok])


def test_noise_free_quadric_has_near_zero_std_and_torus_a_positive_one():
    sphere = synthetic.sphere(4000, seed=1)
    res = curvature.estimate(sphere.points, normals=sphere.normals)
    assert res.info["plan"]["clean"]
    assert np.nanmedian(res.k1_std) < 1e-6
    torus = synthetic.torus(10_000, seed=1)
    res = curvature.estimate(torus.points, normals=torus.normals)
    assert np.nanmedian(res.k1_std) > 1e-3
    assert coverage(res, torus, "k1") > 0.85


def test_a_small_fits_chance_miss_is_no_bias_of_the_kept_fit():
    # Until stop 39 the default reported as bias the largest excess of any smaller fit's
    # disagreement over its errors: 24-point rungs with a hundred times the kept fit's sigma
    # missed by chance and half of a noisy sphere's points read standard errors of 0.02 to 2
    # (median 0.064 for a median error of 0.0025), a fifth of them flagged uncertain.
    cloud = synthetic.sphere(10_000, noise=0.25, noise_model="axis", seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    err = np.abs(res.k1 - cloud.k1)
    assert np.median(res.k1_std) < 4.0 * np.median(err)
    assert res.uncertain.mean() < 0.02
    assert coverage(res, cloud, "k1") > 0.9


def test_anchored_std_combines_sigma_bias_and_the_residual_beyond_the_noise():
    sigma = np.array([0.1, 0.1, np.inf])
    bias = np.array([[0.0, 0.2], [0.0, 0.0], [0.0, 0.0]])
    distance = np.array([0.05, 0.5, 0.5])  # the second fit misses its points by 0.4 more
    h = np.array([1.0, 2.0, 2.0])
    err = anchored_std(sigma, bias, distance, h, 0.3)
    np.testing.assert_allclose(err[0], [0.1, np.hypot(0.1, BIAS_WEIGHT * 0.2)])
    np.testing.assert_allclose(err[1], np.hypot(0.1, MODEL_BIAS * 0.4 / 4.0))
    assert np.all(np.isinf(err[2]))
    # no noise measured (a clean cloud): no model term
    np.testing.assert_allclose(anchored_std(sigma, bias, distance, h, np.nan)[1], [0.1, 0.1])


def test_uncertain_rule():
    k1 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, np.nan, 1.0])
    k2 = np.array([0.5, 0.5, 0.5, 0.0, 0.0, np.nan, 1.0])
    share = UNCERTAIN_SHARE
    k1_std = np.array([0.1, share + 0.01, 0.1, 0.05, 0.2, np.nan, np.inf])
    k2_std = np.full(7, 0.1)
    count = np.array([24, 24, THIN_NEIGHBORS - 1, 24, 24, 24, 24])
    status = np.array([0, 0, 0, 0, 0, 1, 0])
    # a diagonal of 5: flat points are trusted while their error is below 0.5 * (1 / 5)
    flags = uncertain(k1, k2, k1_std, k2_std, count, status, 5.0)
    np.testing.assert_array_equal(flags, [0, 1, 1, 0, 1, 1, 1])
    assert flags.dtype == np.uint8


def test_uncertain_grows_with_noise():
    shares = []
    for noise in (0.1, 0.5):
        cloud = synthetic.torus(6000, noise=noise, seed=2)
        res = curvature.estimate(cloud.points, "knn", k=24, fit="monge")
        shares.append(res.uncertain.mean())
    assert shares[0] < shares[1]


def test_cli_summary_prints_the_median_standard_error(tmp_path, capsys):
    from curvature.cli import main

    cloud = synthetic.sphere(3000, noise=0.2, seed=1)
    src = tmp_path / "s.ply"
    curvature.write(src, cloud.points)
    assert main(["estimate", str(src), "-o", str(tmp_path / "r.npz")]) == 0
    line = next(ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("std"))
    res = curvature.io.read_result(tmp_path / "r.npz")
    assert f"k1 {np.nanmedian(res.k1_std):.4g}" in line
    assert "uncertain" in line


def test_neighbor_spread_widens_only_where_neighbors_disagree():
    from curvature.fitting.uncertainty import add_neighbor_spread

    k1 = np.array([1.0, 1.0, -0.5, 3.0, np.nan])
    k2 = np.array([0.5, 0.5, -1.0, 0.5, np.nan])
    normals = np.array([[0, 0, 1], [0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, 1]], float)
    # point 0's neighbors: itself (skipped), 1 (equal), 2 (equal, seen from the other side),
    # 4 (no estimate); point 3's: 0 and 1, which read k1 2 lower
    graph = np.array([[0, 1, 2, 4], [1, 0, 2, 4], [2, 0, 1, 4], [3, 0, 1, 4], [4, 0, 1, 2]])
    std = [np.full(5, 0.1) for _ in range(3)]
    std[0][4] = std[1][4] = std[2][4] = np.nan
    add_neighbor_spread(k1, k2, normals, graph, 1.5, *std, np.zeros(5, bool))
    assert np.allclose([s[:3] for s in std], 0.1)  # agreeing neighbors add nothing
    assert std[0][3] == pytest.approx(np.hypot(0.1, 1.5 * 2.0))
    assert std[1][3] == pytest.approx(0.1)
    assert std[2][3] == pytest.approx(np.hypot(0.1, 1.5 * 1.0))  # H: 1.75 against 0.75
    assert all(np.isnan(s[4]) for s in std)
    # a skipped point keeps its own standard errors however its neighbors disagree (3), and
    # its curvatures are still read by the others (0, which 3 reads)
    for skipped in (0, 3):
        std = [np.full(5, 0.1) for _ in range(3)]
        add_neighbor_spread(k1, k2, normals, graph, 1.5, *std, np.arange(5) == skipped)
        assert all(s[skipped] == 0.1 for s in std)
        if skipped == 0:
            assert std[0][3] == pytest.approx(np.hypot(0.1, 1.5 * 2.0))


def test_default_standard_errors_do_not_depend_on_the_orientation_mode():
    # the neighbor spread reads the orientation's neighbor rows with orientation "auto" and
    # makes the same rows itself otherwise
    cloud = synthetic.filleted_box(noise=0.1, seed=2)
    given = curvature.estimate(cloud.points, normals=cloud.normals)
    auto = curvature.estimate(cloud.points)
    ok = given.status == 0
    pair = np.sort(np.c_[given.k1_std, given.k2_std][ok], axis=1)
    assert np.allclose(pair, np.sort(np.c_[auto.k1_std, auto.k2_std][ok], axis=1))
    assert np.allclose(given.mean_std[ok], auto.mean_std[ok])
    assert "neighbor_spread" in given.info["timings"]
    knn = curvature.estimate(cloud.points, "knn", k=24, fit="monge", normals=cloud.normals)
    assert "neighbor_spread" not in knn.info["timings"]  # the fixed methods' stay as fitted


def test_a_fit_over_two_parallel_sheets_counts_its_distance_as_noise():
    sigma = np.array([0.3, 0.3])
    bias = np.zeros((2, 2))
    distance = np.array([0.5, 0.5])  # the half thickness of a wall, 5 noise
    h = np.array([2.0, 2.0])
    err = anchored_std(sigma, bias, distance, h, 0.1, np.array([True, False]))
    # over two sheets: sigma shrinks by (noise / distance) ** SHEETS_SIGMA_POWER, no model term
    share = 0.2 ** SHEETS_SIGMA_POWER
    np.testing.assert_allclose(err[0], [0.3 * share, 0.3 * share])
    np.testing.assert_allclose(err[1], np.hypot(0.3, MODEL_BIAS * np.sqrt(0.24) / 4.0))


def _sheets_of(points, normal, k=96):
    from scipy.spatial import cKDTree

    from curvature.fitting.parallel_sheets import parallel_sheets

    anchors = np.arange(0, len(points), 97, dtype=np.int64)
    _, nbr = cKDTree(points).query(points[anchors], k + 1)
    out = np.zeros(anchors.size, bool)
    parallel_sheets(points, anchors, np.tile(normal, (anchors.size, 1)),
                    np.arange(0, (anchors.size + 1) * k, k, dtype=np.int64),
                    np.ascontiguousarray(nbr[:, 1:]).ravel(), out)
    return out


def test_parallel_sheets_are_told_from_one_sheet_and_from_a_wedge():
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1.0, 1.0, (4000, 2))
    side = rng.random(4000) < 0.5
    noise = 0.002 * rng.normal(size=4000)
    slab = np.c_[xy, np.where(side, 0.03, -0.03) + noise]  # faces 0.06 apart, 2 spacings
    plane = np.c_[xy, noise]
    # faces 12 degrees apart (the blade's wedge), as far apart at x = 0 as the slab's
    wedge = np.c_[xy, np.where(side, 1.0, -1.0) * (0.03 + np.tan(np.radians(6)) * xy[:, 0])
                  + noise]
    z = np.array([0.0, 0.0, 1.0])
    # measured: 100 % / 0 % / 0 % of the anchors
    assert _sheets_of(slab, z).mean() > 0.9
    assert not _sheets_of(plane, z).any()
    inner = np.abs(wedge[np.arange(0, 4000, 97), 0]) < 0.25  # where the wedge is a wall
    assert not _sheets_of(wedge, z)[inner].any()


def test_the_thin_plates_standard_errors_are_not_its_walls_thickness():
    # Fits over both faces of the bench's plate (3 spacings apart) miss their points by half
    # the thickness, which is no misfit. Measured: median standard error of k1 0.055 for a
    # median error of 0.034, 2 standard errors covering 0.913 / 0.903 of k1 / k2 (before
    # stop 48: 1.16, covering 0.999 / 0.998).
    cloud = synthetic.make("thin_plate", noise=0.1, noise_model="view", seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    ok = res.status == 0
    assert np.median(res.k1_std[ok]) < 0.3
    assert 0.85 <= coverage(res, cloud, "k1") <= 0.99
    assert 0.85 <= coverage(res, cloud, "k2") <= 0.99
