"""Normal signs on real single-view scans: every method agrees, and the scanner is faced.

bun000 (a Cyberware range scan, no viewpoint in the file) is oriented by the automatic rule;
the PCL scenes carry a VIEWPOINT, used by default. Scans are thinned (every 2nd point of
bun000, every 4th row and column of the 640 x 480 grids) to keep the test quick; they stay
single-view range scans.
"""

from __future__ import annotations

import pytest
from real_scans import decimated, sign_agreement

import curvature

METHODS = ("auto", "knn", "tc", "egg", "mesh")
# The settings docs/defaults.md measures as sane on real scans (the defaults are not yet).
SANE = {"auto": {}, "knn": {"fit": "monge"},
        "tc": {"fit": "monge", "min_neighbors": 24, "candidates": 60},
        "egg": {"fit": "monge", "min_neighbors": 24, "candidates": 60},
        "mesh": {"fit": "monge", "min_neighbors": 24}}
SCANS = {"bun000.ply": 2, "table_scene_mug_stereo_textured.pcd": 4,
         "milk_cartoon_all_small_clorox.pcd": 4}


@pytest.mark.parametrize("name", list(SCANS))
def test_every_method_gives_the_same_normal_sign(shared_data, name):
    cloud = decimated(shared_data / name, SCANS[name])
    results = {m: curvature.estimate(cloud, m, **SANE[m]) for m in METHODS}
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
