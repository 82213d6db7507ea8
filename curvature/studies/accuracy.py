"""Accuracy of the default estimator against issue 6's targets, beside the paper and APSS.

Synthetic clouds of ``n_points`` (10,000) with per-axis Gaussian noise of 0 .. 0.5 % of the
bounding-box diagonal: torus (R=2, r=1), ellipsoid (3, 2, 1), unit sphere, the bicubic Bezier
patch and a cylinder. Estimators:

* ``default``: ``curvature.estimate(points)`` with no parameter (method "auto");
* ``paper``: ``preset="paper"`` (Territory Claiming, 10 neighbors, implicit quadric);
* ``apss``: MeshLab's APSS (filter scale 8) through :mod:`curvature.studies.peers.apss`, on normals
  estimated from the points (pymeshlab's plane fit over 30 neighbors), run only when
  ``pymeshlab`` is installed (the ``bench`` extra). With these normals it reproduces the issue's
  APSS figures within about 10 %; given the exact normals APSS would be about twice as accurate,
  an advantage no estimator has on a real scan.

Every estimator gets the exact normals for orientation only, so a sign flip never counts as a
curvature error. Errors are mean ``|k1 - k1_true|`` and ``|k2 - k2_true|`` over interior points
whose estimate succeeded (failures are counted apart), and their relative form (divided by the
mean true ``|k|``; a zero principal curvature, as on the cylinder, is measured against the other
one). The targets (:data:`TARGETS`) are half of APSS's errors at 0.5 % noise as measured in the
issue, for every noise level, and 1 % (sphere, cylinder, ellipsoid) or 3 % (torus, Bezier)
relative error without noise.

Command line::

    curvature bench accuracy --out DIR [--quick] [--seeds N] [--no-apss]
"""

from __future__ import annotations

import csv
import json
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import synthetic
from ..pipeline import estimate

#: Shape label -> (synthetic shape name, its keyword arguments).
SHAPES: dict[str, tuple[str, dict]] = {
    "torus": ("torus", {}),
    "ellipsoid": ("ellipsoid", {"axes": (3.0, 2.0, 1.0)}),
    "sphere": ("sphere", {}),
    "bezier": ("bezier_patch", {}),
    "cylinder": ("cylinder", {}),
}
#: Mean |k1| / |k2| error limits at any noise level: half of APSS's at 0.5 % (issue 6).
TARGETS: dict[str, tuple[float, float] | None] = {
    "torus": (0.050, 0.052), "ellipsoid": (0.081, 0.071), "sphere": (0.1605, 0.1605),
    "bezier": (0.22, 0.22), "cylinder": None,
}
#: APSS's own figures at 0.5 % noise as reported in issue 6 (filter scale 8).
APSS_ISSUE = {"torus": (0.100, 0.104), "ellipsoid": (0.162, 0.142), "sphere": (0.321, 0.321),
              "bezier": (0.44, 0.44)}
#: Relative error limits without noise.
CLEAN_LIMITS = {"torus": 0.03, "bezier": 0.03, "sphere": 0.01, "cylinder": 0.01,
                "ellipsoid": 0.01}
ESTIMATORS = ("default", "paper", "apss")

Log = Callable[[str], None]


@dataclass(frozen=True)
class AccuracyConfig:
    """What to run. ``full`` is the issue's grid; ``quick`` takes about a minute."""

    n_points: int = 10_000
    noises: tuple = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
    seeds: tuple = (1, 2)
    shapes: tuple = tuple(SHAPES)
    estimators: tuple = ESTIMATORS
    workers: int | None = None

    @classmethod
    def full(cls, **changes) -> AccuracyConfig:
        return cls(**changes)

    @classmethod
    def quick(cls, **changes) -> AccuracyConfig:
        return cls(**{"noises": (0.0, 0.5), "seeds": (1,), **changes})


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def apss_available() -> bool:
    from .peers.apss import apss_available as available

    return available()


def run_estimator(name: str, cloud, workers) -> tuple[np.ndarray, np.ndarray]:
    """k1, k2 of one estimator on one cloud (NaN where it failed)."""
    if name == "default":
        res = estimate(cloud.points, normals=cloud.normals, workers=workers)
        return res.k1, res.k2
    if name == "paper":
        res = estimate(cloud.points, preset="paper", normals=cloud.normals, workers=workers)
        return res.k1, res.k2
    if name == "apss":
        from .peers.apss import apss_curvature, estimate_normals

        # APSS fits to oriented normals; like ours they are estimated from the points, and
        # only their signs come from the exact normals.
        normals = estimate_normals(cloud.points)
        flip = np.sum(normals * cloud.normals, axis=1) < 0
        normals[flip] *= -1.0
        return apss_curvature(cloud.points, normals, filter_scale=8.0)
    raise ValueError(f"unknown estimator {name!r}")


def error_row(cloud, k1: np.ndarray, k2: np.ndarray) -> dict:
    """Mean absolute and relative errors over the interior points that succeeded."""
    m = cloud.interior
    ok = m & np.isfinite(k1) & np.isfinite(k2)
    s1, s2 = np.mean(np.abs(cloud.k1[m])), np.mean(np.abs(cloud.k2[m]))
    e1 = float(np.mean(np.abs(k1 - cloud.k1)[ok])) if ok.any() else math.nan
    e2 = float(np.mean(np.abs(k2 - cloud.k2)[ok])) if ok.any() else math.nan
    return {"err_k1": e1, "err_k2": e2, "rel_k1": e1 / s1,
            "rel_k2": e2 / (s2 if s2 > 1e-9 * s1 else s1),
            "failed": float(1.0 - ok.sum() / m.sum())}


