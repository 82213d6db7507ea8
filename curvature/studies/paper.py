"""The accuracy study of Khameneifar & Feng (CAD&A 16(1), 2019, section 3), regenerated.

Three parts, each written as CSV (one row per configuration and seed, plus a summary over
seeds) and PNG plots:

1. **Accuracy** (the paper's Figs. 3 and 4): a torus and a bicubic Bezier patch, ``n_points``
   sampled at random, Gaussian noise of 0 .. 0.5 % of the bounding-box diagonal in both
   readings of "random directions" (``noise_model`` "axis" and "direction"), every
   neighborhood method (TC, 10-NN, 24-NN, mesh, EGG) with the implicit quadric and the Monge
   fit. Statistics of ``|k1 error|`` and ``|k2 error|``: mean and std (the paper's), median and
   p90, and the failure rate. On the Bezier patch only interior points are evaluated
   (``cloud.interior``); the torus has no border. Normals are oriented with the exact normals,
   so a sign flip never counts as a curvature error.
2. **eta** (Figs. 5 and 6): share of points where TC's error is below each other method's, on
   the same cloud (:func:`curvature.evaluation.win_share`: failures lose, ties count half).

Beyond the paper, "TC-24" is TC with ``min_neighbors=24``: the paper's TC gathers about 11
neighbors, so against 24-NN it also differs in size; TC-24 against 24-NN compares the balance
of the neighbors at (nearly) equal size. It appears in every part and in one extra eta pair.
3. **Density reduction** (Fig. 8): on a real scan (``bun000.ply``), estimate on the full scan,
   delete 20/40/60/80 % of the points at random, estimate again and compare at the kept points
   (:func:`curvature.evaluation.density_consistency`). Every method sees the same reduced
   clouds. All runs orient their normals against one reference normal field (24-NN Monge fit
   on the full scan, auto orientation), so sign choices do not differ between runs.

Every cloud and every deletion is seeded; ``seeds`` repeats each configuration and the plots
show the mean over seeds with min/max error bars.

Command line::

    curvature bench paper --out DIR [--quick] [--seeds N] [--workers N] [--data DIR]

matplotlib is imported only by the plotting functions (headless, Agg backend), so the rest of
this module, and the library, work without it.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .. import synthetic
from ..evaluation import density_consistency, error_summary, point_errors, win_share
from ..io import read
from ..neighborhoods import FINDERS
from ..pipeline import estimate

__all__ = [
    "EXTRA_PAIRS",
    "METHODS",
    "PAPER_METHODS",
    "REFERENCE_METHOD",
    "SCAN_NAME",
    "StudyConfig",
    "accuracy_study",
    "aggregate",
    "default_data_dir",
    "density_study",
    "eta_pairs",
    "run_study",
]

#: Label -> (method name for :func:`curvature.estimate`, its parameters): the paper's five
#: neighborhoods (its sizes written out: the library's defaults gather 24), then our
#: size-matched TC variant.
METHODS: dict[str, tuple[str, dict]] = {
    "TC": ("tc", {"min_neighbors": 10, "candidates": 30}),
    "10-NN": ("knn", {"k": 10}),
    "24-NN": ("knn", {"k": 24}),
    "mesh": ("mesh", {"min_neighbors": 10}),
    "EGG": ("egg", {"min_neighbors": 10, "candidates": 30}),
    "TC-24": ("tc", {"min_neighbors": 24, "candidates": 30}),
}
PAPER_METHODS = ("TC", "10-NN", "24-NN", "mesh", "EGG")
#: eta compares this method against every other paper method ...
REFERENCE_METHOD = "TC"
#: ... and these extra pairs (A, B) are compared too.
EXTRA_PAIRS = (("TC-24", "24-NN"),)
#: The real scan of the density study, looked up in the data directory.
SCAN_NAME = "bun000.ply"
#: Neighborhood and fit of the reference normals that orient every density-study run.
REFERENCE_NORMALS = ("knn", {"k": 24}, "monge")

STAT_NAMES = ("mean", "std", "median", "p90")
ERROR_COLUMNS = tuple(f"{k}_{s}" for k in ("k1", "k2") for s in STAT_NAMES)
DENSITY_COLUMNS = tuple(f"{d}_{s}" for d in ("dk1", "dk2", "dH") for s in ("median", "mean"))
CONFIG_KEYS = ("shape", "noise_model", "noise_pct")

Log = Callable[[str], None]


def default_data_dir() -> Path:
    """The shared data folder next to the repository: ``<repo>/../shared/data``."""
    return Path(__file__).resolve().parents[3] / "shared" / "data"


@dataclass(frozen=True)
class StudyConfig:
    """What the study runs. :meth:`full` is the paper's grid, :meth:`quick` a reduced one.

    Attributes
    ----------
    n_points : int
        Points per synthetic cloud.
    noise_levels : tuple of float
        Noise std in percent of the bounding-box diagonal.
    noise_models : tuple of str
        "axis" and/or "direction" (see :mod:`curvature.synthetic`). Noise 0 is computed once
        and reported under every model.
    shapes : tuple of str
        "torus" and/or "bezier".
    methods : tuple of str
        Labels of :data:`METHODS`; methods whose finder is not installed are skipped (and
        listed in ``run.json``).
    fits : tuple of str
        "implicit" and/or "monge".
    seeds : tuple of int
        One synthetic cloud (and one set of deletions) per seed.
    removal_fractions : tuple of float
        Shares of the scan deleted in the density study.
    scan : str or None
        Path of the real scan; None skips the density study.
    workers : int or None
        Threads of each :func:`curvature.estimate` call (None: all cores).
    """

    n_points: int = 10_000
    noise_levels: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
    noise_models: tuple[str, ...] = ("axis", "direction")
    shapes: tuple[str, ...] = ("torus", "bezier")
    methods: tuple[str, ...] = tuple(METHODS)
    fits: tuple[str, ...] = ("implicit", "monge")
    seeds: tuple[int, ...] = (1, 2, 3)
    removal_fractions: tuple[float, ...] = (0.2, 0.4, 0.6, 0.8)
    scan: str | None = None
    workers: int | None = None

    @classmethod
    def full(cls, **changes) -> StudyConfig:
        """The paper's grid: 10,000 points, noise 0 .. 0.5 % in steps of 0.1, three seeds."""
        return replace(cls(), **changes)

    @classmethod
    def quick(cls, **changes) -> StudyConfig:
        """A reduced grid (about a minute): 4,000 points, noise 0/0.25/0.5 %, two seeds."""
        return replace(cls(n_points=4000, noise_levels=(0.0, 0.25, 0.5), seeds=(1, 2),
                           removal_fractions=(0.4, 0.8)), **changes)

    def available_methods(self) -> tuple[str, ...]:
        """The configured methods whose neighborhood finder is installed."""
        return tuple(m for m in self.methods if METHODS[m][0] in FINDERS)


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------
# Accuracy and eta on analytic shapes
# --------------------------------------------------------------------------------------------


