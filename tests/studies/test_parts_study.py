"""`curvature bench parts` (issue 15): rows per case, region and estimator, the summary and the
profile plots, on small clouds of the quick cases (the default with given and with its own
signs; the peers are checked by their own tests)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from curvature import synthetic
from curvature.studies import parts


def test_quick_run_writes_rows_summary_and_profiles(tmp_path):
    rows = parts.run_parts(tmp_path, quick=True, n_points=3000,
                           estimators=("default", "default_auto_sign"), log=lambda m: None)
    with open(tmp_path / "parts.csv") as fh:
        stored = list(csv.DictReader(fh))
    assert len(stored) == len(rows)
    seen = {(r["case"], r["region"], r["estimator"]) for r in rows}
    for case in parts.QUICK_CASES:
        shape, _ = parts.CASES[case]
        regions = {"filleted_box": ("face", "fillet"), "blade": ("side", "crest")}[shape]
        for region in regions:
            for name in ("default", "default_auto_sign"):
                assert (case, region, name) in seen
        assert (tmp_path / f"profile_{case}.png").stat().st_size > 0
    summary = (tmp_path / "parts_summary.md").read_text()
    assert "| box_0.05 | fillet |" in summary and "default_auto_sign" in summary
    for r in rows:
        assert r["failed"] == 0 and np.isfinite(r["max"])
    # the box orients itself as its exact normals do: the same errors with its own signs
    mean = {(r["case"], r["region"], r["estimator"]): r["mean"] for r in rows}
    for region in ("face", "fillet"):
        assert (mean["box_0.05", region, "default_auto_sign"]
                == pytest.approx(mean["box_0.05", region, "default"], rel=0.02))
        assert mean["box_0.05", region, "default"] < 1.0  # 1/R = 5 on the fillets


def test_region_rows_measure_the_larger_error_per_region():
    cloud = synthetic.make("filleted_box", n=2000, noise=0.0, seed=1)
    k1, k2 = cloud.k1.copy(), cloud.k2.copy()
    face = cloud.region_mask("face") & cloud.interior
    k2[face] += 0.5  # an error of 0.5 on the faces' k2 alone
    rows = {r["region"]: r for r in parts.region_rows("c", cloud, "x", k1, k2, 0.0)}
    assert rows["face"]["mean"] == 0.5 and rows["face"]["mean_k1"] == 0.0
    assert rows["fillet"]["mean"] == 0.0 and rows["face"]["points"] == int(face.sum())
