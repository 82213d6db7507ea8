"""CGAL's jet fitting as an estimator family of the accuracy bench, and the ratio to its best.

Issue 23 holds the default estimator to half the error of CGAL's ``Monge_via_jet_fitting`` tuned
per cell: the grid :data:`JET_SETTINGS` (k = 24, 96, 384 neighbors, jet degree 2 and 4) runs on
every noisy cloud of ``curvature bench accuracy`` (:mod:`curvature.studies.accuracy`), through
:mod:`curvature.studies.peers.cgal`, with the exact normals for orientation only. Its rows carry
the estimator names of :func:`jet_name` (``"jet96d4"``).

The error figure of a row is the mean of its k1 and k2 mean absolute errors
(:func:`error_figure`). Per shape, noise level and noise model, :func:`jet_ratios` averages it
over the seeds for the default and for each jet setting, picks the setting with the lowest
average (the best-tuned jet a user could have chosen for that cell) and reports
``default / best``; the target is :data:`RATIO_TARGET` (0.5).
"""

from __future__ import annotations

import math
import re

import numpy as np

#: Neighbor counts and jet degrees of the grid (issue 23).
JET_KS = (24, 96, 384)
JET_DEGREES = (2, 4)
#: Every (k, degree) setting of the grid.
JET_SETTINGS = tuple((k, d) for k in JET_KS for d in JET_DEGREES)
#: Highest admitted ratio of the default's error to the best jet setting's.
RATIO_TARGET = 0.5

_NAME = re.compile(r"jet(\d+)d(\d+)")


def jet_name(k: int, degree: int) -> str:
    """Estimator name of one jet setting, e.g. ``jet_name(96, 4) == "jet96d4"``.

    Parameters
    ----------
    k : int
        Neighbors per fit.
    degree : int
        Jet degree.

    Returns
    -------
    str
    """
    return f"jet{int(k)}d{int(degree)}"


def parse_jet_name(name: str) -> tuple[int, int] | None:
    """``(k, degree)`` of a jet estimator name, or None for any other estimator.

    Parameters
    ----------
    name : str

    Returns
    -------
    tuple of int or None
    """
    m = _NAME.fullmatch(name)
    return (int(m[1]), int(m[2])) if m else None


def jets_unavailable_reason() -> str | None:
    """Why the jet family cannot run here (missing headers or compiler, failed build), or None.

    Builds the CGAL driver once when everything is present, so a compile error shows up before
    the grid starts rather than in its first cell.

    Returns
    -------
    str or None
    """
    from .peers.cgal import CgalBuildError, build_cgal_jet, cgal_unavailable_reason

    reason = cgal_unavailable_reason()
    if reason is not None:
        return reason
    try:
        build_cgal_jet()
    except CgalBuildError as exc:
        return str(exc)
    return None


def run_jet(name: str, cloud, workers=None) -> tuple[np.ndarray, np.ndarray]:
    """k1, k2 of one jet setting on one synthetic cloud (NaN where the fit failed).

    Parameters
    ----------
    name : str
        A :func:`jet_name`.
    cloud : curvature.synthetic.SyntheticCloud
        Its exact normals only orient the result, as for every estimator of the bench.
    workers : int, optional
        Threads of the CGAL driver (default: all cores).

    Returns
    -------
    k1, k2 : ndarray, shape (n,)
    """
    from .peers.cgal import cgal_jet_curvature

    setting = parse_jet_name(name)
    if setting is None:
        raise ValueError(f"not a jet estimator name: {name!r}")
    k, degree = setting
    k1, k2, _, _ = cgal_jet_curvature(cloud.points, cloud.normals, k=k, degree=degree,
                                      workers=workers)
    return k1, k2  # already NaN where status != 0


def error_figure(row: dict) -> float:
    """The issue's error figure of one row: mean of the k1 and k2 mean absolute errors."""
    return 0.5 * (float(row["err_k1"]) + float(row["err_k2"]))


def _model(row: dict) -> str:
    return row.get("noise_model", "axis")


