"""Which fit and neighbor count should ``tc``, ``egg``, ``mesh`` and ``knn`` use by default?

Two questions for each candidate setting (issue 19, docs/defaults.md):

* real scans (bun000, the PCL table and milk scenes): the share of points with a result, |k1|
  percentiles (speckle shows as a p95 far above the scan's true curvature scale: a bunny ear
  is about 1 cm across, about 100/m) and the normal-sign agreement with method ``auto``;
* analytic shapes without noise: the largest relative error of k1, k2 on a sphere (r = 2) and
  a cylinder (r = 1.5), and the mean |error| on a torus (R = 2, r = 1), 10,000 points each.

    python benchmarks/defaults.py [--data /work/shared/data] [--scans bun000.ply ...]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import curvature
from curvature import synthetic
from curvature.cloud import PointCloud

# name -> (method, parameters)
CANDIDATES = {
    "knn 24 implicit": ("knn", {"k": 24, "fit": "implicit"}),
    "knn 48 implicit": ("knn", {"k": 48, "fit": "implicit"}),
    "knn 24 monge": ("knn", {"k": 24, "fit": "monge"}),
    "tc 10 of 30 implicit (paper)": ("tc", {"min_neighbors": 10, "candidates": 30,
                                            "fit": "implicit"}),
    "tc 24 of 60 implicit": ("tc", {"min_neighbors": 24, "candidates": 60, "fit": "implicit"}),
    "tc 24 of 60 monge": ("tc", {"min_neighbors": 24, "candidates": 60, "fit": "monge"}),
    "egg 24 of 60 monge": ("egg", {"min_neighbors": 24, "candidates": 60, "fit": "monge"}),
    "mesh 24 monge": ("mesh", {"min_neighbors": 24, "fit": "monge"}),
    "knn 24 adaptive": ("knn", {"k": 24, "fit": "adaptive"}),
    "tc 24 of 60 adaptive": ("tc", {"min_neighbors": 24, "candidates": 60, "fit": "adaptive"}),
    "egg 24 of 60 adaptive": ("egg", {"min_neighbors": 24, "candidates": 60,
                                      "fit": "adaptive"}),
    "mesh 24 adaptive": ("mesh", {"min_neighbors": 24, "fit": "adaptive"}),
}
SCANS = ("bun000.ply", "table_scene_mug_stereo_textured.pcd",
         "milk_cartoon_all_small_clorox.pcd")


def thinned(cloud: PointCloud, step: int) -> PointCloud:
    """Every ``step``-th row and column of an organized scan (all points otherwise)."""
    if cloud.grid is None or step == 1:
        return cloud
    index = cloud.input_index()
    width = cloud.grid[0]
    keep = ((index // width) % step == 0) & ((index % width) % step == 0)
    return PointCloud(points=cloud.points[keep], index=index[keep], grid=cloud.grid,
                      viewpoint=cloud.viewpoint, viewpoint_source=cloud.viewpoint_source)


def sign_agreement(a: np.ndarray, b: np.ndarray) -> float:
    dot = np.einsum("ij,ij->i", a, b)
    ok = np.isfinite(dot)
    return float(np.mean(dot[ok] > 0))


def real_scans(data: Path, names, step: int) -> None:
    print("scan | setting | ok % | |k1| p50 | |k1| p95 | sign vs auto % | seconds")
    for name in names:
        cloud = thinned(curvature.read(data / name), step)
        auto = curvature.estimate(cloud)
        for label, (method, params) in CANDIDATES.items():
            t0 = time.perf_counter()
            res = curvature.estimate(cloud, method, **params)
            dt = time.perf_counter() - t0
            ok = res.status == 0
            k1 = np.abs(res.k1[ok])
            print(f"{name} | {label} | {100 * ok.mean():.2f} | {np.percentile(k1, 50):,.1f} | "
                  f"{np.percentile(k1, 95):,.0f} | "
                  f"{100 * sign_agreement(res.normals, auto.normals):.2f} | {dt:.1f}",
                  flush=True)


def analytic() -> None:
    shapes = {"sphere": synthetic.sphere(10000, radius=2.0, seed=1),
              "cylinder": synthetic.cylinder(10000, radius=1.5, height=4.0, seed=2),
              "torus": synthetic.torus(10000, major=2.0, minor=1.0, seed=5)}
    print("setting | sphere max rel err | cylinder max err * r | torus mean |err k1|, |k2|")
    for label, (method, params) in CANDIDATES.items():
        cells = []
        for shape, cloud in shapes.items():
            res = curvature.estimate(cloud.points, method, normals=cloud.normals, **params)
            ok = res.status == 0
            e1 = np.abs(res.k1 - cloud.k1)[ok]
            e2 = np.abs(res.k2 - cloud.k2)[ok]
            if shape == "sphere":
                cells.append(f"{max(e1.max(), e2.max()) * 2.0:.2e}")
            elif shape == "cylinder":
                cells.append(f"{max(e1.max(), e2.max()) * 1.5:.2e}")
            else:
                cells.append(f"{e1.mean():.4f}, {e2.mean():.4f}")
        print(f"{label} | " + " | ".join(cells), flush=True)


def speed(data: Path, repeats: int) -> None:
    """Median seconds of knn 24 with each fit on bun000, runs interleaved."""
    cloud = curvature.read(data / "bun000.ply")
    fits = ("implicit", "monge", "adaptive")
    times = {f: [] for f in fits}
    for f in fits:  # compile and load outside the timed runs
        curvature.estimate(cloud, "knn", fit=f)
    for _ in range(repeats):
        for f in fits:
            res = curvature.estimate(cloud, "knn", fit=f)
            times[f].append(res.info["timings"]["fit"])
    base = np.median(times["monge"])
    for f in fits:
        print(f"fit time, knn 24 on bun000, {f}: median {np.median(times[f]):.3f} s "
              f"({np.median(times[f]) / base:.2f} x monge)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("/work/shared/data"))
    parser.add_argument("--scans", nargs="*", default=list(SCANS))
    parser.add_argument("--grid-step", type=int, default=1,
                        help="keep every n-th row and column of organized scans")
    parser.add_argument("--skip-analytic", action="store_true")
    parser.add_argument("--only", default="", help="settings whose name contains this")
    parser.add_argument("--speed", type=int, default=0, metavar="N",
                        help="only time the fits, N interleaved runs each")
    args = parser.parse_args()
    if args.speed:
        speed(args.data, args.speed)
        return
    for name in [c for c in CANDIDATES if args.only not in c]:
        del CANDIDATES[name]
    if not args.skip_analytic:
        analytic()
    real_scans(args.data, args.scans, args.grid_step)


if __name__ == "__main__":
    main()