def accuracy_rows(config: AccuracyConfig, log: Log = _stderr) -> list[dict]:
    """One row per shape, noise, seed and estimator."""
    estimators = [e for e in config.estimators if e != "apss" or apss_available()]
    if "apss" in config.estimators and "apss" not in estimators:
        log("pymeshlab is not installed: APSS is left out (pip install 'curvature[bench]')")
    rows = []
    for shape in config.shapes:
        name, kwargs = SHAPES[shape]
        for noise in config.noises:
            for seed in config.seeds:
                cloud = synthetic.make(name, config.n_points, noise=noise, seed=seed, **kwargs)
                for est in estimators:
                    t = time.perf_counter()
                    k1, k2 = run_estimator(est, cloud, config.workers)
                    dt = time.perf_counter() - t
                    row = {"shape": shape, "noise": noise, "seed": seed, "estimator": est,
                           **error_row(cloud, k1, k2), "seconds": dt}
                    rows.append(row)
                    log(f"{shape:9} noise {noise:.1f} seed {seed} {est:8} "
                        f"|k1| {row['err_k1']:.4f} |k2| {row['err_k2']:.4f} "
                        f"({row['rel_k1']:.2%} / {row['rel_k2']:.2%}) {dt:.2f}s")
    return rows


def verdicts(rows: list[dict], estimator: str = "default") -> list[dict]:
    """Per shape and noise, the worst seed of ``estimator`` against the issue's limits."""
    out = []
    keys = sorted({(r["shape"], r["noise"]) for r in rows if r["estimator"] == estimator},
                  key=lambda k: (list(SHAPES).index(k[0]), k[1]))
    for shape, noise in keys:
        sel = [r for r in rows if r["estimator"] == estimator and r["shape"] == shape
               and r["noise"] == noise]
        worst = {k: max(r[k] for r in sel) for k in ("err_k1", "err_k2", "rel_k1", "rel_k2")}
        target = TARGETS[shape]
        passed = target is None or (worst["err_k1"] <= target[0]
                                    and worst["err_k2"] <= target[1])
        if noise == 0.0:
            passed = passed and max(worst["rel_k1"], worst["rel_k2"]) <= CLEAN_LIMITS[shape]
        out.append({"shape": shape, "noise": noise, **worst, "target": target,
                    "passed": passed})
    return out


def summary_markdown(rows: list[dict]) -> str:
    """Tables: worst seed per estimator, then the default's verdicts."""
    estimators = [e for e in ESTIMATORS if any(r["estimator"] == e for r in rows)]
    lines = ["| shape | noise % | " + " | ".join(f"{e} k1 / k2" for e in estimators)
             + " | target (issue 6) |", "|---|---|" + "---|" * len(estimators) + "---|"]
    for v in verdicts(rows):
        cells = []
        for est in estimators:
            sel = [r for r in rows if r["estimator"] == est and r["shape"] == v["shape"]
                   and r["noise"] == v["noise"]]
            cells.append(f"{max(r['err_k1'] for r in sel):.3f} / "
                         f"{max(r['err_k2'] for r in sel):.3f}" if sel else "")
        target = f"{v['target'][0]:.3f} / {v['target'][1]:.3f}" if v["target"] else "-"
        if v["noise"] == 0.0:
            target += f" ; {CLEAN_LIMITS[v['shape']]:.0%} rel. (default: " \
                      f"{v['rel_k1']:.2%} / {v['rel_k2']:.2%})"
        mark = "" if v["passed"] else " **missed**"
        lines.append(f"| {v['shape']} | {v['noise']:.1f} | " + " | ".join(cells)
                     + f" | {target}{mark} |")
    timing = {e: np.median([r["seconds"] for r in rows if r["estimator"] == e])
              for e in estimators}
    lines.append("")
    lines.append("Median seconds per 10,000-point cloud: " + ", ".join(
        f"{e} {t:.2f}" for e, t in timing.items()))
    return "\n".join(lines)


def write_csv(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def run_accuracy(config: AccuracyConfig, out, log: Log = _stderr) -> dict:
    """Run the study and write ``accuracy.csv``, ``verdicts.csv``, ``summary.md`` and
    ``config.json`` into ``out``; returns the rows and verdicts."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = accuracy_rows(config, log)
    verdict = verdicts(rows)
    write_csv(out / "accuracy.csv", rows)
    write_csv(out / "verdicts.csv", verdict)
    summary = summary_markdown(rows)
    (out / "summary.md").write_text(summary + "\n")
    (out / "config.json").write_text(json.dumps(
        {**asdict(config), "seconds": time.perf_counter() - t0, "python": sys.version,
         "machine": platform.platform(), "apss": apss_available()}, indent=2, default=str))
    log(summary)
    return {"rows": rows, "verdicts": verdict}


__all__ = ["APSS_ISSUE", "AccuracyConfig", "CLEAN_LIMITS", "SHAPES", "TARGETS",
           "accuracy_rows", "run_accuracy", "summary_markdown", "verdicts"]