def make_cloud(shape: str, n: int, noise: float, noise_model: str, seed: int):
    """One synthetic cloud; the same seed gives the same sample positions at every noise."""
    makers = {"torus": synthetic.torus, "bezier": synthetic.bezier_patch}
    return makers[shape](n, noise=noise, noise_model=noise_model, seed=seed)


def evaluate_cloud(cloud, methods: Sequence[str], fits: Sequence[str], workers) -> dict:
    """Estimate with every method and fit; errors at the evaluated points of ``cloud``.

    Returns
    -------
    dict
        ``(label, fit) -> (PointErrors, extra)`` where ``extra`` holds the median neighbor
        count and the estimate's wall time.
    """
    out = {}
    for label in methods:
        method, params = METHODS[label]
        for fit in fits:
            t0 = time.perf_counter()
            res = estimate(cloud.points, method, fit=fit, normals=cloud.normals,
                           workers=workers, **params)
            seconds = time.perf_counter() - t0
            errors = point_errors(res, cloud.k1, cloud.k2, cloud.interior)
            extra = {"neighbors_median": float(np.median(res.neighbor_count[cloud.interior])),
                     "seconds": seconds}
            out[label, fit] = (errors, extra)
    return out


def accuracy_study(config: StudyConfig, log: Log = _stderr) -> tuple[list[dict], list[dict]]:
    """Error statistics and eta for every shape, seed, noise level, model, method and fit.

    Parameters
    ----------
    config : StudyConfig
    log : callable
        Receives one progress line per cloud.

    Returns
    -------
    accuracy_rows : list of dict
        One row per (shape, noise_model, noise_pct, seed, method, fit) with
        :func:`~curvature.evaluation.error_summary` columns, ``neighbors_median`` and
        ``seconds``.
    eta_rows : list of dict
        One row per (shape, noise_model, noise_pct, seed, fit, pair) with
        :func:`~curvature.evaluation.win_share` columns for ``method`` against ``other``
        (pairs from :func:`eta_pairs`).
    """
    methods = config.available_methods()
    accuracy_rows: list[dict] = []
    eta_rows: list[dict] = []
    for shape in config.shapes:
        for seed in config.seeds:
            for noise in config.noise_levels:
                # Without noise both models give the same cloud: run once, report under each.
                runs = [(m, [m]) for m in config.noise_models] if noise > 0 else \
                    [(config.noise_models[0], list(config.noise_models))]
                for model, reported_as in runs:
                    t0 = time.perf_counter()
                    cloud = make_cloud(shape, config.n_points, noise, model, seed)
                    results = evaluate_cloud(cloud, methods, config.fits, config.workers)
                    for name in reported_as:
                        base = {"shape": shape, "noise_model": name, "noise_pct": noise,
                                "seed": seed, "n_points": config.n_points}
                        accuracy_rows += accuracy_rows_of(base, results)
                        eta_rows += eta_rows_of(base, results, methods, config.fits)
                    log(f"accuracy {shape} seed {seed} noise {noise:g}% {model}: "
                        f"{time.perf_counter() - t0:.1f}s")
    return accuracy_rows, eta_rows


