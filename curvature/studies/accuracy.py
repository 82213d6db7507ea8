"""Accuracy of the default estimator against issue 6's targets, beside the paper and APSS.

Synthetic clouds of ``n_points`` (10,000) with Gaussian noise of 0 .. 0.5 % of the
bounding-box diagonal, in both noise models of :mod:`curvature.synthetic` (``"axis"``: per-axis;
``"view"``: along one viewing direction, as a scanner's range noise; without noise they are the
same cloud, so noise 0 runs once): torus (R=2, r=1), ellipsoid (3, 2, 1), unit sphere, the
bicubic Bezier patch and a cylinder. Estimators:

* ``default``: ``curvature.estimate(points)`` with no parameter (method "auto");
* ``paper``: ``preset="paper"`` (Territory Claiming, 10 neighbors, implicit quadric);
* ``apss``: MeshLab's APSS (filter scale 8) through :mod:`curvature.studies.peers.apss`, on normals
  estimated from the points (pymeshlab's plane fit over 30 neighbors), run only when
  ``pymeshlab`` is installed (the ``bench`` extra). With these normals it reproduces the issue's
  APSS figures within about 10 %; given the exact normals APSS would be about twice as accurate,
  an advantage no estimator has on a real scan;
* ``jet<k>d<degree>``: CGAL's jet fitting at every setting of
  :data:`curvature.studies.jets.JET_SETTINGS` (k = 24, 96, 384; degree 2 and 4) on the noisy
  clouds, run only when CGAL's headers and a C++ compiler are present
  (:mod:`curvature.studies.peers.cgal`). :mod:`curvature.studies.jets` reports the default's
  error over the best of these settings per shape, noise level and model (issue 23: at most 0.5).

Every estimator gets the exact normals for orientation only, so a sign flip never counts as a
curvature error. Errors are mean ``|k1 - k1_true|`` and ``|k2 - k2_true|`` over interior points
whose estimate succeeded (failures are counted apart), and their relative form (divided by the
mean true ``|k|``; a zero principal curvature, as on the cylinder, is measured against the other
one). The targets (:data:`TARGETS`) are half of APSS's errors at 0.5 % noise as measured in the
issue, for every noise level, and 1 % (sphere, cylinder, ellipsoid) or 3 % (torus, Bezier)
relative error without noise.

Command line::

    curvature bench accuracy --out DIR [--quick] [--seeds N] [--no-apss] [--no-jets]
                             [--noise-models axis,view]

Files: ``accuracy.csv`` (default, paper, APSS rows), ``verdicts.csv``, ``jets.csv`` (every jet
setting's rows), ``jet_ratios.csv``, ``summary.md`` and ``config.json``.
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
from . import jets

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
#: Noise models every estimator runs on (names of :data:`curvature.synthetic.NOISE_MODELS`).
NOISE_MODELS = ("axis", "view")

Log = Callable[[str], None]


@dataclass(frozen=True)
class AccuracyConfig:
    """What to run. ``full`` is the issue's grid (about 40 minutes on 2 cores with CGAL's jet
    grid, which takes most of it); ``quick`` (noise 0 and 0.5 %, one seed) a few minutes."""

    n_points: int = 10_000
    noises: tuple = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
    seeds: tuple = (1, 2)
    shapes: tuple = tuple(SHAPES)
    estimators: tuple = ESTIMATORS
    noise_models: tuple = NOISE_MODELS
    #: (k, degree) of the CGAL jet settings run on the noisy clouds; empty leaves CGAL out.
    jets: tuple = jets.JET_SETTINGS
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
    """k1, k2 of one estimator on one cloud (NaN where it failed).

    Parameters
    ----------
    name : str
        ``"default"``, ``"paper"``, ``"apss"`` or a jet name (``"jet96d4"``).
    cloud : curvature.synthetic.SyntheticCloud
        Its exact normals only orient the results.
    workers : int or None
        Threads of each estimate.

    Returns
    -------
    k1, k2 : ndarray, shape (n,)
    """
    if jets.parse_jet_name(name) is not None:
        return jets.run_jet(name, cloud, workers)
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


def jet_estimators(config: AccuracyConfig, log: Log = _stderr) -> list[str]:
    """Names of the jet settings to run, or none (with the reason logged) without CGAL."""
    if not config.jets:
        return []
    reason = jets.jets_unavailable_reason()
    if reason is not None:
        log(f"CGAL jet fitting is left out: {reason}")
        return []
    return [jets.jet_name(k, d) for k, d in config.jets]


def accuracy_rows(config: AccuracyConfig, log: Log = _stderr) -> list[dict]:
    """One row per shape, noise, noise model, seed and estimator (jets on noisy clouds only).

    Parameters
    ----------
    config : AccuracyConfig
    log : callable
        Receives one line per run and the reasons an estimator is left out.

    Returns
    -------
    list of dict
        ``shape``, ``noise``, ``noise_model``, ``seed``, ``estimator``, the errors of
        :func:`error_row` and ``seconds``.
    """
    estimators = [e for e in config.estimators if e != "apss" or apss_available()]
    if "apss" in config.estimators and "apss" not in estimators:
        log("pymeshlab is not installed: APSS is left out (pip install 'curvature[bench]')")
    jet_names = jet_estimators(config, log)
    rows = []
    for shape in config.shapes:
        name, kwargs = SHAPES[shape]
        for noise in config.noises:
            # Without noise every model gives the same cloud, and the ratio is for noisy ones.
            models = config.noise_models if noise > 0 else config.noise_models[:1]
            names = estimators + (jet_names if noise > 0 else [])
            for model in models:
                for seed in config.seeds:
                    cloud = synthetic.make(name, config.n_points, noise=noise,
                                           noise_model=model, seed=seed, **kwargs)
                    for est in names:
                        t = time.perf_counter()
                        k1, k2 = run_estimator(est, cloud, config.workers)
                        dt = time.perf_counter() - t
                        row = {"shape": shape, "noise": noise, "noise_model": model,
                               "seed": seed, "estimator": est,
                               **error_row(cloud, k1, k2), "seconds": dt}
                        rows.append(row)
                        log(f"{shape:9} noise {noise:.1f} {model:4} seed {seed} {est:8} "
                            f"|k1| {row['err_k1']:.4f} |k2| {row['err_k2']:.4f} "
                            f"({row['rel_k1']:.2%} / {row['rel_k2']:.2%}) {dt:.2f}s")
    return rows


def _model(row: dict) -> str:
    return row.get("noise_model", "axis")


def verdicts(rows: list[dict], estimator: str = "default") -> list[dict]:
    """Per shape, noise and noise model, the worst seed of ``estimator`` against issue 6's limits.

    The limits were set on per-axis noise; they apply unchanged to the view model.
    """
    out = []
    keys = sorted({(r["shape"], r["noise"], _model(r)) for r in rows
                   if r["estimator"] == estimator},
                  key=lambda k: (list(SHAPES).index(k[0]), NOISE_MODELS.index(k[2])
                                 if k[2] in NOISE_MODELS else len(NOISE_MODELS), k[1]))
    for shape, noise, model in keys:
        sel = [r for r in rows if r["estimator"] == estimator and r["shape"] == shape
               and r["noise"] == noise and _model(r) == model]
        worst = {k: max(r[k] for r in sel) for k in ("err_k1", "err_k2", "rel_k1", "rel_k2")}
        target = TARGETS[shape]
        passed = target is None or (worst["err_k1"] <= target[0]
                                    and worst["err_k2"] <= target[1])
        if noise == 0.0:
            passed = passed and max(worst["rel_k1"], worst["rel_k2"]) <= CLEAN_LIMITS[shape]
        out.append({"shape": shape, "noise": noise, "noise_model": model, **worst,
                    "target": target, "passed": passed})
    return out


def summary_markdown(rows: list[dict]) -> str:
    """Tables: worst seed per estimator, then the default's verdicts."""
    estimators = [e for e in ESTIMATORS if any(r["estimator"] == e for r in rows)]
    lines = ["| shape | noise % | model | " + " | ".join(f"{e} k1 / k2" for e in estimators)
             + " | target (issue 6) |", "|---|---|---|" + "---|" * len(estimators) + "---|"]
    for v in verdicts(rows):
        cells = []
        for est in estimators:
            sel = [r for r in rows if r["estimator"] == est and r["shape"] == v["shape"]
                   and r["noise"] == v["noise"] and _model(r) == v["noise_model"]]
            cells.append(f"{max(r['err_k1'] for r in sel):.3f} / "
                         f"{max(r['err_k2'] for r in sel):.3f}" if sel else "")
        target = f"{v['target'][0]:.3f} / {v['target'][1]:.3f}" if v["target"] else "-"
        if v["noise"] == 0.0:
            target += f" ; {CLEAN_LIMITS[v['shape']]:.0%} rel. (default: " \
                      f"{v['rel_k1']:.2%} / {v['rel_k2']:.2%})"
        mark = "" if v["passed"] else " **missed**"
        lines.append(f"| {v['shape']} | {v['noise']:.1f} | {v['noise_model']} | "
                     + " | ".join(cells)
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
    """Run the study and write its files into ``out``.

    Parameters
    ----------
    config : AccuracyConfig
    out : str or os.PathLike
        Output folder (created): ``accuracy.csv`` (default, paper, APSS), ``verdicts.csv``,
        ``summary.md``, ``config.json`` and, when CGAL ran, ``jets.csv`` (every jet row) and
        ``jet_ratios.csv`` (:func:`curvature.studies.jets.jet_ratios`).
    log : callable

    Returns
    -------
    dict
        ``rows`` (every row, jets included), ``verdicts`` and ``ratios``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = accuracy_rows(config, log)
    base = [r for r in rows if jets.parse_jet_name(r["estimator"]) is None]
    jet_rows = jets.jet_csv_rows(rows)
    verdict = verdicts(base)
    ratios = jets.jet_ratios(rows)
    write_csv(out / "accuracy.csv", base)
    write_csv(out / "verdicts.csv", verdict)
    summary = summary_markdown(base)
    if jet_rows:
        write_csv(out / "jets.csv", jet_rows)
    if ratios:
        write_csv(out / "jet_ratios.csv", ratios)
        summary += ("\n\n## The default against the best CGAL jet setting (issue 23)\n\n"
                    + jets.ratio_markdown(ratios) + "\n\n" + jets.jet_timing(jet_rows))
    (out / "summary.md").write_text(summary + "\n")
    (out / "config.json").write_text(json.dumps(
        {**asdict(config), "seconds": time.perf_counter() - t0, "python": sys.version,
         "machine": platform.platform(), "apss": apss_available(), "cgal": bool(jet_rows)},
        indent=2, default=str))
    log(summary)
    return {"rows": rows, "verdicts": verdict, "ratios": ratios}


__all__ = ["APSS_ISSUE", "AccuracyConfig", "CLEAN_LIMITS", "NOISE_MODELS", "SHAPES", "TARGETS",
           "accuracy_rows", "jet_estimators", "run_accuracy", "summary_markdown", "verdicts"]
