"""The default estimator's time per point in two checkouts of the project, in one run.

A change's cost is only visible beside the code before it on the same machine at the same
moment (the 2-core machine's speed drifts with other jobs by 20 % and more). Each checkout
runs in its own child process (its own imports and numba cache, warmed on a 20,000-point
cloud first); the runs alternate between the checkouts so that drift hits both alike, and the
medians are printed with their ratio.

    git clone -q . /tmp/before && (cd /tmp/before && git checkout <commit>)
    python benchmarks/compare_checkouts.py /tmp/before . [--n 100000 1000000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

# Run by each child with the checkout first on sys.path; prints the seconds of one estimate.
CHILD = r"""
import sys, time
sys.path.insert(0, sys.argv[1])
import curvature
from curvature import synthetic
cloud = synthetic.make("torus", int(sys.argv[2]), noise=float(sys.argv[3]), seed=3)
curvature.estimate(cloud.points[:20000])
t = time.perf_counter()
curvature.estimate(cloud.points)
print(time.perf_counter() - t)
"""


def time_once(checkout: Path, n: int, noise: float) -> float:
    """Seconds of one default estimate of an ``n``-point torus in ``checkout``."""
    out = subprocess.run([sys.executable, "-c", CHILD, str(checkout), str(n), str(noise)],
                         capture_output=True, text=True, cwd=checkout)
    if out.returncode != 0:
        raise SystemExit(f"{checkout}: the estimate failed:\n{out.stderr[-2000:]}")
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--n", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--noise", type=float, default=0.1, help="percent of the bbox diagonal")
    args = ap.parse_args(argv)
    for path in (args.before, args.after):
        if not (path / "curvature" / "__init__.py").is_file():
            raise SystemExit(f"{path}: not a checkout of this project (no curvature/)")
    times: dict[tuple[str, int], list[float]] = {}
    for rep in range(args.repeat):
        for n in args.n:
            for name, path in (("before", args.before), ("after", args.after)):
                t = time_once(path.resolve(), n, args.noise)
                times.setdefault((name, n), []).append(t)
                print(f"run {rep + 1}: {name} {n} points {t:.2f} s", flush=True)
    for n in args.n:
        b = statistics.median(times[("before", n)])
        a = statistics.median(times[("after", n)])
        print(f"{n} points: before {b:.2f} s ({n / b:,.0f} points/s), after {a:.2f} s "
              f"({n / a:,.0f} points/s), ratio {a / b:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
