"""Accuracy on machined-part shapes, per region, beside MeshLab's APSS and CGAL's jet fitting.

Shapes from :mod:`curvature.synthetic.parts` (filleted box, blade, thin plate, stepped
cylinder) at several noise levels and models (per-axis, along one view direction, with 1 %
outliers). Every estimator gets the exact normals for orientation only. Per region (face,
fillet, corner, edge zone, ...) the study reports mean, median and 99th percentile of
``max(|k1 err|, |k2 err|)`` and the mean of each, over the points whose estimate succeeded
(failures counted apart; outliers are never scored). Estimators:

* ``default``: ``curvature.estimate(points)``;
* ``apss``: MeshLab's APSS at filter scale 8 (when ``pymeshlab`` is installed);
* ``jet24d4`` and ``jet96d2``: CGAL's ``Monge_via_jet_fitting`` over 24 neighbors at degree 4
  and over 96 at degree 2 (when :mod:`curvature.studies.peers.cgal` finds CGAL's headers).

Plots (``profile_<case>.png``): the estimated k1 (median per bin) against the signed distance
from the nearest curvature jump, negative on the flat side and positive inside the fillet or
edge, beside the exact value: how far each estimator smears a feature.

Command line::

    curvature bench parts --out DIR [--quick] [--no-apss]

``curvature bench accuracy`` runs it too, into ``DIR/parts``.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import synthetic
from ..pipeline import estimate

Log = Callable[[str], None]

#: Case label -> (shape, keyword arguments).
CASES: dict[str, tuple[str, dict]] = {
    "box_clean": ("filleted_box", {"noise": 0.0}),
    "box_0.05": ("filleted_box", {"noise": 0.05}),
    "box_0.1": ("filleted_box", {"noise": 0.1}),
    "box_0.05_view": ("filleted_box", {"noise": 0.05, "noise_model": "view"}),
    "box_0.05_outliers": ("filleted_box", {"noise": 0.05, "outliers": 0.01}),
    "blade_clean": ("blade", {"noise": 0.0}),
    "blade_0.1": ("blade", {"noise": 0.1}),
    "plate_0.1": ("thin_plate", {"noise": 0.1}),
    "stepped_cylinder_0.1": ("filleted_cylinder", {"noise": 0.1, "fillet": 0.1,
                                                   "step": (0.6, 1.0)}),
}
QUICK_CASES = ("box_0.05", "blade_0.1")
#: ``default_auto_sign`` is the default as a user without normals runs it: the signs from its
#: own orientation (the others take them from the exact normals), so a side oriented the
#: wrong way shows as errors of twice the curvature.
ESTIMATORS = ("default", "default_auto_sign", "apss", "jet24d4", "jet96d2")


def _stderr(message: str) -> None:
    import sys

    print(message, file=sys.stderr, flush=True)


def available_estimators(requested=ESTIMATORS, log: Log = _stderr) -> list[str]:
    """The requested estimators whose peer is installed here (the others are logged)."""
    out = []
    for name in requested:
        if name == "apss":
            from .peers.apss import apss_available

            if not apss_available():
                log("pymeshlab is not installed: APSS is left out (pip install 'curvature[bench]')")
                continue
        if name.startswith("jet"):
            try:
                from .peers.cgal import cgal_available
            except ImportError:
                log("curvature.studies.peers.cgal is missing: CGAL jet fitting is left out")
                continue
            if not cgal_available():
                log("CGAL's headers or a C++ compiler are missing: jet fitting is left out")
                continue
        out.append(name)
    return out


def run_estimator(name: str, cloud) -> tuple[np.ndarray, np.ndarray]:
    """k1, k2 of one estimator on a synthetic cloud (exact normals for orientation only,
    but for ``default_auto_sign``)."""
    if name in ("default", "default_auto_sign"):
        res = estimate(cloud.points, normals=cloud.normals if name == "default" else None)
        return res.k1, res.k2
    if name == "apss":
        from .accuracy import run_estimator as accuracy_estimator

        return accuracy_estimator("apss", cloud, None)
    from .peers.cgal import cgal_jet_curvature

    k, degree = {"jet24d4": (24, 4), "jet96d2": (96, 2)}[name]
    k1, k2, _, status = cgal_jet_curvature(cloud.points, cloud.normals, k=k, degree=degree)
    bad = status != 0
    return np.where(bad, np.nan, k1), np.where(bad, np.nan, k2)


def region_rows(case: str, cloud, name: str, k1, k2, seconds: float) -> list[dict]:
    """One row per region of ``cloud`` with the error statistics of one estimator."""
    e1 = np.abs(k1 - cloud.k1)
    e2 = np.abs(k2 - cloud.k2)
    worst = np.fmax(e1, e2)
    rows = []
    for region in cloud.region_names:
        m = cloud.region_mask(region) & cloud.interior
        if region == "outlier" or not m.any():
            continue
        ok = m & np.isfinite(worst)
        w = worst[ok]
        rows.append({
            "case": case, "shape": cloud.name, "noise": cloud.noise,
            "noise_model": cloud.noise_model, "outliers": cloud.params.get("outliers", 0.0),
            "estimator": name, "region": region, "points": int(m.sum()),
            "failed": int(m.sum() - ok.sum()),
            "mean_k1": float(np.mean(e1[ok])) if ok.any() else np.nan,
            "mean_k2": float(np.mean(e2[ok])) if ok.any() else np.nan,
            "mean": float(np.mean(w)) if w.size else np.nan,
            "median": float(np.median(w)) if w.size else np.nan,
            "p99": float(np.percentile(w, 99)) if w.size else np.nan,
            "max": float(np.max(w)) if w.size else np.nan,
            "feature_k": float(np.nanmax(np.abs(cloud.k1))),
            "seconds": seconds,
        })
    return rows


def profile_plot(path: Path, case: str, cloud, estimates: dict) -> None:
    """Median estimated k1 against the signed distance from the nearest curvature jump."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spacing = cloud.params["spacing"]
    flat = (cloud.k1 == 0) & (cloud.k2 == 0)
    signed = np.where(flat, -1.0, 1.0) * cloud.feature_distance / spacing
    keep = cloud.interior & np.isfinite(signed) & (np.abs(signed) < 12) & np.isfinite(cloud.k1)
    # The region with the sharpest exact k1 next to a flat one: the feature to look across.
    feature_k = np.nanmax(cloud.k1[keep & ~flat]) if (keep & ~flat).any() else 0.0
    across = keep & (flat | np.isclose(cloud.k1, feature_k))
    edges = np.linspace(-12, 12, 49)
    mids = 0.5 * (edges[1:] + edges[:-1])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.step(mids, np.where(mids > 0, feature_k, 0.0), where="mid", color="k", lw=2,
            label="exact")
    for name, (k1, _) in estimates.items():
        med = np.full(mids.size, np.nan)
        for i in range(mids.size):
            sel = across & (signed >= edges[i]) & (signed < edges[i + 1]) & np.isfinite(k1)
            if sel.sum() >= 5:
                med[i] = np.median(k1[sel])
        ax.plot(mids, med, marker=".", label=name)
    ax.set_xlabel("signed distance from the curvature jump (point spacings; < 0: flat side)")
    ax.set_ylabel("k1 (1/length), median per bin")
    ax.set_title(f"{case}: across the k1 = {feature_k:g} feature")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def summary_markdown(rows: list[dict]) -> str:
    """Table of mean (median) max(|k1 err|, |k2 err|) per case, region and estimator."""
    estimators = list(dict.fromkeys(r["estimator"] for r in rows))
    lines = ["| case | region | " + " | ".join(estimators) + " |",
             "|---|---|" + "---|" * len(estimators)]
    keys = list(dict.fromkeys((r["case"], r["region"]) for r in rows))
    table = {(r["case"], r["region"], r["estimator"]): r for r in rows}
    for case, region in keys:
        cells = []
        for name in estimators:
            r = table.get((case, region, name))
            cells.append("" if r is None else f"{r['mean']:.3g} ({r['median']:.3g})")
        lines.append(f"| {case} | {region} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run_parts(out, *, quick: bool = False, estimators=ESTIMATORS, n_points: int | None = None,
              log: Log = _stderr) -> list[dict]:
    """Run the study; write ``parts.csv``, ``parts_summary.md``, ``config.json`` and the
    profile plots into ``out``. Returns the rows."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = available_estimators(estimators, log)
    cases = QUICK_CASES if quick else tuple(CASES)
    rows: list[dict] = []
    t_start = time.perf_counter()
    for case in cases:
        shape, kwargs = CASES[case]
        size = {} if n_points is None else {"n": n_points}
        cloud = synthetic.make(shape, seed=1, **size, **kwargs)
        estimates = {}
        for name in names:
            t0 = time.perf_counter()
            k1, k2 = run_estimator(name, cloud)
            dt = time.perf_counter() - t0
            estimates[name] = (k1, k2)
            rows.extend(region_rows(case, cloud, name, k1, k2, dt))
            log(f"{case:22} {name:8} {dt:6.1f} s")
        profile_plot(out / f"profile_{case}.png", case, cloud, estimates)
    with open(out / "parts.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    summary = summary_markdown(rows)
    (out / "parts_summary.md").write_text(summary + "\n")
    (out / "config.json").write_text(json.dumps(
        {"cases": {c: CASES[c] for c in cases}, "estimators": names, "n_points": n_points,
         "seconds": time.perf_counter() - t_start}, indent=2, default=str))
    log(summary)
    return rows


__all__ = ["CASES", "ESTIMATORS", "available_estimators", "region_rows", "run_estimator",
           "run_parts", "summary_markdown"]
