"""The default estimator on machined-part shapes (issue 15): bounds per region, no blow-ups,
outliers, per-point scale and invariance. Figures measured on this code are in comments; the
bounds leave a margin for other seeds and platforms."""

from __future__ import annotations

import numpy as np
import pytest

import curvature
from curvature import synthetic
from curvature.estimators import auto
from curvature.fitting import scale_selection

R = 0.2  # the filleted box's fillet radius: 1/R = 5


def region_mean(cloud, res, region, field="k1"):
    m = cloud.region_mask(region)
    assert np.all(res.status[m] == 0)
    return float(np.mean(np.abs(getattr(res, field) - getattr(cloud, field))[m]))


def worst(cloud, res):
    return np.fmax(np.abs(res.k1 - cloud.k1), np.abs(res.k2 - cloud.k2))


@pytest.fixture(scope="module")
def noisy_box():
    cloud = synthetic.filleted_box(noise=0.05, seed=1)
    return cloud, curvature.estimate(cloud.points, normals=cloud.normals)


def test_noisy_box_keeps_fillets_corners_and_flat_faces(noisy_box):
    cloud, res = noisy_box
    # issue 15's targets: fillets 10 % of 1/R, corners 12 %, faces 3 % (measured 2.9 %,
    # 2.8 % (k1) and 6.3 % (k2), 1.4 % (k1) and 0.9 % (k2); at stop 29 6.3 %, 3.8 % and 8.3 %,
    # 1.6 % and 0.6 %; before the circular rungs and the refits 8.4 %, 8.6 % and 23 %, 2.1 %)
    # tighter than the issue: kept gains (0.165 = 3.3 % until the normal fits sat out beside
    # tight ridges, stop 42)
    assert region_mean(cloud, res, "fillet") <= 0.032 / R
    assert region_mean(cloud, res, "corner") <= 0.12 / R
    assert region_mean(cloud, res, "corner", "k2") <= 0.08 / R
    assert region_mean(cloud, res, "face") <= 0.03 / R
    assert region_mean(cloud, res, "face", "k2") <= 0.03 / R
    # at a fixed 384 neighbors the fillets read far lower (measured 0.67, 13 %)
    fixed = curvature.estimate(cloud.points, normals=cloud.normals, k=384, scale_gamma=0.0)
    assert region_mean(cloud, fixed, "fillet") > 1.3 * region_mean(cloud, res, "fillet")


def test_points_beside_small_fits_fit_around_themselves(noisy_box, monkeypatch):
    # a corner point reading its anchor's small patch a cell away straddles the corner's edge
    # (measured corners' k2: 0.24 with the refits, 0.93 without)
    cloud, res = noisy_box
    monkeypatch.setattr(auto, "REFIT_BELOW", 0)
    anchored = curvature.estimate(cloud.points, normals=cloud.normals)
    assert (region_mean(cloud, anchored, "corner", "k2")
            > 1.8 * region_mean(cloud, res, "corner", "k2"))
    assert "refit" in res.info["timings"]


def test_normals_are_not_refined_again_beside_features(noisy_box, monkeypatch):
    # a fit of normals one pass already smoothed spreads a fillet further onto its faces:
    # refined twice everywhere the faces read 0.082 (mean |k1 error|), refined once 0.070;
    # the anchors within 4 cells of a feature's small fits keep one refinement (0.070).
    # (Without the sphere fits of the last pass, which read many face points afresh.)
    cloud, _ = noisy_box
    no_spheres = {"umbilic_pass": lambda *args, **kwargs: 0}
    for name, value in no_spheres.items():
        monkeypatch.setattr(auto, name, value)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    monkeypatch.setattr(auto, "REFINE_AGAIN_FROM", 0)  # no anchor is beside a feature
    everywhere = curvature.estimate(cloud.points, normals=cloud.normals)
    monkeypatch.undo()
    for name, value in no_spheres.items():
        monkeypatch.setattr(auto, name, value)
    monkeypatch.setattr(auto.AutoRun, "_refine_again",
                        lambda self, field, w, reps, *args: (w, np.zeros(reps.size, bool)))
    once = curvature.estimate(cloud.points, normals=cloud.normals)
    face, face_once, face_everywhere = (region_mean(cloud, r, "face")
                                        for r in (res, once, everywhere))
    assert face_everywhere > 1.1 * face_once
    assert face <= 1.02 * face_once


