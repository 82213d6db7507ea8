"""Exact k-nearest-neighbor queries of curvature.neighborhoods.kdtree, old against new (issue 21).

A noisy torus, Z-ordered as the pipeline does, queried as the default estimator queries it:
k = 24 and 48 at every point, k = 384 at one point in 13 (every 13th in Z-order, as spatially
coherent as the anchors). The current ``knn_parallel`` runs beside the kernel of an older
revision (``--old``, loaded from git into a temporary module) and beside SciPy's ``cKDTree``
(``workers`` threads, one extra neighbor for the point itself) in the same process; medians of
``--repeat`` runs. The outputs of old and new must be identical (indices and squared
distances); the script exits non-zero if they are not.

Usage::

    python benchmarks/knn.py                      # 1M points, median of 5
    python benchmarks/knn.py --n 100000 --repeat 3
    python benchmarks/knn.py --old main --no-scipy
"""

from __future__ import annotations

import argparse
import importlib
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np
from scipy.spatial import cKDTree

from curvature import synthetic
from curvature.neighborhoods import kdtree
from curvature.pipeline.spatial_order import morton_order

# The kernel before the speed work of issue 21.
OLD_REV = "dc32620"
PATH = "curvature/neighborhoods/kdtree.py"


def load_old(rev: str):
    """The kdtree module of revision ``rev`` as a separate module (its own numba cache)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    src = subprocess.run(["git", "-C", root, "show", f"{rev}:{PATH}"], capture_output=True,
                         text=True, check=True).stdout
    folder = os.path.join(tempfile.gettempdir(), f"curvature_knn_bench_{rev}")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "kdtree_old.py")
    if not os.path.exists(path) or open(path).read() != src:
        with open(path, "w") as fh:
            fh.write(src)
    sys.path.insert(0, folder)  # a plain import, so numba's cache can find the module again
    return importlib.import_module("kdtree_old")


def median_times(fns, repeat: int) -> list[float]:
    """Median time of each function, the runs interleaved so that load from other jobs
    falls on all of them alike."""
    runs = [[] for _ in fns]
    for fn in fns:
        fn()  # compile / warm caches outside the measurement
    for _ in range(repeat):
        for fn, r in zip(fns, runs, strict=True):
            t = time.perf_counter()
            fn()
            r.append(time.perf_counter() - t)
    return [statistics.median(r) for r in runs]


def query(mod, pts, tree, idx, k):
    nbr = np.empty((idx.shape[0], k), np.int32)
    d2 = np.empty((idx.shape[0], k))
    mod.knn_parallel(pts, tree, idx, k, nbr, d2)
    return nbr, d2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--noise", type=float, default=0.1, help="percent of the bbox diagonal")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--old", default=OLD_REV, help="git revision of the old kernel")
    ap.add_argument("--no-scipy", action="store_true")
    ap.add_argument("--k", type=int, nargs="*", default=[24, 48, 384])
    args = ap.parse_args()
    numba.set_num_threads(args.workers)
    old = load_old(args.old)
    cloud = synthetic.torus(args.n, noise=args.noise, seed=1)
    pts = np.ascontiguousarray(cloud.points[morton_order(cloud.points)])
    t_old, t_new = median_times([lambda: old.build_tree(pts), lambda: kdtree.build_tree(pts)],
                                args.repeat)
    tree_old, tree_new = old.build_tree(pts), kdtree.build_tree(pts)
    print(f"# {args.n}-point torus, noise {args.noise}% BBD, Z-ordered, {args.workers} threads, "
          f"median of {args.repeat}; old = {args.old}")
    print(f"{'what':28} {'old s':>8} {'new s':>8} {'old/new':>8} {'cKDTree s':>10}  equal")
    print(f"{'build tree':28} {t_old:8.3f} {t_new:8.3f} {t_old / t_new:8.2f}")
    ok = True
    for k in args.k:
        step = 13 if k > 100 else 1
        idx = np.arange(0, args.n, step, dtype=np.int64)
        a = query(old, pts, tree_old, idx, k)
        b = query(kdtree, pts, tree_new, idx, k)
        same = np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        ok &= same
        del a, b
        fns = [lambda idx=idx, k=k: query(old, pts, tree_old, idx, k),
               lambda idx=idx, k=k: query(kdtree, pts, tree_new, idx, k)]
        if not args.no_scipy:
            ref = cKDTree(pts)
            fns.append(lambda idx=idx, k=k, ref=ref: ref.query(pts[idx], k + 1,
                                                                workers=args.workers))
        t_old, t_new, t_sp = (median_times(fns, args.repeat) + [float("nan")])[:3]
        what = f"k = {k}, {idx.size} queries"
        print(f"{what:28} {t_old:8.3f} {t_new:8.3f} {t_old / t_new:8.2f} {t_sp:10.3f}  "
              f"{'yes' if same else 'NO'}")
    if not ok:
        sys.exit("outputs differ")


if __name__ == "__main__":
    main()
