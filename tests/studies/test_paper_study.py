"""The paper study: metrics (curvature.evaluation), runner outputs, ``curvature bench``."""

import csv
import json
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np
import pytest

import curvature
from curvature import evaluation, synthetic
from curvature.cli import PLUGIN_GROUP, build_parser, main
from curvature.studies import paper as paper_study


@dataclass
class FakeResult:
    """The fields the metrics read from a CurvatureResult."""

    k1: np.ndarray
    k2: np.ndarray
    status: np.ndarray

    @property
    def mean(self):
        return 0.5 * (self.k1 + self.k2)

    def __len__(self):
        return len(self.k1)


def fake(k1, k2, status=None):
    k1, k2 = np.asarray(k1, float), np.asarray(k2, float)
    status = np.zeros(len(k1), np.int8) if status is None else np.asarray(status, np.int8)
    return FakeResult(np.where(status == 0, k1, np.nan), np.where(status == 0, k2, np.nan), status)


# ---------------------------------------------------------------------------------------------
# Metrics
# ---------------------------------------------------------------------------------------------


def test_point_errors_marks_failures_and_applies_mask():
    res = fake([1.0, 2.0, 3.0, 4.0], [0.0, 0.0, 0.0, 0.0], status=[0, 2, 0, 0])
    err = evaluation.point_errors(res, [1.5, 2.0, 2.0, 4.0], [0.0, 0.0, 1.0, 0.0],
                                  mask=[True, True, True, False])
    assert err.failed.tolist() == [False, True, False]
    assert np.allclose(err.k1, [0.5, np.nan, 1.0], equal_nan=True)
    stats = evaluation.error_summary(err)
    assert stats["points"] == 3 and stats["failures"] == 1
    assert stats["failure_rate"] == pytest.approx(1 / 3)
    assert stats["k1_mean"] == pytest.approx(0.75) and stats["k1_median"] == pytest.approx(0.75)
    assert stats["k2_mean"] == pytest.approx(0.5) and stats["k2_std"] == pytest.approx(0.5)


def test_error_summary_all_failed_is_nan_not_an_error():
    err = evaluation.point_errors(fake([1.0], [1.0], status=[3]), [1.0], [1.0])
    stats = evaluation.error_summary(err)
    assert stats["failure_rate"] == 1.0 and np.isnan(stats["k1_mean"])


def test_win_share_counts_failures_as_losses_and_ties_as_half():
    truth = np.zeros(5)
    # Per point: A better, B better, A failed vs B ok, A ok vs B failed, both failed.
    a = evaluation.point_errors(fake([1, 2, 0, 1, 0], [1, 1, 0, 1, 0], [0, 0, 2, 0, 1]),
                                truth, truth)
    b = evaluation.point_errors(fake([2, 1, 1, 0, 0], [1, 1, 1, 0, 0], [0, 0, 0, 3, 1]),
                                truth, truth)
    ab, ba = evaluation.win_share(a, b), evaluation.win_share(b, a)
    assert ab["eta_k1"] == pytest.approx((1 + 0 + 0 + 1 + 0.5) / 5)
    assert ab["tie_k1"] == pytest.approx(1 / 5)
    assert ab["eta_k2"] == pytest.approx((0.5 + 0.5 + 0 + 1 + 0.5) / 5)
    assert ab["tie_k2"] == pytest.approx(3 / 5)
    for k in ("eta_k1", "eta_k2"):
        assert ab[k] + ba[k] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="length"):
        evaluation.win_share(a, evaluation.point_errors(fake([1], [1]), [0], [0]))


def test_density_consistency_compares_kept_points_only():
    full = fake([1.0, 2.0, 3.0, 4.0], [0.0, 1.0, 2.0, 3.0], status=[0, 0, 0, 2])
    kept = np.array([1, 2, 3])
    reduced = fake([2.5, 3.0, 4.0], [1.0, 1.0, 3.0], status=[0, 0, 0])
    out = evaluation.density_consistency(full, reduced, kept)
    assert out["kept"] == 3 and out["failed_full"] == 1 and out["failed_reduced"] == 0
    assert out["compared"] == 2
    assert out["dk1_median"] == pytest.approx(0.25) and out["dk1_mean"] == pytest.approx(0.25)
    assert out["dk2_mean"] == pytest.approx(0.5) and out["dH_mean"] == pytest.approx(0.375)
    same = evaluation.density_consistency(full, full, np.arange(4))
    assert same["dk1_mean"] == 0.0 and same["compared"] == 3
    with pytest.raises(ValueError, match="kept"):
        evaluation.density_consistency(full, reduced, kept[:2])


