"""Peak memory and throughput of the CLI on a big synthetic cloud (issue 7).

Generates a noisy torus (not committed), saves it as .npy, then runs ``curvature estimate`` on
it in a child process per worker count and reports wall time, points per second and the
child's peak resident memory.

Usage::

    python benchmarks/scale.py                   # 10M points, default method, 1 and 2 workers
    python benchmarks/scale.py --n 2000000 --workers 2
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from curvature import synthetic


def run_cli(args: list[str]) -> tuple[float, int]:
    """Wall time and peak RSS (bytes) of one CLI run in a fresh child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "curvature", *args], check=True)
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    # ru_maxrss of children is the largest child so far: runs go from the smallest expected
    # peak up, and a smaller later peak is reported as "<= earlier"
    return wall, max(peak, before) * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000_000)
    ap.add_argument("--noise", type=float, default=0.1)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--method", default=None, help="default: the library's default")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "cloud.npy")
        t = time.perf_counter()
        np.save(src, synthetic.torus(args.n, noise=args.noise, seed=1).points)
        print(f"# {args.n:,} point torus, noise {args.noise}% BBD, generated in "
              f"{time.perf_counter() - t:.1f} s; {os.cpu_count()} cores", flush=True)
        for workers in args.workers:
            out = os.path.join(tmp, "result.npz")
            cli = ["estimate", src, "-o", out, "--workers", str(workers), "-q"]
            if args.method:
                cli += ["--method", args.method]
            wall, peak = run_cli(cli)
            print(f"workers {workers}: {wall:.1f} s, {args.n / wall:,.0f} points/s, peak RSS "
                  f"{peak / 2**30:.2f} GiB ({peak / args.n:.0f} B/point)", flush=True)
            os.remove(out)


if __name__ == "__main__":
    main()