def test_ridge_rungs_follow_fillets_and_leading_edges(noisy_box, monkeypatch):
    # a patch stretched along the fillet, as narrow across it as the 24-point rung with four
    # times its points (measured fillets 0.177 with it, 0.226 without; 0.187 at aspect 2,
    # stop 36; the blade's leading edge at 0.1 %, k = 20: 1.43 and 1.89, 1.57 at aspect 2;
    # now 1.16 and 1.88). Circles read every point of that edge (0.19): the anchored fits are
    # compared without them.
    cloud, res = noisy_box
    blade = synthetic.blade(noise=0.1, seed=1)
    monkeypatch.setattr(auto, "EDGE_LADDER", ())
    with_ridge = curvature.estimate(blade.points, normals=blade.normals)
    rungs = scale_selection.RUNGS
    ridges = (scale_selection.KIND_MONGE_RIDGE, scale_selection.KIND_MONGE_RIDGE_SHORT,
              scale_selection.KIND_MONGE_RIDGE_LONG)
    monkeypatch.setattr(scale_selection, "RUNGS", dict(rungs, fit=tuple(
        r for r in rungs["fit"] if r[1] not in ridges)))
    plain = curvature.estimate(cloud.points, normals=cloud.normals)
    assert region_mean(cloud, plain, "fillet") > 1.12 * region_mean(cloud, res, "fillet")
    plain_blade = curvature.estimate(blade.points, normals=blade.normals)
    assert (region_mean(blade, plain_blade, "leading_edge")
            > 1.12 * region_mean(blade, with_ridge, "leading_edge"))


def test_a_leading_edge_of_2_6_spacings_reads_well():
    # the bench's blade (10,000 points, leading edge k = 20 of 2.6 spacings' radius, 0.1 %
    # noise): mean of the larger of the k1 and k2 errors measured 0.336 with the circles of
    # curvature.fitting.rounded_edge (0.434 with the long ridge rung alone, stop 43; 0.682
    # with the 96-point ridge rungs, stop 42; 1.33 until stop 42; APSS at scale 8: 0.944)
    blade = synthetic.blade(n=10000, noise=0.1, seed=1)
    res = curvature.estimate(blade.points, normals=blade.normals)
    edge = blade.region_mask("leading_edge") & blade.interior
    assert worst(blade, res)[edge].mean() <= 0.45


def test_without_circles_a_leading_edge_reads_its_long_ridge_rung(monkeypatch):
    # the long ridge rung alone (stop 43): 0.434, every edge point keeping it
    monkeypatch.setattr(auto.AutoRun, "_rounded_edges", lambda self, *args: (None, None))
    blade = synthetic.blade(n=10000, noise=0.1, seed=1)
    res = curvature.estimate(blade.points, normals=blade.normals)
    edge = blade.region_mask("leading_edge") & blade.interior
    assert worst(blade, res)[edge].mean() <= 0.55
    assert np.mean(res.neighbor_count[edge] == 192) > 0.8


def _narrow_cylinder(height):
    """A unit cylinder sampled 2.6 points per radius, its point at mid-height and every
    point's index sorted by distance from it."""
    spacing = 1.0 / 2.6
    n = int(round(2.0 * np.pi * height / spacing ** 2))
    cyl = synthetic.cylinder(n, radius=1.0, height=height, seed=3)
    p = int(np.argmin(np.abs(cyl.points[:, 2])))
    return cyl, p, np.argsort(np.linalg.norm(cyl.points - cyl.points[p], axis=1)), spacing


def test_a_ridge_rung_is_judged_by_its_width_not_its_length():
    # a cylinder of 2.6 spacings' radius: the 96-point patch stretched along its axis is about
    # 8 spacings long, so |k| times its RMS distance exceeds SUPPORT, though the rung reads the
    # curvature across it well (width about 2 spacings); noise-free it reads 1.03 for 1
    cyl, p, order, spacing = _narrow_cylinder(40.0)
    nbr = order[1:385].astype(np.int64)
    ladder = np.array([48, 96], np.int64)
    kinds = np.array([scale_selection.KIND_MONGE_CIRCULAR, scale_selection.KIND_MONGE_RIDGE],
                     np.int64)
    quads = np.empty((2, 10))
    out = np.empty((2, 8))
    scale_selection.ladder_estimates(cyl.points, cyl.normals, p, nbr, ladder, kinds, quads,
                                     out)
    assert out[1, 0] == 1.0  # admitted
    np.testing.assert_allclose(sorted(np.abs(out[1, 1:3])), [0.0, 1.0], atol=0.05)
    width = out[1, 5]
    assert width < 2.5 * spacing and out[1, 4] == width  # its quadric is held in that unit
    # the quadric reads the same curvature in that unit (as the scale selection stores it)
    from curvature.fitting.normal_quadric import curvature_from_quadric
    st, c1, c2 = curvature_from_quadric(quads[1], out[1, 4], np.zeros(3), 2.0)[:3]
    assert st == 0
    np.testing.assert_allclose(sorted(np.abs([c1, c2])), sorted(np.abs(out[1, 1:3])),
                               atol=1e-9)


def test_the_scale_is_chosen_per_point(noisy_box):
    cloud, res = noisy_box
    sizes = set(np.unique(res.neighbor_count))
    assert sizes <= {24, 48, 96, 192, 384, 768} and len(sizes) >= 3
    face = np.median(res.neighbor_count[cloud.region_mask("face")])
    fillet = np.median(res.neighbor_count[cloud.region_mask("fillet")])
    assert fillet < face  # small fits on the fillet, large ones on flat faces


