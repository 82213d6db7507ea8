"""Calibration of the per-point standard errors (issue 16) on shapes with exact curvature.

For every shape (smooth: torus, sphere, ellipsoid, Bezier patch, cylinder; parts: filleted
box, blade, thin plate, filleted cylinder), noise level (% of the bounding-box diagonal) and
noise model (per axis, along the view), one estimate; over the points with a true curvature
(``interior``) and status 0 it records

- ``cov_k1``, ``cov_k2``, ``cov_mean``: share of points whose true error is within 2 standard
  errors (target 0.90 to 0.98);
- ``rho_k1``, ``rho_k2``: Spearman correlation of the standard error with the absolute error
  (target >= 0.5 on noisy clouds), and ``rho_ceiling``: the correlation a perfect standard
  error would reach on this cell (errors drawn as ``std * |z|`` with z normal): where the
  standard errors barely vary over a shape (a sphere: every point alike) no estimate can rank
  its points, and the ceiling says so;
- the observed coverage at nominal levels 50 to 99 % (the calibration plot).

On a real scan (``--scan ../shared/data/bun000.ply``) it renders a preview colored by the
standard error of k1 and compares the standard error at the edges of the range image (points
whose neighbors lie to one side) with the rest.

    python benchmarks/uncertainty.py [--method auto] [--out docs/figures/uncertainty]
    python benchmarks/uncertainty.py --scan ../shared/data/bun000.ply
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import norm, spearmanr

import curvature
from curvature import synthetic

SMOOTH = ("torus", "sphere", "ellipsoid", "bezier_patch", "cylinder")
PARTS = ("filleted_box", "blade", "thin_plate", "filleted_cylinder")
NOISES = (0.0, 0.05, 0.1, 0.25, 0.5)
MODELS = ("axis", "view")
NOMINAL = (0.5, 0.68, 0.8, 0.9, 0.95, 0.99)
BAND = (0.90, 0.98)
RHO_TARGET = 0.5


def make_cloud(shape: str, noise: float, model: str, seed: int):
    """A cloud of the benchmark: smooth shapes with 10,000 points, parts at their default."""
    kw = {"noise": noise, "noise_model": model, "seed": seed}
    if shape in SMOOTH:
        return getattr(synthetic, shape)(10_000, **kw)
    return getattr(synthetic, shape)(**kw)


def cell_metrics(res, cloud, seed: int) -> dict:
    """Coverage, rank correlation and coverage curve of one estimate (module docstring)."""
    keep = cloud.interior & (res.status == 0) & np.isfinite(cloud.k1) & np.isfinite(cloud.k2)
    truth = {"k1": cloud.k1, "k2": cloud.k2, "mean": 0.5 * (cloud.k1 + cloud.k2)}
    out = {"points": int(keep.sum())}
    rng = np.random.default_rng(seed)
    for name, true in truth.items():
        err = np.abs(getattr(res, name) - true)[keep]
        std = getattr(res, f"{name}_std")[keep]
        out[f"cov_{name}"] = float(np.mean(err <= 2.0 * std))
        if name != "mean":
            out[f"rho_{name}"] = float(spearmanr(std, err).statistic)
            out[f"med_err_{name}"] = float(np.median(err))
            out[f"med_std_{name}"] = float(np.median(std))
        if name == "k1":
            ideal = std * np.abs(rng.normal(size=std.shape))
            out["rho_ceiling"] = float(spearmanr(std, ideal).statistic)
            for p in NOMINAL:
                out[f"obs_{p:g}"] = float(np.mean(err <= norm.ppf(0.5 + p / 2) * std))
    out["uncertain"] = float(res.uncertain[cloud.interior].mean())
    return out


def run(method: str, seed: int, shapes, noises, models) -> list[dict]:
    rows = []
    for shape in shapes:
        for noise in noises:
            for model in (models[:1] if noise == 0.0 else models):
                cloud = make_cloud(shape, noise, model, seed)
                kw = {"k": 24, "fit": "monge"} if method == "knn" else {}
                t0 = time.perf_counter()
                res = curvature.estimate(cloud.points, method, normals=cloud.normals, **kw)
                row = {"shape": shape, "group": "smooth" if shape in SMOOTH else "parts",
                       "noise": noise, "model": model if noise else "-",
                       "seconds": round(time.perf_counter() - t0, 2),
                       **cell_metrics(res, cloud, seed)}
                rows.append(row)
                print(f"{shape:18} {noise:5.2f} {row['model']:5} cov k1 {row['cov_k1']:.3f} "
                      f"k2 {row['cov_k2']:.3f} H {row['cov_mean']:.3f}  rho {row['rho_k1']:.2f} "
                      f"{row['rho_k2']:.2f} (ceiling {row['rho_ceiling']:.2f})", flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    """Shares of cells in the coverage band and at the rank-correlation target."""
    noisy = [r for r in rows if r["noise"] > 0]
    in_band = [all(BAND[0] <= r[f"cov_{k}"] <= BAND[1] for k in ("k1", "k2")) for r in noisy]
    rho_ok = [min(r["rho_k1"], r["rho_k2"]) >= RHO_TARGET for r in noisy]
    ceiling_ok = [r["rho_ceiling"] >= RHO_TARGET for r in noisy]
    return {"noisy_cells": len(noisy), "coverage_in_band": float(np.mean(in_band)),
            "coverage_at_least_90": float(np.mean([min(r["cov_k1"], r["cov_k2"]) >= BAND[0]
                                                   for r in noisy])),
            "spearman_at_target": float(np.mean(rho_ok)),
            "ceiling_at_target": float(np.mean(ceiling_ok))}


def plot(rows: list[dict], path: Path) -> None:
    """Nominal against observed coverage, one line per group and noise level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6), sharey=True)
    for ax, group in zip(axes, ("smooth", "parts"), strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="ideal")
        ax.axhspan(BAND[0], BAND[1], color="0.9")
        for noise in sorted({r["noise"] for r in rows}):
            cells = [r for r in rows if r["group"] == group and r["noise"] == noise]
            if not cells:
                continue
            obs = [np.median([c[f"obs_{p:g}"] for c in cells]) for p in NOMINAL]
            lo = [min(c[f"obs_{p:g}"] for c in cells) for p in NOMINAL]
            hi = [max(c[f"obs_{p:g}"] for c in cells) for p in NOMINAL]
            line, = ax.plot(NOMINAL, obs, marker="o", label=f"noise {noise:g} %")
            ax.fill_between(NOMINAL, lo, hi, color=line.get_color(), alpha=0.12)
        ax.set_title(f"{group} shapes: median, min to max")
        ax.set_xlabel("nominal coverage (normal interval of the standard error)")
        ax.set_xlim(0.45, 1.0)
        ax.set_ylim(0.3, 1.0)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("observed share of k1 errors within the interval")
    axes[1].legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def scan_edges(points: np.ndarray, k: int = 24, offset: float = 0.35) -> np.ndarray:
    """Points at the edge of a scan, shape (n,) bool: the mean of their k nearest neighbors
    lies more than ``offset`` RMS neighbor distances away from them (one-sided neighbors)."""
    from scipy.spatial import cKDTree

    d, idx = cKDTree(points).query(points, k + 1)
    shift = np.linalg.norm(points[idx[:, 1:]].mean(axis=1) - points, axis=1)
    return shift > offset * np.sqrt((d[:, 1:] ** 2).mean(axis=1))


