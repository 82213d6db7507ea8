"""Normal signs on real single-view scans: every method agrees, and the scanner is faced.

bun000 (a Cyberware range scan, no viewpoint in the file) is oriented by the automatic rule;
the PCL scenes carry a VIEWPOINT, used by default. Scans are thinned (every 2nd point of
bun000, every 4th row and column of the 640 x 480 grids) to keep the test quick; they stay
single-view range scans.
"""

from __future__ import annotations

import numpy as np
import pytest
from real_scans import decimated, sign_agreement

import curvature

METHODS = ("auto", "knn", "tc", "egg", "mesh")
SCANS = {"bun000.ply": 2, "table_scene_mug_stereo_textured.pcd": 4,
         "milk_cartoon_all_small_clorox.pcd": 4}


_RUNS: dict = {}


def default_runs(shared_data, name):
    """The thinned scan and every method's result with its defaults (no parameter given),
    computed once for the tests of this module."""
    if name not in _RUNS:
        cloud = decimated(shared_data / name, SCANS[name])
        _RUNS[name] = cloud, {m: curvature.estimate(cloud, m) for m in METHODS}
    return _RUNS[name]


@pytest.mark.parametrize("name", list(SCANS))
def test_every_method_gives_the_same_normal_sign(shared_data, name):
    cloud, results = default_runs(shared_data, name)
    worst = min(sign_agreement(results[a].normals, results[b].normals)
                for i, a in enumerate(METHODS) for b in METHODS[i + 1:])
    assert worst >= 0.99, f"{name}: lowest pairwise sign agreement {worst:.4f}"
    if cloud.viewpoint is not None:
        for method, res in results.items():
            assert res.info["orientation_rule"] == "viewpoint from the file (PCD VIEWPOINT)"
            facing = sign_agreement(res.normals, cloud.viewpoint - cloud.points)
            assert facing >= 0.99, f"{name} {method}: {facing:.4f} face the scanner"
            assert "grid" in res.info and res.index.max() < 640 * 480


def test_automatic_orientation_on_a_scene_is_one_consistent_field(shared_data):
    """Without the viewpoint the propagated field is consistent; only its global sign is a
    guess (outward from the centroid, which on this scene points away from the camera).
    (On the table scene the field is consistent at about 95 % only: the viewpoint matters.)"""
    cloud = decimated(shared_data / "milk_cartoon_all_small_clorox.pcd", 4)
    res = curvature.estimate(cloud, "knn", fit="monge", orientation="auto")
    facing = sign_agreement(res.normals, cloud.viewpoint - cloud.points)
    assert max(facing, 1.0 - facing) >= 0.99


def test_defaults_give_no_speckle_on_the_bunny_scan(shared_data):
    """Issue 19: without parameters every neighborhood method gives curvature of the scan's
    scale (a bunny ear is about 1 cm across: |k1| of order 100/m); the paper's setting,
    10 Territory Claiming neighbors with the implicit quadric, turns it into speckle."""
    cloud, results = default_runs(shared_data, "bun000.ply")
    for method in ("knn", "tc", "egg", "mesh"):
        res = results[method]
        ok = res.status == 0
        p95 = np.percentile(np.abs(res.k1[ok]), 95)
        assert ok.mean() > 0.999 and 50 < p95 < 500, f"{method}: ok {ok.mean():.4f}, p95 {p95}"
    paper = curvature.estimate(cloud, preset="paper")
    assert np.percentile(np.abs(paper.k1[paper.status == 0]), 95) > 5000