def test_clean_box_has_no_blow_ups():
    cloud = synthetic.filleted_box(seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    assert res.info["plan"]["clean"]
    w = worst(cloud, res)
    # every piece is a quadric: a point whose own fit straddles a joint (or is a singular
    # plane pair) reads an exact neighbor's fit (curvature.fitting.shifted)
    for region in ("face", "fillet", "corner"):
        assert np.max(w[cloud.region_mask(region)]) < 1e-6, region
    # the edge zone (within 2 spacings of a joint): either side's value, at most the jump 1/R;
    # measured p99.9 5.0 (was 10.9 before the neighbor fits, 143 before the guards)
    assert np.percentile(w[np.isfinite(w)], 99.9) <= 1.0 / R + 1e-6
    assert np.all(res.status == 0)


def test_clean_smooth_surfaces_keep_their_centred_fits():
    # no fit on a torus is exact, so no point takes a neighbor's (noise-free mean errors as
    # before the neighbor fits: k1 0.0128, k2 0.0064 at 20,000 points)
    cloud = synthetic.torus(20_000, seed=1)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    assert np.mean(res.neighbor_count == 24) > 0.98
    m = cloud.interior
    assert np.mean(np.abs(res.k1 - cloud.k1)[m]) < 0.014
    assert np.mean(np.abs(res.k2 - cloud.k2)[m]) < 0.007


def test_a_plane_and_a_cylinder_read_0_and_1_over_r_at_every_point():
    plane = synthetic.plane(5000, seed=2)
    res = curvature.estimate(plane.points)
    assert np.all(res.status == 0)
    assert np.max(np.abs(np.r_[res.k1, res.k2])) < 1e-9
    cyl = synthetic.cylinder(5000, radius=0.5, seed=2)
    res = curvature.estimate(cyl.points, normals=cyl.normals)
    assert np.all(res.status == 0)
    np.testing.assert_allclose(res.k1, 2.0, atol=1e-6)
    np.testing.assert_allclose(res.k2, 0.0, atol=1e-6)
    # with noise, every point of the plane stays far below anything a feature would read
    noisy = synthetic.plane(10000, noise=0.1, seed=2)
    res = curvature.estimate(noisy.points, normals=noisy.normals)
    k = np.abs(np.r_[res.k1, res.k2])
    assert np.mean(k) < 0.03
    # measured p99.9 0.34, max 0.42 (0.40 and 1.46 until stop 43, when a small rung's chance
    # bump needed no confirmation by the 96-point rung; 0.90 and 2.8 before the border's
    # Monge rungs had their standard errors widened, scale_selection.design_spread: the tail
    # was the border's one-sided 48-point and ridge fits); 0.09 with scale_gamma=0
    assert np.percentile(k, 99.9) < 0.5
    assert np.max(k) < 1.0


def test_a_patch_cut_by_the_border_has_a_wider_design():
    # sqrt(m) times the largest standard error of the height fit's Hessian terms, per unit of
    # noise: sqrt(18) for a uniformly filled disk; a half-disk about 3.4 times that
    rng = np.random.default_rng(5)
    ratios, sides = [], []
    for _ in range(20):
        uv = rng.uniform(-1.0, 1.0, (400, 2))
        disk = uv[np.einsum("ij,ij->i", uv, uv) <= 1.0][:48]
        half = uv[(np.einsum("ij,ij->i", uv, uv) <= 1.0) & (uv[:, 0] >= 0.0)][:48]
        spreads = []
        for patch in (disk, half):
            xs = np.c_[patch, 1e-3 * rng.normal(size=len(patch))]
            xs[0] = 0.0  # the anchor at the origin, its neighbors around it
            xs /= np.sqrt(np.mean(np.sum(xs[1:] ** 2, axis=1)))
            _, axes = np.linalg.eigh(np.cov(xs.T))
            spreads.append(scale_selection.design_spread(xs, axes))
            sides.append(scale_selection.one_sided(xs, axes))
        assert sides[-2] < scale_selection.BORDER_SIDE < sides[-1]
        assert 0.8 * scale_selection.DESIGN_ISOTROPIC < spreads[0] < 2.0 * \
            scale_selection.DESIGN_ISOTROPIC
        ratios.append(spreads[1] / spreads[0])
    assert 2.5 < np.median(ratios) < 5.0
    line = np.c_[np.linspace(-1, 1, 30), np.zeros(30), np.zeros(30)]
    _, axes = np.linalg.eigh(np.cov(line.T) + 1e-12 * np.eye(3))
    assert scale_selection.design_spread(line, axes) == np.inf  # no second direction


def test_outliers_leave_the_inliers_nearly_unchanged(noisy_box):
    cloud, res = noisy_box
    dirty = synthetic.filleted_box(noise=0.05, seed=1, outliers=0.01)
    res_dirty = curvature.estimate(dirty.points, normals=dirty.normals)
    # measured (stop 58): faces +11 % (k1) and 0 % (k2), fillets +8 % / +13 %, corners -4 % /
    # +7 %; issue 15 asks for at most 20 % (stop 34: faces +11 %; before the refits: faces
    # +12 %, fillets +35 %)
    assert region_mean(dirty, res_dirty, "face") <= 1.2 * region_mean(cloud, res, "face")
    assert region_mean(dirty, res_dirty, "face", "k2") <= 1.2 * region_mean(cloud, res, "face",
                                                                           "k2")
    for region in ("fillet", "corner"):
        for field in ("k1", "k2"):
            assert (region_mean(dirty, res_dirty, region, field)
                    <= 1.2 * region_mean(cloud, res, region, field)), (region, field)
    inliers = ~dirty.region_mask("outlier")
    assert np.all(res_dirty.status[inliers] == 0)


def test_outliers_past_a_wedge_tip_leave_its_edge_zone_unchanged():
    # Uniform outliers in the blade's box fall inside its thin trailing end or just past its
    # tip, where the offset test cannot see them (curvature.fitting.outliers.off_sheets).
    # measured (seed 1): edge zone 2.03 -> 4.07 (+101 %) before that test, 2.03 -> 2.09 with
    # it; leading edge +8 %, crest -4 %
    clean, dirty = (synthetic.blade(noise=0.1, seed=1, outliers=share) for share in (0.0, 0.01))
    res, res_dirty = (curvature.estimate(c.points, normals=c.normals) for c in (clean, dirty))
    for region in ("edge_zone", "leading_edge", "crest"):
        mean = np.nanmean(worst(clean, res)[clean.region_mask(region)])
        mean_dirty = np.nanmean(worst(dirty, res_dirty)[dirty.region_mask(region)])
        assert mean_dirty <= 1.2 * mean, (region, mean, mean_dirty)


def test_thin_plate_faces_stay_flat():
    # the faces are 4 spacings apart: fits must not bend toward the other side
    cloud = synthetic.thin_plate(noise=0.1, seed=3)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    face = cloud.region_mask("face") & cloud.interior
    assert np.median(worst(cloud, res)[face]) < 0.3
    assert np.mean(worst(cloud, res)[face]) < 1.0


def test_a_thin_plates_faces_read_flat_up_to_its_open_border_also_with_outliers():
    # Within a spacing of the plate's cut (z = 0 and 1) a point's nearest 24 hold the other
    # face, behind it only: fits over both read the cut as a rim. Measured (seed 1): that
    # band 1.82 before its fits kept to one face (stop 59), 0.48 now; the faces 0.126 ->
    # 0.081. With 1 % outliers the faces read 0.102 at stop 62, 1.33 times the clean
    # cloud's 0.076 (0.191 at stop 58): two outliers in the gap past the top cut, one
    # tilting the faces' planes the other was judged by, were not flagged (step 47 of
    # docs/accuracy.md, section 9); now 0.082, 1.07 times (with every outlier flagged 0.069).
    clean, dirty = (synthetic.thin_plate(noise=0.1, seed=1, outliers=share)
                    for share in (0.0, 0.01))
    res, res_dirty = (curvature.estimate(c.points, normals=c.normals) for c in (clean, dirty))
    face = clean.region_mask("face")
    z = clean.clean[:, 2]
    cut = face & (np.minimum(z - z.min(), z.max() - z) < clean.params["spacing"])
    assert np.mean(worst(clean, res)[cut]) < 0.8
    assert np.mean(worst(clean, res)[face]) < 0.1
    # issue 15: the inliers' errors rise by at most 20 % with 1 % outliers
    assert (np.nanmean(worst(dirty, res_dirty)[dirty.region_mask("face")])
            <= 1.2 * np.mean(worst(clean, res)[face]))


def test_two_outliers_near_each_other_do_not_hide_each_other():
    # On the blade (seed 1, 1 % outliers) one outlier lies 9 noise off a side just past its
    # top, 0.7 spacings out, with another 16 noise off among its 48 neighbors: that one
    # raised their thickness to 2.5 noise, and the offset test let the first pass. Eleven
    # points of the side below it then read errors of 1.2 to 6.9 (stop 62); now the points
    # whose neighbors lost an outlier are tested again without it
    # (AutoRun._normals_without_outliers), and none of them errs more than 0.11.
    cloud = synthetic.blade(noise=0.1, seed=1, outliers=0.01)
    res = curvature.estimate(cloud.points, normals=cloud.normals)
    near = (cloud.region_mask("side")
            & (np.linalg.norm(cloud.points - [1.195, -0.106, 1.01], axis=1)
               < 5 * cloud.params["spacing"]))
    assert near.sum() >= 10
    assert np.max(worst(cloud, res)[near]) < 1.0


@pytest.mark.parametrize("seed, shift", [(1, 0.0), (1, 1.0), (2, 0.0), (2, 1.0)])
def test_a_blades_sides_read_flat_up_to_its_open_ends_wherever_the_grid_falls(
        seed, shift, move_anchor_grid):
    # By the extrusion's open ends (z = 0 and 1) a side point's list lies behind it and holds
    # the wedge's other face; fits over both read the end as a rim (k2 of -20 to -40 on a
    # flat side). The result must not hang on where the anchor grid falls: ``shift`` moves
    # its corner by (0.61, 0.3, 0.54) cells. Measured, sides within 2 spacings of an end
    # (seed 1 / 2, grid as is / moved): 0.24 / 0.25, 0.63 / 0.57 at stop 59; 0.21 / 0.15,
    # 0.33 / 0.24 with the ends' lists on one face (step 42).
    move_anchor_grid(shift * np.array([0.61, 0.3, 0.54]))
    blade = synthetic.blade(noise=0.1, seed=seed)
    res = curvature.estimate(blade.points, normals=blade.normals)
    z = blade.clean[:, 2]
    ends = blade.region_mask("side") & (
        np.minimum(z, blade.params["height"] - z) < 2 * blade.params["spacing"])
    assert np.mean(worst(blade, res)[ends]) < 0.4


@pytest.mark.parametrize("shape, seed", [("blade", 2), ("thin_plate", 1)])
def test_thin_walls_keep_one_orientation_without_given_normals(shape, seed):
    # Without normals the orientation joined the two sides through the wall (the thin plate's
    # faces 3 spacings apart, the blade's trailing edge), flipping one side: half the points,
    # and the blade's convex crest read k1 -1 instead of 1 (measured before: 0.50 and 0.49 of
    # the points wrong; now 0.0010 and 0.0100, the plate's at its rims of 2 spacings).
    cloud = synthetic.make(shape, noise=0.1, seed=seed)
    res = curvature.estimate(cloud.points)
    along = np.einsum("ij,ij->i", res.normals, cloud.normals)
    ok = np.isfinite(along)
    assert np.mean(along[ok] < 0) < 0.015
    if shape == "blade":
        crest = cloud.region_mask("crest") & cloud.interior
        assert np.median(res.k1[crest]) == pytest.approx(1.0, abs=0.15)


@pytest.mark.parametrize("change", ["order", "workers", "translate"])
def test_part_results_do_not_depend_on_order_workers_or_position(noisy_box, change):
    cloud, res = noisy_box
    if change == "order":
        perm = np.random.default_rng(0).permutation(len(cloud))
        other = curvature.estimate(cloud.points[perm], normals=cloud.normals[perm])
        np.testing.assert_array_equal(other.k1, res.k1[perm])
        np.testing.assert_array_equal(other.neighbor_count, res.neighbor_count[perm])
    elif change == "workers":
        other = curvature.estimate(cloud.points, normals=cloud.normals, workers=1)
        np.testing.assert_array_equal(other.k1, res.k1)
    else:  # a translation moves the anchor grid with the cloud
        other = curvature.estimate(cloud.points + [10.0, -3.0, 7.0], normals=cloud.normals)
        np.testing.assert_allclose(other.k1, res.k1, atol=1e-6)


def test_rotated_box_keeps_its_region_errors(noisy_box):
    cloud, res = noisy_box
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rot = rot @ np.array([[1, 0, 0], [0, np.cos(0.4), -np.sin(0.4)], [0, np.sin(0.4),
                                                                       np.cos(0.4)]])
    other = curvature.estimate(cloud.points @ rot.T, normals=cloud.normals @ rot.T)
    for region in ("face", "fillet", "corner"):
        before = region_mean(cloud, res, region)
        assert region_mean(cloud, other, region) <= 1.25 * before + 0.02


def test_misfitting_normal_quadrics_do_not_judge_a_normal_field_top():
    # Rungs of the fit pass (circular Monge, ridge and normal quadric rungs) and two
    # tops that kept the polynomial normal field. The quadric rungs read k1 10 standard errors
    # off the tops; the Monge rungs agree with the tops.
    kinds = np.array([r[1] for r in scale_selection.RUNGS["fit"]], np.int64)
    levels = kinds.shape[0]
    quadric = kinds == scale_selection.KIND_NORMAL_QUADRIC
    est = np.zeros((levels + 2, 8))
    est[:, 0] = 1.0
    est[:, 1] = 1.0
    est[:levels, 1][quadric] = 1.2
    sg = np.full(levels + 2, 0.01)
    t_status = np.zeros(2, np.int8)  # both tops OK
    field, quadric_top = np.zeros(2, np.int8), np.ones(2, np.int8)  # MODEL_FIELD, MODEL_QUADRIC
    gamma = scale_selection.DEFAULT_GAMMA
    # The quadrics misfit their normals twice as much as the tops' field (a torus's tube):
    # they are no judges of the tops, which are kept.
    est[:levels, 7][quadric] = 2e-4
    est[levels:, 7] = 1e-4
    witness, peer = scale_selection._witnesses(est, sg, kinds, t_status, field, levels)
    assert not witness[levels:, :levels][:, quadric].any()
    assert witness[levels:, 1:levels][:, ~quadric[1:]].all()
    nested = scale_selection.nested_rungs(kinds, 2)
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) == levels + 1
    # Quadrics that fit their normals better than the tops' field (a face beside a fillet
    # the tops reach) judge them, and turn them down; so they do for tops that kept the quadric.
    est[:levels, 7][quadric] = 0.5e-4
    for model in (field, quadric_top):
        witness, peer = scale_selection._witnesses(est, sg, kinds, t_status, model, levels)
        assert witness[levels:, 1:].all()
        assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                       peer) < levels