def test_aggregate_over_seeds_and_kept_indices():
    rows = [{"a": "x", "seed": s, "v": v} for s, v in ((1, 1.0), (2, 3.0), (3, float("nan")))]
    rows.append({"a": "y", "seed": 1, "v": 5.0})
    out = paper_study.aggregate(rows, ["a"], ["v"])
    assert out[0] == {"a": "x", "seeds": 3, "v": 2.0, "v_min": 1.0, "v_max": 3.0}
    assert out[1]["v"] == 5.0 and out[1]["seeds"] == 1
    kept = paper_study.kept_indices(1000, 0.4, seed=3)
    assert kept.size == 600 and np.all(np.diff(kept) > 0)
    assert np.array_equal(kept, paper_study.kept_indices(1000, 0.4, seed=3))
    assert not np.array_equal(kept, paper_study.kept_indices(1000, 0.4, seed=4))


# ---------------------------------------------------------------------------------------------
# A tiny run of the whole study
# ---------------------------------------------------------------------------------------------

ACCURACY_COLUMNS = ["shape", "noise_model", "noise_pct", "seed", "n_points", "method", "fit",
                    "evaluated", "failures", "failure_rate", *paper_study.ERROR_COLUMNS,
                    "neighbors_median", "seconds"]
ETA_COLUMNS = ["shape", "noise_model", "noise_pct", "seed", "n_points", "fit", "pair",
               "method", "other", "evaluated", "eta_k1", "tie_k1", "eta_k2", "tie_k2"]
DENSITY_COLUMNS = ["scan", "points", "method", "fit", "removed_pct", "seed", "full_failures",
                   "kept", "failed_full", "failed_reduced", "compared",
                   *paper_study.DENSITY_COLUMNS, "seconds"]


def read_csv(path):
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return reader.fieldnames, list(reader)


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    base = tmp_path_factory.mktemp("study")
    scan = base / "scan.ply"
    wavy = synthetic.bezier_patch(3000, noise=0.1, seed=7)
    curvature.write(scan, curvature.PointCloud(points=wavy.points))
    config = paper_study.StudyConfig(n_points=1500, noise_levels=(0.0, 0.5), seeds=(1, 2),
                                     removal_fractions=(0.5,), scan=str(scan), workers=1)
    record = paper_study.run_study(config, base / "out", log=lambda _msg: None)
    return config, base / "out", record


def test_study_writes_every_file(tiny_study):
    config, out, record = tiny_study
    methods = config.available_methods()
    assert record["config"]["methods"] == list(methods)
    assert set(record["skipped_methods"]) == set(config.methods) - set(methods)
    expected = {f"{t}{s}.csv" for t in ("accuracy", "eta", "density") for s in ("", "_summary")}
    expected |= {f"errors_{shape}_{fit}_{model}.png" for shape in config.shapes
                 for fit in config.fits for model in config.noise_models}
    expected |= {f"eta_{shape}_{model}.png" for shape in config.shapes
                 for model in config.noise_models}
    expected |= {"failures.png", "density_implicit.png", "density_monge.png", "summary.md"}
    assert expected <= set(record["files"])
    assert json.loads((out / "run.json").read_text())["files"] == record["files"]
    import matplotlib.image

    for name in record["files"]:
        assert (out / name).is_file()
        if name.endswith(".png"):
            assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            image = matplotlib.image.imread(out / name)
            assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 400
    assert "| method \\ noise_pct |" in (out / "summary.md").read_text()