def scan_report(path: Path, out: Path) -> dict:
    """Standard error of k1 at the scan's edges against its inside, and a preview."""
    cloud = curvature.read(path)
    res = curvature.estimate(cloud)
    edge = scan_edges(res.points)
    ok = res.status == 0
    inside = ~edge & ok
    doc = {"scan": path.name, "points": len(res), "edge_points": int(edge.sum()),
           "median_k1_std_edge": float(np.median(res.k1_std[edge & ok])),
           "median_k1_std_inside": float(np.median(res.k1_std[inside])),
           "median_residual_edge": float(np.median(res.residual[edge & ok])),
           "median_residual_inside": float(np.median(res.residual[inside])),
           "uncertain_edge": float(res.uncertain[edge].mean()),
           "uncertain_inside": float(res.uncertain[~edge].mean())}
    doc["edge_over_inside"] = doc["median_k1_std_edge"] / doc["median_k1_std_inside"]
    out.mkdir(parents=True, exist_ok=True)
    curvature.render_preview(res, "k1_std", view="front", path=out / f"{path.stem}_k1_std.png")
    return doc


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--method", default="auto", choices=("auto", "knn"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--shapes", nargs="*", default=SMOOTH + PARTS)
    ap.add_argument("--noises", nargs="*", type=float, default=NOISES)
    ap.add_argument("--models", nargs="*", default=MODELS)
    ap.add_argument("--out", type=Path, default=Path("docs/figures/uncertainty"))
    ap.add_argument("--scan", type=Path, default=None,
                    help="a real scan: preview by standard error, edges against inside")
    args = ap.parse_args(argv)
    if args.scan is not None:
        doc = scan_report(args.scan, args.out)
        Path(args.out / f"{args.scan.stem}_std.json").write_text(json.dumps(doc, indent=1) + "\n")
        print(json.dumps(doc, indent=1))
        return 0
    rows = run(args.method, args.seed, args.shapes, args.noises, args.models)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"calibration_{args.method}"
    with open(f"{stem}.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    doc = summary(rows)
    Path(f"{stem}_summary.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(json.dumps(doc, indent=1))
    plot(rows, Path(f"{stem}.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