def accuracy_rows_of(base: dict, results: dict) -> list[dict]:
    """Rows of error statistics, one per (method, fit)."""
    return [{**base, "method": label, "fit": fit, **_evaluated(error_summary(errors)), **extra}
            for (label, fit), (errors, extra) in results.items()]


def _evaluated(stats: dict) -> dict:
    """Rename the statistics' ``points`` (evaluated points) so it is not read as n_points."""
    return {("evaluated" if k == "points" else k): v for k, v in stats.items()}


def eta_pairs(methods: Sequence[str]) -> list[tuple[str, str]]:
    """(A, B) pairs compared by eta: TC against each other paper method, then EXTRA_PAIRS."""
    pairs = [(REFERENCE_METHOD, m) for m in methods
             if REFERENCE_METHOD in methods and m in PAPER_METHODS and m != REFERENCE_METHOD]
    return pairs + [(a, b) for a, b in EXTRA_PAIRS if a in methods and b in methods]


def eta_rows_of(base: dict, results: dict, methods: Sequence[str], fits: Sequence[str]):
    """Rows of eta for every pair of :func:`eta_pairs`, per fit."""
    return [{**base, "fit": fit, "pair": f"{a} vs {b}", "method": a, "other": b,
             **_evaluated(win_share(results[a, fit][0], results[b, fit][0]))}
            for fit in fits for a, b in eta_pairs(methods)]


# --------------------------------------------------------------------------------------------
# Density reduction on a real scan
# --------------------------------------------------------------------------------------------


def kept_indices(n: int, removed: float, seed: int) -> np.ndarray:
    """Sorted indices of the points kept after deleting the share ``removed`` at random."""
    rng = np.random.default_rng([seed, round(removed * 1000)])
    keep = n - int(round(removed * n))
    return np.sort(rng.choice(n, size=keep, replace=False))


def reference_normals(points: np.ndarray, workers) -> np.ndarray:
    """One normal field (24-NN Monge, auto orientation) that orients every density run."""
    method, params, fit = REFERENCE_NORMALS
    return estimate(points, method, fit=fit, workers=workers, **params).normals


