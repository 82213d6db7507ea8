"""Speed of curvature.estimate and of the neighborhood methods (DESIGN.md section 9).

Medians of several runs in one process, numba compile time reported apart (first call in a
fresh process with the on-disk cache cleared by ``--cold``), and the memory of a 1M-point run
measured in a child process.

Usage::

    python benchmarks/speed.py                 # 100k-point noisy torus, every configuration
    python benchmarks/speed.py --n 200000 --repeat 7
    python benchmarks/speed.py --million       # also peak memory per point at 1M points
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

import curvature
from curvature import synthetic


def timed(fn, repeat: int) -> tuple[float, list[float]]:
    """First-call time and the steady-state times of ``repeat`` further calls."""
    t = time.perf_counter()
    fn()
    first = time.perf_counter() - t
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t)
    return first, runs


def bench_estimate(points, repeat, workers):
    rows = []
    configs = [("knn", "monge", {}), ("knn", "implicit", {}), ("knn", "implicit",
                                                               {"solver": "algebraic"})]
    for method in ("tc", "egg", "mesh"):
        if method in curvature.FINDERS:
            configs.append((method, "monge", {}))
    for method, fit, extra in configs:
        stages = []

        def run(method=method, fit=fit, extra=extra, stages=stages):
            res = curvature.estimate(points, method, fit=fit, workers=workers, **extra)
            stages.append(res.info["timings"])

        first, runs = timed(run, repeat)
        steady = stages[1:]
        rows.append({
            "what": f"estimate {method} {fit}" + (f" {extra}" if extra else ""),
            "first_s": first, "median_s": statistics.median(runs), "runs": runs,
            **{f"{k}_s": statistics.median(s[k] for s in steady)
               for k in ("neighbors", "fit", "orientation")},
        })
    return rows


def bench_neighbors(points, repeat, workers):
    rows = []
    for method in sorted(curvature.FINDERS):
        first, runs = timed(lambda m=method: curvature.neighbors(points, m, workers=workers),
                            repeat)
        sizes = curvature.neighbors(points, method, workers=workers).sizes()
        rows.append({"what": f"neighbors {method}", "first_s": first,
                     "median_s": statistics.median(runs), "runs": runs,
                     "mean_size": float(sizes.mean())})
    return rows


def memory_child(n: int, method: str, fit: str) -> None:
    """Run one estimate on n points and print peak RSS growth per point (bytes) as JSON."""
    cloud = synthetic.torus(n, noise=0.1, seed=3)
    pts = np.ascontiguousarray(cloud.points)
    del cloud
    # Compile outside the measurement, on a small cloud.
    curvature.estimate(pts[:2000], method, fit=fit)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t = time.perf_counter()
    res = curvature.estimate(pts, method, fit=fit)
    dt = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"n": n, "method": method, "fit": fit, "seconds": dt,
                      "result_bytes_per_point": sum(a.nbytes for a in res.fields().values()) / n,
                      "peak_growth_bytes_per_point": (peak - base) / n}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--noise", type=float, default=0.1, help="percent of the bbox diagonal")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--million", action="store_true", help="also measure memory at 1M points")
    ap.add_argument("--memory-child", nargs=3, metavar=("N", "METHOD", "FIT"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        n, method, fit = args.memory_child
        memory_child(int(n), method, fit)
        return
    cloud = synthetic.torus(args.n, noise=args.noise, seed=1)
    print(f"# {args.n}-point torus, noise {args.noise}% BBD, workers {args.workers or 'all'}, "
          f"{os.cpu_count()} cores, median of {args.repeat} runs (first call apart)")
    rows = bench_neighbors(cloud.points, args.repeat, args.workers)
    rows += bench_estimate(cloud.points, args.repeat, args.workers)
    print(f"{'what':44} {'first':>8} {'median':>8} {'nbrs':>7} {'fit':>7} {'orient':>7}")
    for r in rows:
        extra = "".join(f" {r[k]:7.3f}" for k in ("neighbors_s", "fit_s", "orientation_s")
                        if k in r)
        size = f"  mean size {r['mean_size']:.1f}" if "mean_size" in r else ""
        print(f"{r['what']:44} {r['first_s']:8.3f} {r['median_s']:8.3f}{extra}{size}")
    if args.million:
        for fit in ("monge", "implicit"):
            out = subprocess.run([sys.executable, __file__, "--memory-child", "1000000", "knn",
                                  fit], capture_output=True, text=True, check=True)
            m = json.loads(out.stdout)
            print(f"1M points knn {fit}: {m['seconds']:.2f} s, peak memory growth "
                  f"{m['peak_growth_bytes_per_point']:.0f} B/point (result arrays "
                  f"{m['result_bytes_per_point']:.0f} B/point)")


if __name__ == "__main__":
    main()