def _full_witness(count):
    """Every smaller fit judges a larger one in k1 and k2 (the 24-point rung only the next)."""
    witness = np.ones((count, count), np.int8)
    witness[2:, 0] = 0
    return witness, np.ones((count, count), np.bool_)


def _edge_ladder(k48):
    """Rung estimates beside a leading edge (k = 20 across it, 0 along): the 48-point rung
    reads ``k48`` across, the ridge rung the edge, the short ridge rung reads it low; the
    other rungs are unusable."""
    kinds = np.array([r[1] for r in scale_selection.RUNGS["fit"]], np.int64)
    levels = kinds.shape[0]
    ridge = int(np.flatnonzero(kinds == scale_selection.KIND_MONGE_RIDGE)[0])
    short = int(np.flatnonzero(kinds == scale_selection.KIND_MONGE_RIDGE_SHORT)[0])
    est = np.zeros((levels, 8))
    sg = np.full(levels, np.inf)
    for r, (across, along, sigma) in {0: (20.5, 0.3, 1.5), 1: (k48, 0.2, 0.8),
                                      ridge: (20.3, 0.0, 0.7), short: (16.5, 0.1, 0.5)}.items():
        est[r, :3] = 1.0, across, along
        sg[r] = sigma
    return kinds, levels, ridge, short, est, sg


