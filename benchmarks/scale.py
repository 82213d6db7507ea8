"""Peak memory and throughput of the CLI on a big synthetic cloud (issue 7).

Generates a noisy torus (not committed), saves it as .npy, then runs ``curvature estimate`` on
it in a child process per worker count and reports wall time, points per second and the
child's peak resident memory. CGAL's jet fitting (degree 2, k = 96) then runs on the same cloud
with the last worker count, and the ratio of the two rates is printed (``jet_reference.py``).

Usage::

    python benchmarks/scale.py                   # 10M points, default method, 1 and 2 workers
    python benchmarks/scale.py --n 2000000 --workers 2
    python benchmarks/scale.py --n 1000000 --workers 2 --dask 2   # also tiles on a LocalCluster

``--dask N`` also computes the cloud in this process with its tiles sent to a
``distributed.LocalCluster`` of N single-threaded worker processes, beside the same call with
a local thread pool, and checks that both equal the CLI's result.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from jet_reference import ratio_line, time_cgal_jet

from curvature import synthetic

# Runs the CLI as its child and prints the child's peak RSS: a fresh measuring process per run,
# since RUSAGE_CHILDREN keeps the largest child seen so far.
MEASURE = """
import resource, subprocess, sys
subprocess.run([sys.executable, "-m", "curvature", *sys.argv[1:]], check=True)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def run_cli(args: list[str]) -> tuple[float, int]:
    """Wall time and peak RSS (bytes) of one CLI run in a fresh child process."""
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", MEASURE, *args], check=True,
                         stdout=subprocess.PIPE, text=True).stdout
    wall = time.perf_counter() - t
    return wall, int(out.split()[-1]) * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000_000)
    ap.add_argument("--noise", type=float, default=0.1)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--method", default=None, help="default: the library's default")
    ap.add_argument("--dask", type=int, default=0, metavar="N",
                    help="also run the tiles on a LocalCluster of N workers")
    ap.add_argument("--tile-points", type=int, default=250_000)
    ap.add_argument("--no-cgal", action="store_true",
                    help="skip CGAL's jet fitting (degree 2, k = 96) on the same cloud")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "cloud.npy")
        t = time.perf_counter()
        np.save(src, synthetic.torus(args.n, noise=args.noise, seed=1).points)
        print(f"# {args.n:,} point torus, noise {args.noise}% BBD, generated in "
              f"{time.perf_counter() - t:.1f} s; {os.cpu_count()} cores", flush=True)
        walls = {}
        for workers in args.workers:
            out = os.path.join(tmp, "result.npz")
            cli = ["estimate", src, "-o", out, "--workers", str(workers), "-q"]
            if args.method:
                cli += ["--method", args.method]
            wall, peak = run_cli(cli)
            walls[workers] = wall
            print(f"workers {workers}: {wall:.1f} s, {args.n / wall:,.0f} points/s, peak RSS "
                  f"{peak / 2**30:.2f} GiB ({peak / args.n:.0f} B/point)", flush=True)
            if args.dask and workers == args.workers[-1]:
                with np.load(out) as npz:
                    reference = npz["k1"]
            os.remove(out)
        if not args.no_cgal:
            workers = args.workers[-1]
            cgal_s, label = time_cgal_jet(np.load(src), workers)
            print(f"workers {workers}, " + ratio_line(args.n, walls[workers], cgal_s, label)
                  + " (ours: the CLI's wall time, reading and writing included)", flush=True)
        if args.dask:
            compare_executors(np.load(src), args.method, args.dask, args.tile_points, reference)


def warm_up(points) -> None:
    import curvature

    curvature.estimate(points, workers=1)


def compare_executors(points, method, n_workers: int, tile_points: int, reference) -> None:
    """Points per second with tiles on a thread pool and on a Dask LocalCluster."""
    from concurrent.futures import ThreadPoolExecutor

    from distributed import Client, LocalCluster

    import curvature

    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.run(warm_up, points[:2000].copy())  # compile the kernels in every worker
        runs = {"thread pool": lambda: ThreadPoolExecutor(n_workers),
                "dask LocalCluster": lambda: client}
        for name, make in runs.items():
            executor = make()
            t = time.perf_counter()
            res = curvature.estimate(points, method, workers=1, executor=executor,
                                     tile_points=tile_points)
            wall = time.perf_counter() - t
            same = np.array_equal(res.k1, reference, equal_nan=True)
            print(f"{name} ({n_workers} workers, tiles of {tile_points:,}): {wall:.1f} s, "
                  f"{len(points) / wall:,.0f} points/s, {res.info['tiles']} tiles, "
                  f"{res.info['regrown']} regrown, identical to the CLI: {same}", flush=True)


if __name__ == "__main__":
    main()
