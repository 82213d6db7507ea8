"""Does the default get better with more points? The same surface and noise at 100k and 1M.

Issue 15: at a fixed neighbor count a denser cloud gives each fit a smaller patch, so the error
rose with density (torus at 0.25 % BBD noise: 0.054 at 100k, 0.38 at 1M). Prints mean |k1|
and |k2| errors (interior points) of the default for each shape and size, beside the same
run with per-anchor scale selection off (``scale_gamma=0``).

    python benchmarks/density.py [--sizes 100000 1000000] [--noise 0.25]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import curvature
from curvature import synthetic


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--noise", type=float, default=0.25)
    parser.add_argument("--shapes", nargs="+", default=["torus", "sphere", "bezier"])
    args = parser.parse_args()
    print("shape    points   variant      mean|k1 err|  mean|k2 err|  seconds  wide_noise  share")
    for shape in args.shapes:
        for n in args.sizes:
            cloud = synthetic.make(shape, n, noise=args.noise, seed=1)
            m = cloud.interior
            for label, params in (("default", {}), ("dense off", {"dense_noise": 1e6})):
                t0 = time.perf_counter()
                res = curvature.estimate(cloud.points, normals=cloud.normals, **params)
                dt = time.perf_counter() - t0
                e1 = np.nanmean(np.abs(res.k1 - cloud.k1)[m])
                e2 = np.nanmean(np.abs(res.k2 - cloud.k2)[m])
                plan = res.info["plan"]
                print(f"{shape:8} {n:8d}   {label:11}  {e1:12.4f}  {e2:12.4f}  {dt:7.1f}"
                      f"  {plan['wide_noise']:10.3f}  {plan['dense_share']:5.3f}", flush=True)


if __name__ == "__main__":
    main()