def test_a_ridge_rung_is_judged_across_the_ridge_by_narrower_rungs_only():
    # Beside a leading edge of 2.6 spacings' radius the 48-point rung reaches round it onto
    # the flat sides and reads it low (the bench blade: 13 to 18 for 20); it judges the ridge
    # rung, narrower across and longer along, only along the ridge, and the ridge rung judges
    # the short one across it (the bench blade's leading edge 1.38 -> 0.70, stop 42).
    kinds, levels, ridge, short, est, sg = _edge_ladder(15.0)
    witness, peer = scale_selection._witnesses(est, sg, kinds, np.zeros(0, np.int8),
                                               np.zeros(0, np.int8), levels)
    assert witness[ridge, 0] == 1 and witness[ridge, 1] == scale_selection.ALONG
    assert witness[short, ridge] == scale_selection.ACROSS and witness[short, 1] == 1
    assert not peer[ridge, 1] and peer[short, 1] and witness[short, 0] == 0
    nested = scale_selection.nested_rungs(kinds, 0)
    gamma = scale_selection.DEFAULT_GAMMA
    kept = scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer)
    assert kept == ridge  # the short rung reads 3.8 below it: more than 2 combined sigmas
    assert scale_selection._least_error(est, sg, kept, kinds, gamma, peer) == ridge
    # a ridge rung whose curvature along the ridge the 48-point rung contradicts (a patch
    # reaching a corner along a fillet) is turned down
    est[ridge, 2] = 6.0
    kept = scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer)
    assert kept == 1
    # where the 48-point rung reads no significant curvature (a noisy plane's chance bump),
    # every smaller rung judges the ridge rung in full, as before
    kinds, levels, ridge, short, est, sg = _edge_ladder(15.0)
    est[1, 1] = scale_selection.RIDGE_SIGNIFICANCE * sg[1] * 0.9
    witness, peer = scale_selection._witnesses(est, sg, kinds, np.zeros(0, np.int8),
                                               np.zeros(0, np.int8), levels)
    assert witness[ridge, 1] == 1 and witness[ridge, 0] == 0 and peer.all()
    assert witness[short, ridge] == 1