def density_study(config: StudyConfig, log: Log = _stderr) -> list[dict]:
    """Consistency of every method and fit when part of the scan is deleted.

    Returns
    -------
    list of dict
        One row per (method, fit, removed share, seed) with
        :func:`~curvature.evaluation.density_consistency` columns, plus the failures of the
        full-scan run (``full_failures``) and the wall time of the reduced run.
    """
    if config.scan is None:
        return []
    points = read(config.scan).points
    normals = reference_normals(points, config.workers)
    subsets = {(r, s): kept_indices(len(points), r, s)
               for r in config.removal_fractions for s in config.seeds}
    rows = []
    for label in config.available_methods():
        method, params = METHODS[label]
        for fit in config.fits:
            t0 = time.perf_counter()
            full = estimate(points, method, fit=fit, normals=normals, workers=config.workers,
                            **params)
            full_failures = int((full.status != 0).sum())
            for (removed, seed), kept in subsets.items():
                t1 = time.perf_counter()
                reduced = estimate(points[kept], method, fit=fit, normals=normals[kept],
                                   workers=config.workers, **params)
                rows.append({"scan": Path(config.scan).name, "points": len(points),
                             "method": label, "fit": fit, "removed_pct": 100.0 * removed,
                             "seed": seed, "full_failures": full_failures,
                             **density_consistency(full, reduced, kept),
                             "seconds": time.perf_counter() - t1})
            log(f"density {label} {fit}: {time.perf_counter() - t0:.1f}s")
    return rows


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def aggregate(rows: Iterable[dict], keys: Sequence[str], values: Sequence[str]) -> list[dict]:
    """Summarize rows over seeds: the mean, min and max of each value per group of ``keys``.

    Parameters
    ----------
    rows : iterable of dict
    keys : sequence of str
        Columns that define a group (everything but the seed).
    values : sequence of str
        Numeric columns to summarize; NaN entries are ignored.

    Returns
    -------
    list of dict
        One row per group in first-seen order: the keys, ``seeds`` (rows in the group), and
        ``v``, ``v_min``, ``v_max`` for every value column ``v`` (NaN if all were NaN).
    """
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    out = []
    for key, members in groups.items():
        summary = dict(zip(keys, key, strict=True))
        summary["seeds"] = len(members)
        for v in values:
            arr = np.array([float(r[v]) for r in members])
            arr = arr[np.isfinite(arr)]
            mean, lo, hi = (arr.mean(), arr.min(), arr.max()) if arr.size else (math.nan,) * 3
            summary.update({v: float(mean), f"{v}_min": float(lo), f"{v}_max": float(hi)})
        out.append(summary)
    return out