def jet_ratios(rows: list[dict], estimator: str = "default",
               target: float = RATIO_TARGET) -> list[dict]:
    """Per shape, noise level (> 0) and noise model: ``estimator``'s error over the best jet's.

    Parameters
    ----------
    rows : list of dict
        Bench rows with ``shape``, ``noise``, ``noise_model`` (``"axis"`` when absent),
        ``seed``, ``estimator``, ``err_k1`` and ``err_k2``; rows of other estimators are ignored.
    estimator : str
        The estimator held to the target.
    target : float
        Highest ratio that passes.

    Returns
    -------
    list of dict
        One per cell where both ``estimator`` and at least one jet setting have a finite error,
        in the order the cells first appear: ``shape``, ``noise``, ``noise_model``, ``seeds``,
        ``default`` (its error figure averaged over the seeds), ``best_jet`` (name), ``best_k``,
        ``best_degree``, ``best_error`` (that setting's average), ``ratio`` (``default /
        best_error``), ``worst_seed_ratio`` (the largest ratio of one seed against the best
        setting on the same seed), ``runner_up`` (second best setting's average) and ``passed``
        (``ratio <= target``).
    """
    cells: dict[tuple, dict[str, dict[int, float]]] = {}
    for r in rows:
        if r["noise"] <= 0.0 or (r["estimator"] != estimator
                                 and parse_jet_name(r["estimator"]) is None):
            continue
        cell = cells.setdefault((r["shape"], r["noise"], _model(r)), {})
        cell.setdefault(r["estimator"], {})[r["seed"]] = error_figure(r)
    out = []
    for (shape, noise, model), by_est in cells.items():
        own = by_est.get(estimator)
        if not own:
            continue
        default = float(np.mean(list(own.values())))
        # Mean over the seeds the default also ran on, so both sides average the same clouds.
        means = {}
        for name, errs in by_est.items():
            if name == estimator:
                continue
            shared = [errs[s] for s in own if s in errs]
            if shared and all(math.isfinite(e) for e in shared):
                means[name] = float(np.mean(shared))
        if not means or not math.isfinite(default):
            continue
        ranked = sorted(means, key=lambda n: (means[n], n))
        best = ranked[0]
        k, degree = parse_jet_name(best)
        per_seed = [own[s] / by_est[best][s] for s in own if s in by_est[best]]
        ratio = default / means[best]
        out.append({"shape": shape, "noise": noise, "noise_model": model, "seeds": len(own),
                    "default": default, "best_jet": best, "best_k": k, "best_degree": degree,
                    "best_error": means[best], "ratio": ratio,
                    "worst_seed_ratio": max(per_seed),
                    "runner_up": means[ranked[1]] if len(ranked) > 1 else math.nan,
                    "passed": bool(ratio <= target)})
    return out


def jet_csv_rows(rows: list[dict]) -> list[dict]:
    """The jet rows of ``rows``, each with its ``k`` and ``degree`` after the estimator name."""
    out = []
    for r in rows:
        setting = parse_jet_name(r["estimator"])
        if setting is None:
            continue
        row = {}
        for key, value in r.items():
            row[key] = value
            if key == "estimator":
                row["k"], row["degree"] = setting
        out.append(row)
    return out


def ratio_markdown(ratios: list[dict], target: float = RATIO_TARGET) -> str:
    """Table of :func:`jet_ratios`, then how many cells pass and which settings win.

    Parameters
    ----------
    ratios : list of dict
        Output of :func:`jet_ratios`.
    target : float
        The ratio limit named in the header.

    Returns
    -------
    str
        Markdown.
    """
    lines = [f"| shape | noise % | model | default | best jet (setting) | ratio | "
             f"verdict (<= {target:g}) |", "|---|---|---|---|---|---|---|"]
    for r in ratios:
        verdict = "ok" if r["passed"] else "**missed**"
        lines.append(f"| {r['shape']} | {r['noise']:.1f} | {r['noise_model']} | "
                     f"{r['default']:.4f} | {r['best_error']:.4f} ({r['best_jet']}) | "
                     f"{r['ratio']:.2f} | {verdict} |")
    if ratios:
        passed = sum(r["passed"] for r in ratios)
        worst = max(ratios, key=lambda r: r["ratio"])
        wins: dict[str, int] = {}
        for r in ratios:
            wins[r["best_jet"]] = wins.get(r["best_jet"], 0) + 1
        lines += ["", f"{passed} of {len(ratios)} ratios at most {target:g}; the largest "
                  f"{worst['ratio']:.2f} ({worst['shape']}, {worst['noise']:.1f} %, "
                  f"{worst['noise_model']}). Error: mean of the k1 and k2 mean |errors| over "
                  f"the interior points, averaged over {ratios[0]['seeds']} seed(s). Best "
                  "setting per cell: " + ", ".join(
                      f"{n} {c}" for n, c in sorted(wins.items(), key=lambda x: -x[1])) + "."]
    return "\n".join(lines)


def jet_timing(rows: list[dict]) -> str:
    """One line: median seconds per cloud of each jet setting present in ``rows``."""
    names = [jet_name(k, d) for k, d in sorted({parse_jet_name(r["estimator"]) for r in rows
                                                 if parse_jet_name(r["estimator"])})]
    if not names:
        return ""
    return "Median seconds per cloud (CGAL): " + ", ".join(
        f"{n} {np.median([r['seconds'] for r in rows if r['estimator'] == n]):.2f}"
        for n in names)


__all__ = ["JET_DEGREES", "JET_KS", "JET_SETTINGS", "RATIO_TARGET", "error_figure",
           "jet_csv_rows", "jet_name", "jet_ratios", "jet_timing", "jets_unavailable_reason",
           "parse_jet_name", "ratio_markdown", "run_jet"]