def test_accuracy_csv_structure_and_values(tiny_study):
    config, out, _ = tiny_study
    m = len(config.available_methods())
    columns, rows = read_csv(out / "accuracy.csv")
    assert columns == ACCURACY_COLUMNS
    per_seed = len(config.shapes) * len(config.noise_levels) * len(config.noise_models) * m * 2
    assert len(rows) == per_seed * len(config.seeds)
    for row in rows:
        rate = float(row["failure_rate"])
        assert 0.0 <= rate <= 1.0
        assert int(row["evaluated"]) <= config.n_points
        if row["shape"] == "bezier":  # interior points only
            assert int(row["evaluated"]) < config.n_points
        assert rate == 1.0 or all(np.isfinite(float(row[c])) for c in paper_study.ERROR_COLUMNS)
        if row["noise_pct"] == "0" and row["fit"] == "monge":
            assert float(row["k1_median"]) < 0.1 and rate == 0.0
    # Noise 0 is one cloud, reported under both noise models.
    zero = [r for r in rows if r["noise_pct"] == "0"]
    by_model = {model: [r["k1_mean"] for r in zero if r["noise_model"] == model]
                for model in config.noise_models}
    assert by_model["axis"] == by_model["direction"]
    columns, summary = read_csv(out / "accuracy_summary.csv")
    assert len(summary) == per_seed
    assert {"k1_mean_min", "k1_mean_max", "failure_rate_max", "seeds"} <= set(columns)
    for row in summary:
        assert row["seeds"] == str(len(config.seeds))
        assert float(row["k1_median_min"]) <= float(row["k1_median"]) \
            <= float(row["k1_median_max"])


def test_eta_csv_structure_and_values(tiny_study):
    config, out, _ = tiny_study
    methods = config.available_methods()
    pairs = paper_study.eta_pairs(methods)
    assert pairs[0] == ("TC", "10-NN") and ("TC-24", "24-NN") in pairs
    assert len(pairs) == len([m for m in methods if m in paper_study.PAPER_METHODS])
    columns, rows = read_csv(out / "eta.csv")
    assert columns == ETA_COLUMNS
    assert len(rows) == (len(config.shapes) * len(config.noise_levels)
                         * len(config.noise_models) * 2 * len(pairs) * len(config.seeds))
    assert {(r["method"], r["other"]) for r in rows} == set(pairs)
    assert all(r["pair"] == f"{r['method']} vs {r['other']}" for r in rows)
    for row in rows:
        for k in ("eta_k1", "eta_k2", "tie_k1", "tie_k2"):
            assert 0.0 <= float(row[k]) <= 1.0


def test_density_csv_structure_and_values(tiny_study):
    config, out, _ = tiny_study
    m = len(config.available_methods())
    columns, rows = read_csv(out / "density.csv")
    assert columns == DENSITY_COLUMNS
    assert len(rows) == m * 2 * len(config.removal_fractions) * len(config.seeds)
    for row in rows:
        assert row["scan"] == "scan.ply" and row["points"] == "3000"
        assert int(row["kept"]) == 1500 and row["removed_pct"] == "50"
        assert int(row["compared"]) + int(row["failed_reduced"]) >= int(row["kept"]) - \
            int(row["failed_full"])
        assert int(row["compared"]) > 0.9 * int(row["kept"])
        assert all(np.isfinite(float(row[c])) and float(row[c]) >= 0
                   for c in paper_study.DENSITY_COLUMNS)


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------


def test_bench_is_a_plugin_of_the_cli():
    names = {ep.name: ep.value for ep in entry_points(group=PLUGIN_GROUP)}
    assert names.get("bench") == "curvature.studies.cli:register"


def test_bench_parser_options():
    args = build_parser().parse_args(["bench", "paper", "--out", "d", "--quick", "--seeds", "4",
                                      "--workers", "1", "--data", "x"])
    assert (args.study, args.out, args.quick, args.seeds, args.workers, args.data) == \
        ("paper", "d", True, 4, 1, "x")


def test_bench_without_scan_is_a_clear_error(tmp_path, capsys):
    assert main(["bench", "paper", "--out", str(tmp_path / "o"), "--data", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "bun000.ply" in err and "--data" in err
    assert main(["bench", "paper", "--out", str(tmp_path / "o"), "--seeds", "0"]) == 2
    assert "--seeds" in capsys.readouterr().err


def test_default_data_dir_is_next_to_the_repository():
    repo_parent = Path(curvature.__file__).resolve().parents[2]
    assert paper_study.default_data_dir() == repo_parent / "shared" / "data"