def write_csv(path: Path, rows: list[dict]) -> None:
    """Write dict rows as CSV (floats with 6 significant digits, NaN as ``nan``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = list(rows[0]) if rows else []
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{v:.6g}" if isinstance(v, float) else v
                             for k, v in row.items()})


def markdown_table(rows: list[dict], row_key: str, col_key: str, value: str,
                   fmt: str = "{:.3g}") -> str:
    """A markdown table of ``value`` with one row per ``row_key`` and column per ``col_key``."""
    row_names = list(dict.fromkeys(r[row_key] for r in rows))
    col_names = list(dict.fromkeys(r[col_key] for r in rows))
    cell = {(r[row_key], r[col_key]): r[value] for r in rows}
    lines = [f"| {row_key} \\ {col_key} | " + " | ".join(f"{c:g}" if isinstance(c, float)
                                                       else str(c) for c in col_names) + " |",
             "|---" * (len(col_names) + 1) + "|"]
    for name in row_names:
        cells = [fmt.format(cell[name, c]) if (name, c) in cell else "" for c in col_names]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_markdown(accuracy: list[dict], eta: list[dict], density: list[dict]) -> str:
    """Tables of the main numbers (means over seeds) for the report."""
    parts = ["# Paper study: summary tables (means over seeds)\n"]
    for shape in dict.fromkeys(r["shape"] for r in accuracy):
        for model in dict.fromkeys(r["noise_model"] for r in accuracy):
            for fit in dict.fromkeys(r["fit"] for r in accuracy):
                sel = [r for r in accuracy if (r["shape"], r["noise_model"], r["fit"])
                       == (shape, model, fit)]
                for stat in ("k1_mean", "k1_median", "k2_mean", "k2_median", "failure_rate"):
                    parts.append(f"## {shape}, {fit} fit, {model} noise: {stat}\n")
                    parts.append(markdown_table(sel, "method", "noise_pct", stat) + "\n")
            for fit in dict.fromkeys(r["fit"] for r in eta):
                sel = [r for r in eta if (r["shape"], r["noise_model"], r["fit"])
                       == (shape, model, fit)]
                for stat in ("eta_k1", "eta_k2"):
                    parts.append(f"## {shape}, {fit} fit, {model} noise: {stat} "
                                 "(share of points where A beats B)\n")
                    parts.append(markdown_table(sel, "pair", "noise_pct", stat, "{:.3f}")
                                 + "\n")
    for fit in dict.fromkeys(r["fit"] for r in density):
        sel = [r for r in density if r["fit"] == fit]
        for stat in ("dk1_median", "dk2_median", "dH_median", "dH_mean"):
            parts.append(f"## density reduction, {fit} fit: {stat}\n")
            parts.append(markdown_table(sel, "method", "removed_pct", stat) + "\n")
    return "\n".join(parts)


# --------------------------------------------------------------------------------------------
# Plots (matplotlib imported lazily, headless)
# --------------------------------------------------------------------------------------------

METHOD_STYLE = {"TC": ("C3", "o"), "10-NN": ("C0", "s"), "24-NN": ("C1", "^"),
                "mesh": ("C2", "v"), "EGG": ("C4", "D"), "TC-24": ("C5", "P")}


def _method_style(row: dict) -> tuple[str, str | None, str, str]:
    """Label, color, marker and line style of a method's line."""
    color, marker = METHOD_STYLE.get(row["method"], (None, "o"))
    return row["method"], color, marker, "--" if row["method"] not in PAPER_METHODS else "-"


def _pair_style(row: dict) -> tuple[str, str | None, str, str]:
    """An eta pair's line: the other method's color, dashed unless A is the reference."""
    color, marker = METHOD_STYLE.get(row["other"], (None, "o"))
    return row["pair"], color, marker, "-" if row["method"] == REFERENCE_METHOD else "--"


def _pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _series(rows: list[dict], x_key: str, value: str):
    """x, mean, and the (lower, upper) error-bar lengths to the min/max over seeds."""
    rows = sorted(rows, key=lambda r: r[x_key])
    x = np.array([r[x_key] for r in rows], float)
    y = np.array([r[value] for r in rows], float)
    lo = np.array([r[f"{value}_min"] for r in rows], float)
    hi = np.array([r[f"{value}_max"] for r in rows], float)
    return x, y, np.vstack([y - lo, hi - y])


def _plot_lines(ax, rows, style, x_key, value, *, dx=0.0, log=False):
    """One error-bar line per label of ``style(row)`` (slightly offset in x to stay apart)."""
    styles = {style(r)[0]: style(r) for r in rows}
    for i, (name, color, marker, line) in enumerate(styles.values()):
        x, y, err = _series([r for r in rows if style(r)[0] == name], x_key, value)
        if log:  # values <= 0 cannot be shown on a log axis
            y = np.where(y > 0, y, np.nan)
        ax.errorbar(x + (i - (len(styles) - 1) / 2) * dx, y, yerr=err, color=color,
                    marker=marker, ms=4, capsize=2, lw=1.2, ls=line, label=name)
    if log:
        ax.set_yscale("log")
    ax.grid(True, which="major", alpha=0.3)