def test_a_long_ridge_rung_fits_only_from_a_list_as_long_as_its_pool():
    # a cylinder of 2.6 spacings' radius: from the 384 nearest (a refit's list) the long
    # ridge rung is not fitted; from RIDGE_LONG_POOL it reads the curvature across the axis,
    # no wider across than the 96-point ridge rung
    cyl, p, order, _ = _narrow_cylinder(80.0)
    kinds = np.array([scale_selection.KIND_MONGE_CIRCULAR, scale_selection.KIND_MONGE_RIDGE,
                      scale_selection.KIND_MONGE_RIDGE_LONG], np.int64)
    ladder = np.array([48, 96, 192], np.int64)
    quads = np.empty((3, 10))
    out = np.empty((3, 8))
    for pool, fitted in ((384, 0.0), (scale_selection.RIDGE_LONG_POOL, 1.0)):
        nbr = order[1:pool + 1].astype(np.int64)
        scale_selection.ladder_estimates(cyl.points, cyl.normals, p, nbr, ladder, kinds,
                                         quads, out)
        assert out[2, 0] == fitted
    np.testing.assert_allclose(sorted(np.abs(out[2, 1:3])), [0.0, 1.0], atol=0.05)
    assert out[2, 5] <= out[1, 5]


def test_a_long_ridge_rung_is_judged_along_the_ridge_by_every_wider_rung():
    # beside a tight edge the long ridge rung (192 points, as narrow across as the ridge
    # rung, twice as long) is noisier by its formula than every rung below it, all of them
    # wider across the edge: the 24-point rung judges it in full, the others along the ridge
    # only, and its sigma may be RIDGE_LONG_GROWTH times theirs (the bench blade's leading
    # edge 0.682 -> 0.434)
    kinds, levels, ridge, short, est, sg = _edge_ladder(15.0)
    long = int(np.flatnonzero(kinds == scale_selection.KIND_MONGE_RIDGE_LONG)[0])
    assert long > short
    est[long, :3] = 1.0, 20.1, 0.0
    sg[long] = 1.6
    witness, peer = scale_selection._witnesses(est, sg, kinds, np.zeros(0, np.int8),
                                               np.zeros(0, np.int8), levels)
    assert witness[long, 0] == 1 and not peer[long, 0]
    for r in (1, ridge, short):
        assert witness[long, r] == scale_selection.ALONG and not peer[long, r]
    nested = scale_selection.nested_rungs(kinds, 0)
    gamma = scale_selection.DEFAULT_GAMMA
    lepski = scale_selection._lepski
    assert lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer, long) == long
    # with a shorter ridge rung's allowance it is too noisy
    assert lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer) == ridge
    # reaching a corner along the ridge (its curvature along it beyond gamma times the
    # combined sigmas of the short ridge rung's): turned down
    est[long, 2] = 9.0
    assert lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer, long) == ridge


