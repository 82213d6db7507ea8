"""The CGAL jet grid of `curvature bench accuracy` and its ratio table (issue 23).

The ratio logic is checked on hand-made rows; one small real run (2,000-point sphere, one noise
level, one seed, both noise models) is skipped when CGAL's headers or a C++ compiler are
missing.
"""

from __future__ import annotations

import csv
import math

import pytest

from curvature.studies import jets
from curvature.studies.accuracy import AccuracyConfig, run_accuracy
from curvature.studies.jets import (
    JET_SETTINGS,
    error_figure,
    jet_csv_rows,
    jet_name,
    jet_ratios,
    parse_jet_name,
    ratio_markdown,
)
from curvature.studies.peers.cgal import cgal_available, cgal_unavailable_reason

needs_cgal = pytest.mark.skipif(not cgal_available(),
                                reason=f"CGAL reference unavailable: {cgal_unavailable_reason()}")


def row(est, e1, e2, *, shape="sphere", noise=0.3, model="axis", seed=1):
    return {"shape": shape, "noise": noise, "noise_model": model, "seed": seed,
            "estimator": est, "err_k1": e1, "err_k2": e2, "rel_k1": 0.0, "rel_k2": 0.0,
            "failed": 0.0, "seconds": 0.1}


def test_the_grid_has_six_named_settings():
    assert JET_SETTINGS == ((24, 2), (24, 4), (96, 2), (96, 4), (384, 2), (384, 4))
    assert [parse_jet_name(jet_name(k, d)) for k, d in JET_SETTINGS] == list(JET_SETTINGS)
    assert parse_jet_name("default") is None and parse_jet_name("jet24") is None
    assert error_figure(row("default", 0.01, 0.03)) == pytest.approx(0.02)


def test_ratio_is_against_the_best_setting_averaged_over_seeds():
    rows = [
        # axis cell: jet96d2 is best on average (0.05) though jet24d4 wins seed 1
        row("default", 0.010, 0.030, seed=1), row("default", 0.020, 0.040, seed=2),
        row("jet24d4", 0.030, 0.030, seed=1), row("jet24d4", 0.090, 0.090, seed=2),
        row("jet96d2", 0.040, 0.060, seed=1), row("jet96d2", 0.050, 0.050, seed=2),
        row("jet384d4", math.nan, math.nan, seed=1), row("jet384d4", 0.001, 0.001, seed=2),
        row("paper", 0.0001, 0.0001, seed=1),  # not a jet: never the reference
        # view cell: one seed, the default loses
        row("default", 0.04, 0.06, model="view"), row("jet96d4", 0.05, 0.07, model="view"),
        # noise 0 and a cell without the default are left out
        row("default", 0.0, 0.0, noise=0.0), row("jet24d2", 0.1, 0.1, noise=0.0),
        row("jet24d2", 0.1, 0.1, shape="torus"),
    ]
    ratios = {(r["shape"], r["noise_model"]): r for r in jet_ratios(rows)}
    assert set(ratios) == {("sphere", "axis"), ("sphere", "view")}
    axis = ratios["sphere", "axis"]
    assert axis["best_jet"] == "jet96d2" and (axis["best_k"], axis["best_degree"]) == (96, 2)
    assert axis["default"] == pytest.approx(0.025)  # (0.02 + 0.03) / 2
    assert axis["best_error"] == pytest.approx(0.05)
    assert axis["ratio"] == pytest.approx(0.5) and axis["passed"]
    assert axis["runner_up"] == pytest.approx(0.06)  # jet24d4; jet384d4 failed on seed 1
    assert axis["worst_seed_ratio"] == pytest.approx(0.03 / 0.05)  # seed 2 against jet96d2
    view = ratios["sphere", "view"]
    assert view["ratio"] == pytest.approx(0.05 / 0.06) and not view["passed"]
    assert math.isnan(view["runner_up"])
    table = ratio_markdown(jet_ratios(rows))
    assert "| sphere | 0.3 | axis | 0.0250 | 0.0500 (jet96d2) | 0.50 | ok |" in table
    assert "**missed**" in table and "1 of 2 ratios at most 0.5" in table


def test_rows_without_a_noise_model_count_as_axis_and_csv_rows_carry_the_setting():
    rows = [row("default", 0.01, 0.01), row("jet384d2", 0.04, 0.04)]
    for r in rows:
        del r["noise_model"]
    (ratio,) = jet_ratios(rows)
    assert ratio["noise_model"] == "axis" and ratio["ratio"] == pytest.approx(0.25)
    (out,) = jet_csv_rows(rows)
    keys = list(out)
    assert keys[keys.index("estimator") + 1:][:2] == ["k", "degree"]
    assert (out["k"], out["degree"]) == (384, 2)


def test_without_cgal_the_jets_are_left_out_with_the_reason(tmp_path, monkeypatch):
    monkeypatch.setattr(jets, "jets_unavailable_reason", lambda: "no CGAL here")
    messages = []
    config = AccuracyConfig(n_points=2000, noises=(0.3,), seeds=(1,), shapes=("sphere",),
                            estimators=("default",), noise_models=("axis",))
    result = run_accuracy(config, tmp_path, log=messages.append)
    assert any("CGAL jet fitting is left out: no CGAL here" in m for m in messages)
    assert [r["estimator"] for r in result["rows"]] == ["default"] and not result["ratios"]
    assert not (tmp_path / "jets.csv").exists() and not (tmp_path / "jet_ratios.csv").exists()


@needs_cgal
def test_small_real_run_reports_the_ratio_to_the_best_setting(tmp_path):
    config = AccuracyConfig(n_points=2000, noises=(0.3,), seeds=(1,), shapes=("sphere",),
                            estimators=("default",))
    result = run_accuracy(config, tmp_path, log=lambda m: None)
    with open(tmp_path / "jets.csv") as fh:
        jet_rows = list(csv.DictReader(fh))
    with open(tmp_path / "accuracy.csv") as fh:
        base = list(csv.DictReader(fh))
    with open(tmp_path / "jet_ratios.csv") as fh:
        ratios = {r["noise_model"]: r for r in csv.DictReader(fh)}
    assert {r["estimator"] for r in base} == {"default"}
    assert sorted((r["noise_model"], int(r["k"]), int(r["degree"])) for r in jet_rows) == \
        sorted((m, k, d) for m in ("axis", "view") for k, d in JET_SETTINGS)
    assert set(ratios) == {"axis", "view"} and len(result["ratios"]) == 2
    for model, ratio in ratios.items():
        fig = {r["estimator"]: (float(r["err_k1"]) + float(r["err_k2"])) / 2
               for r in jet_rows if r["noise_model"] == model}
        best = min(fig, key=fig.get)
        (default,) = [(float(r["err_k1"]) + float(r["err_k2"])) / 2 for r in base
                      if r["noise_model"] == model]
        assert ratio["best_jet"] == best
        assert float(ratio["ratio"]) == pytest.approx(default / fig[best])
        # a noisy sphere is read to within a few tenths of 1/r by every estimator here
        assert 0.0 < default < 0.5 and 0.0 < fig[best] < 0.5
    summary = (tmp_path / "summary.md").read_text()
    assert "| shape | noise % | model | default | best jet (setting) | ratio |" in summary
    assert "Median seconds per cloud (CGAL)" in summary