def plot_accuracy(summary: list[dict], out: Path) -> list[Path]:
    """Figs. 3/4: mean, std and median of |k1 error| and |k2 error| against noise.

    One PNG per (shape, fit, noise model), ``errors_{shape}_{fit}_{model}.png``.
    """
    plt = _pyplot()
    paths = []
    for key in dict.fromkeys((r["shape"], r["fit"], r["noise_model"]) for r in summary):
        rows = [r for r in summary if (r["shape"], r["fit"], r["noise_model"]) == key]
        fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), sharex=True)
        for i, k in enumerate(("k1", "k2")):
            for j, stat in enumerate(("mean", "std", "median")):
                ax = axes[i, j]
                _plot_lines(ax, rows, _method_style, "noise_pct", f"{k}_{stat}", dx=0.004,
                            log=True)
                ax.set_title(f"{stat} of |{k} error|")
                if i == 1:
                    ax.set_xlabel("noise std (% of bounding-box diagonal)")
        axes[0, 0].legend(fontsize=8)
        shape, fit, model = key
        where = "interior points" if shape == "bezier" else "all points"
        fig.suptitle(f"{shape} ({where}), {fit} fit, noise model '{model}': mean over seeds, "
                     "bars = min/max over seeds")
        fig.tight_layout()
        paths.append(_save(fig, out / f"errors_{shape}_{fit}_{model}.png"))
    return paths


def plot_eta(summary: list[dict], out: Path) -> list[Path]:
    """Figs. 5/6: eta (A beats B) against noise, per shape and noise model."""
    plt = _pyplot()
    paths = []
    fits = list(dict.fromkeys(r["fit"] for r in summary))
    for shape, model in dict.fromkeys((r["shape"], r["noise_model"]) for r in summary):
        fig, axes = plt.subplots(len(fits), 2, figsize=(11, 3.8 * len(fits)), squeeze=False,
                                 sharex=True, sharey=True)
        for i, fit in enumerate(fits):
            rows = [r for r in summary if (r["shape"], r["noise_model"], r["fit"])
                    == (shape, model, fit)]
            for j, k in enumerate(("k1", "k2")):
                ax = axes[i, j]
                _plot_lines(ax, rows, _pair_style, "noise_pct", f"eta_{k}", dx=0.004)
                ax.axhline(0.5, color="k", lw=0.8, ls="--")
                ax.set_ylim(0, 1)
                ax.set_title(f"{fit} fit: eta for {k}")
                if j == 0:
                    ax.set_ylabel("share of points where A beats B")
        for ax in axes[-1]:
            ax.set_xlabel("noise std (% of bounding-box diagonal)")
        axes[0, 0].legend(fontsize=8)
        fig.suptitle(f"{shape}, noise model '{model}' (failed points lose; ties count half)")
        fig.tight_layout()
        paths.append(_save(fig, out / f"eta_{shape}_{model}.png"))
    return paths


def plot_failures(summary: list[dict], out: Path) -> Path:
    """Failure rate (status != 0) per method against noise, per shape and fit."""
    plt = _pyplot()
    shapes = list(dict.fromkeys(r["shape"] for r in summary))
    fits = list(dict.fromkeys(r["fit"] for r in summary))
    models = list(dict.fromkeys(r["noise_model"] for r in summary))
    fig, axes = plt.subplots(len(shapes), len(fits), figsize=(5.5 * len(fits),
                                                              3.6 * len(shapes)),
                             squeeze=False, sharex=True)
    for i, shape in enumerate(shapes):
        for j, fit in enumerate(fits):
            ax = axes[i, j]
            for model, style in zip(models, ("-", "--", ":"), strict=False):
                for method in dict.fromkeys(r["method"] for r in summary):
                    rows = sorted((r for r in summary if (r["shape"], r["fit"], r["noise_model"],
                                                          r["method"]) == (shape, fit, model,
                                                                           method)),
                                  key=lambda r: r["noise_pct"])
                    ax.plot([r["noise_pct"] for r in rows],
                            [100 * r["failure_rate"] for r in rows], style, marker="o", ms=3,
                            color=METHOD_STYLE.get(method, (None,))[0],
                            label=f"{method} ({model})")
            ax.set_title(f"{shape}, {fit} fit")
            ax.set_ylabel("failed points (%)")
            ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("noise std (% of bounding-box diagonal)")
    axes[0, 0].legend(fontsize=7, ncol=2)
    fig.suptitle("failure rate (status != 0), mean over seeds")
    fig.tight_layout()
    return _save(fig, out / "failures.png")