def test_a_chance_bump_of_a_small_patch_needs_the_wide_rung_to_confirm_it():
    # a noisy plane's anchor (10,000 points, 0.1 %, seed 4; stop 43): the 24- and 48-point
    # rungs and the ridge rung read a bump of the noise 4 of their standard errors deep, the
    # 96-point circular rung and the wider fits read about 0. The bump turned every wider
    # fit down and the ridge rung's -2.9 was kept; unconfirmed by the 96-point rung it is
    # taken for chance and the top is kept
    ladder, kinds = scale_selection.pass_rungs(192, "fit")[:2]  # a refit's ladder, one top
    levels = kinds.shape[0]
    wide = int(np.flatnonzero((kinds == scale_selection.KIND_MONGE_CIRCULAR)
                              & (ladder >= scale_selection.CONFIRM_SIZE))[-1])
    long = int(np.flatnonzero(kinds == scale_selection.KIND_MONGE_RIDGE_LONG)[0])
    est = np.zeros((levels + 1, 8))
    est[:, 0] = 1.0
    reading = [(0.25, -3.88, 2.07), (0.70, -2.53, 0.62), (-0.10, -2.92, 0.65),
               (-0.09, -1.35, 0.37), (0.0, 0.0, np.inf), (0.13, -0.33, 0.23),
               (0.005, -0.001, 0.095), (0.006, -0.001, 0.069)]
    assert wide == 5 and long == 4 and levels == 7
    sg = np.array([r[2] for r in reading])
    est[:, 1] = [r[0] for r in reading]
    est[:, 2] = [r[1] for r in reading]
    est[1, 5] = 0.05  # the 48-point rung's RMS radius: no tight ridge
    witness, peer = scale_selection._witnesses(est, sg, kinds, np.zeros(1, np.int8),
                                               np.zeros(1, np.int8), levels)
    nested = scale_selection.nested_rungs(kinds, 1)
    gamma = scale_selection.DEFAULT_GAMMA
    lepski = scale_selection._lepski
    args = (est, sg, sg, gamma, 2.0, levels, witness, nested, peer, long)
    unconfirmed = lepski(*args)
    assert unconfirmed < wide  # as before: a small rung reading the bump is kept
    kept = lepski(*args, wide)
    assert kept == levels
    assert scale_selection._least_error(est, sg, kept, kinds, gamma, peer, wide) == levels
    assert scale_selection._least_error(est, sg, kept, kinds, gamma, peer) < wide
    # where the 96-point rung reads the curvature too (a corner, a fillet), it confirms
    est[wide, 2] = -1.0  # 4.3 of its sigmas
    assert lepski(*args, wide) < wide


def test_normal_fits_sit_out_beside_a_tight_cylindrical_ridge():
    # the stage-1 normals are smoothed where a tight ridge meets its flanks: the normal fits
    # read it low with small standard errors (the filleted box's fillets at 0.1 %: 0.294 ->
    # 0.255 without them there, stop 42), so beside such a ridge only positional rungs count
    kinds, levels, ridge, short, est, sg = _edge_ladder(15.0)
    est[1, 5] = 0.05  # the 48-point rung's RMS radius: it turns the normal 0.75 rad
    assert scale_selection._tight_ridge(est, sg, kinds, ridge)
    est[1, 5] = 0.9 * scale_selection.RIDGE_TURN / 15.0  # a gentle ridge (a torus's tube)
    assert not scale_selection._tight_ridge(est, sg, kinds, ridge)
    est[1, 5] = 0.05
    est[ridge, 2] = 0.2 * est[ridge, 1]  # not a cylinder (an ellipsoid's end)
    assert not scale_selection._tight_ridge(est, sg, kinds, ridge)
    est[ridge, 2] = 0.0
    sg[ridge] = np.inf  # unusable
    assert not scale_selection._tight_ridge(est, sg, kinds, ridge)