def plot_density(summary: list[dict], out: Path) -> list[Path]:
    """Fig. 8: median |dk1|, |dk2|, |dH| (reduced vs full scan) against the deleted share."""
    plt = _pyplot()
    paths = []
    for fit in dict.fromkeys(r["fit"] for r in summary):
        rows = [r for r in summary if r["fit"] == fit]
        fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharey=True)
        for ax, name in zip(axes, ("dk1", "dk2", "dH"), strict=True):
            _plot_lines(ax, rows, _method_style, "removed_pct", f"{name}_median", dx=0.6,
                        log=True)
            ax.set_title(f"median |{name}| (1/length unit)")
            ax.set_xlabel("points deleted (%)")
        axes[0].legend(fontsize=8)
        scan = rows[0]["scan"] if "scan" in rows[0] else "scan"
        fig.suptitle(f"density reduction on {scan}, {fit} fit: change at the kept points "
                     "(mean over seeds, bars = min/max)")
        fig.tight_layout()
        paths.append(_save(fig, out / f"density_{fit}.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=100)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------------
# Runner
# --------------------------------------------------------------------------------------------


def run_study(config: StudyConfig, out, *, plots: bool = True, log: Log = _stderr) -> dict:
    """Run every part of the study and write CSV, PNG and a run record into ``out``.

    Parameters
    ----------
    config : StudyConfig
    out : str or Path
        Output folder (created). Files: ``accuracy.csv``, ``accuracy_summary.csv``,
        ``eta.csv``, ``eta_summary.csv``, ``density.csv``, ``density_summary.csv``,
        ``summary.md``, ``run.json`` and the PNG plots.
    plots : bool
        Draw the PNG plots (needs matplotlib).
    log : callable
        Progress lines.

    Returns
    -------
    dict
        The run record also written to ``run.json`` (configuration, skipped methods, wall
        times, files written).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if config.scan is not None and not Path(config.scan).is_file():
        raise FileNotFoundError(f"scan for the density study not found: {config.scan}")
    skipped = sorted(set(config.methods) - set(config.available_methods()))
    if skipped:
        log(f"methods not installed, skipped: {', '.join(skipped)}")
    t_start = time.perf_counter()
    accuracy, eta = accuracy_study(config, log)
    t_accuracy = time.perf_counter() - t_start
    density = density_study(config, log)
    t_density = time.perf_counter() - t_start - t_accuracy

    acc_keys = (*CONFIG_KEYS, "method", "fit")
    acc_sum = aggregate(accuracy, acc_keys, (*ERROR_COLUMNS, "failure_rate", "neighbors_median"))
    eta_sum = aggregate(eta, (*CONFIG_KEYS, "fit", "pair", "method", "other"),
                        ("eta_k1", "eta_k2", "tie_k1", "tie_k2"))
    den_sum = aggregate(density, ("scan", "method", "fit", "removed_pct"),
                        (*DENSITY_COLUMNS, "failed_reduced", "full_failures"))
    tables = {"accuracy": accuracy, "accuracy_summary": acc_sum, "eta": eta,
              "eta_summary": eta_sum, "density": density, "density_summary": den_sum}
    files = []
    for name, rows in tables.items():
        write_csv(out / f"{name}.csv", rows)
        files.append(f"{name}.csv")
    (out / "summary.md").write_text(summary_markdown(acc_sum, eta_sum, den_sum))
    files.append("summary.md")
    if plots:
        pngs = plot_accuracy(acc_sum, out) + plot_eta(eta_sum, out) + [plot_failures(acc_sum,
                                                                                     out)]
        pngs += plot_density(den_sum, out) if den_sum else []
        files += [p.name for p in pngs]
    record = {
        "config": {**asdict(config), "methods": list(config.available_methods())},
        "skipped_methods": skipped,
        "seconds": {"accuracy": round(t_accuracy, 1), "density": round(t_density, 1),
                    "total": round(time.perf_counter() - t_start, 1)},
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__},
        "files": files,
    }
    (out / "run.json").write_text(json.dumps(record, indent=2))
    log(f"wrote {len(files)} files to {out} in {record['seconds']['total']:.0f}s")
    return record