def test_normal_fits_sit_out_beside_a_tight_cap():
    # a filleted box's corner (k1 = k2 = 5, the 48-point rung's RMS radius 0.09): the
    # 96-point normal quadric read it 16 % low with a sigma of 0.06 (corners at 0.1 %:
    # 0.556 -> 0.510 without the normal fits there, stop 43)
    kinds, levels, ridge, short, est, sg = _edge_ladder(15.0)
    est[1, 1:3] = 5.2, 4.8
    sg[1] = 0.2
    sg[ridge] = sg[short] = np.inf  # no ridge framed: no ridge rungs
    est[1, 5] = 0.09
    assert scale_selection._tight_cap(est, sg, kinds, ridge)
    assert not scale_selection._tight_ridge(est, sg, kinds, ridge)
    est[1, 5] = 0.9 * scale_selection.RIDGE_TURN / 5.2  # a gentle cap (a sphere)
    assert not scale_selection._tight_cap(est, sg, kinds, ridge)
    est[1, 5] = 0.09
    est[1, 2] = 0.4 * 5.2  # unequal curvatures (an ellipsoid's end): not a cap
    assert not scale_selection._tight_cap(est, sg, kinds, ridge)
    est[1, 2] = 4.8
    sg[1] = 5.2 / scale_selection.RIDGE_SIGNIFICANCE * 1.1  # not significant
    assert not scale_selection._tight_cap(est, sg, kinds, ridge)
    # the 24-point rung alone (the 48-point one unusable) does not read a cap: its chance
    # readings took the normal fits from a noisy cylinder (0.5 %: +7 %)
    sg[1] = np.inf
    est[0, 1:3] = 5.2, 4.8
    est[0, 5] = 0.09
    sg[0] = 0.2
    assert scale_selection._framing_rung(est, sg, kinds, ridge) == 0
    assert not scale_selection._tight_cap(est, sg, kinds, ridge)


def test_a_circular_rung_must_agree_closely_with_the_one_inside_it():
    # The 96-point circular rung's patch holds the 48-point one, so their noise is shared: a
    # difference of 3 combined standard errors passes gamma's tolerance (3.5 times the sum)
    # but shows a bias (a patch straddling a corner's edge); the 48-point rung is kept.
    kinds = np.array([r[1] for r in scale_selection.RUNGS["fit"]], np.int64)
    levels = kinds.shape[0]
    circular = np.flatnonzero(kinds == scale_selection.KIND_MONGE_CIRCULAR)
    small, wide = circular[1], circular[2]  # the 48- and 96-point rungs
    nested = scale_selection.nested_rungs(kinds, 0)
    assert nested[wide] == small and nested[small] == -1 and nested[circular[0]] == -1
    est = np.zeros((levels, 8))
    sg = np.full(levels, np.inf)
    est[:wide + 1, 0] = 1.0
    sg[:wide + 1] = 0.1
    est[:wide + 1, 1:3] = 5.0
    est[wide, 2] = 5.0 - 3.0 * np.sqrt(2) * 0.1
    witness, peer = _full_witness(levels)
    gamma = scale_selection.DEFAULT_GAMMA
    others = [r for r in range(wide) if r != small]
    sg[others] = np.inf  # only the two circular rungs are usable
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) == small
    est[wide, 2] = 5.0 - 1.0 * np.sqrt(2) * 0.1  # within the nested tolerance: kept
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) == wide


def test_a_rung_no_less_noisy_than_a_smaller_one_is_turned_down():
    # Every fit agrees; the 96-point normal quadric's sigma is 1.5 times the smallest below
    # it: twice the points, or normals, and no smaller sigma shows a misfit (RUNG_GROWTH), so
    # the fit below is kept. A top may grow up to SIGMA_GROWTH (2) times.
    kinds = np.array([r[1] for r in scale_selection.RUNGS["fit"]], np.int64)
    levels = kinds.shape[0]
    est = np.zeros((levels + 1, 8))
    est[:, 0] = 1.0
    est[:, 1:3] = 1.0
    sg = np.full(levels + 1, 0.1)
    witness, peer = _full_witness(levels + 1)
    nested = scale_selection.nested_rungs(kinds, 1)
    gamma = scale_selection.DEFAULT_GAMMA
    quadric = int(np.flatnonzero(kinds == scale_selection.KIND_NORMAL_QUADRIC)[0])
    sg[quadric:levels] = 0.15  # the quadric rungs, and the top at 0.1
    assert scale_selection.RUNG_GROWTH < 1.5 < scale_selection.SIGMA_GROWTH
    kept = scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested, peer)
    assert kept == levels  # the top (sigma 0.1) is kept
    sg[levels] = np.inf  # without the top, the quadric rungs are turned down
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) < quadric
    sg[quadric:levels] = 0.1  # as noisy as the smaller rungs: kept
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) == levels - 1
    sg[levels] = 0.15  # a top 1.5 times as noisy passes
    assert scale_selection._lepski(est, sg, sg, gamma, 2.0, levels, witness, nested,
                                   peer) == levels
