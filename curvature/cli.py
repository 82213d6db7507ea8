"""Command line: ``curvature estimate|info|neighbors|bench``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .errors import CurvatureInputError
from .fitting import FITS, SOLVERS
from .io import read, write
from .neighborhoods import FINDERS, make_finder
from .pipeline import ORIENTATIONS, estimate
from .progress import ProgressBar
from .validation import as_points


def method_param_specs() -> dict:
    """Every method parameter by name (the union over methods), for CLI options."""
    specs = {}
    for finder in FINDERS.values():
        for spec in finder.PARAMS:
            specs.setdefault(spec.name, spec)
    return specs


def add_method_options(parser: argparse.ArgumentParser) -> None:
    """``--method`` and one option per method parameter (defaults shown per method)."""
    parser.add_argument("--method", default="knn", choices=sorted(FINDERS),
                        help="neighborhood method (default: knn)")
    for name, spec in method_param_specs().items():
        owners = [m for m, f in sorted(FINDERS.items()) if any(s.name == name for s in f.PARAMS)]
        defaults = ", ".join(
            f"{m}: {next(s.default for s in FINDERS[m].PARAMS if s.name == name)}"
            for m in owners)
        parser.add_argument(f"--{name.replace('_', '-')}", dest=name, type=spec.kind,
                            default=None, help=f"{spec.help} [{defaults}]")


def chosen_method_params(args) -> dict:
    """Method parameters given on the command line; reject those of another method."""
    own = {s.name for s in FINDERS[args.method].PARAMS}
    given = {name: getattr(args, name) for name in method_param_specs()
             if getattr(args, name) is not None}
    foreign = sorted(set(given) - own)
    if foreign:
        opts = ", ".join("--" + f.replace("_", "-") for f in foreign)
        raise CurvatureInputError(f"{opts} does not apply to method '{args.method}'")
    return given


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="curvature", description="Per-point curvature of 3D scans by local quadric fits.")
    sub = parser.add_subparsers(dest="command", required=True)

    est = sub.add_parser("estimate", help="compute curvature of every point of a file")
    est.add_argument("input", help="point cloud or mesh (ply, pcd, xyz, csv, txt, asc, npy, npz, "
                                   "obj, stl, off)")
    est.add_argument("-o", "--output", required=True,
                     help="result file (ply, csv, npz, json by extension)")
    add_method_options(est)
    est.add_argument("--fit", default="implicit", choices=FITS, help="fit model")
    est.add_argument("--solver", default=None, choices=SOLVERS,
                     help="implicit quadric solver (default taubin)")
    est.add_argument("--orientation", default=None, choices=ORIENTATIONS,
                     help="normal orientation (default: normals if the file has them, else auto)")
    est.add_argument("--viewpoint", type=float, nargs=3, metavar=("X", "Y", "Z"),
                     help="scanner position; implies --orientation viewpoint")
    est.add_argument("--workers", type=int, default=None, help="threads (default: all cores)")
    est.add_argument("--ascii", action="store_true", help="write ascii PLY instead of binary")
    est.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")

    sub.add_parser("synthetic", add_help=False,
                   help="sample an analytic test shape with exact curvature "
                        "(curvature synthetic -h)")

    info = sub.add_parser("info", help="describe a point cloud file")
    info.add_argument("input")

    nb = sub.add_parser("neighbors", help="print one point's neighborhood")
    nb.add_argument("input")
    nb.add_argument("--index", type=int, required=True, help="the query point's index")
    add_method_options(nb)

    bench = sub.add_parser("bench", help="regenerate a benchmark study (CSV and PNG plots)")
    bench.add_argument("study", choices=["paper"],
                       help="paper: the accuracy study of Khameneifar & Feng (2019)")
    bench.add_argument("--out", required=True, help="output folder")
    bench.add_argument("--quick", action="store_true", help="reduced grid (about a minute)")
    bench.add_argument("--seeds", type=int, default=None,
                       help="seeds per configuration (default: 3, quick: 2)")
    bench.add_argument("--workers", type=int, default=None,
                       help="threads of each estimate (default: all cores)")
    bench.add_argument("--data", default=None,
                       help="folder holding bun000.ply (default: ../shared/data next to the "
                            "repository)")
    return parser


def percentiles(values: np.ndarray) -> str:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return "n/a"
    p = np.percentile(finite, [5, 25, 50, 75, 95])
    return "  ".join(f"p{q}={v:.4g}" for q, v in zip((5, 25, 50, 75, 95), p, strict=True))


def cmd_estimate(args) -> int:
    t0 = time.perf_counter()
    cloud = read(args.input)
    t_read = time.perf_counter() - t0
    params = chosen_method_params(args)
    if args.solver is not None:
        params["solver"] = args.solver
    bar = None if args.quiet else ProgressBar("estimate")
    t1 = time.perf_counter()
    res = estimate(cloud, args.method, fit=args.fit, orientation=args.orientation,
                   viewpoint=args.viewpoint, workers=args.workers, progress=bar, **params)
    t_est = time.perf_counter() - t1
    t2 = time.perf_counter()
    write(args.output, res, binary=not args.ascii)
    t_write = time.perf_counter() - t2
    if not args.quiet:
        n = len(res)
        counts = res.status_counts()
        failed = {k: v for k, v in counts.items() if k != "ok"}
        lines = [
            f"points      {n}" + (f" ({cloud.dropped} NaN rows dropped on read)"
                                  if cloud.dropped else ""),
            f"method      {res.info['method']} {res.info['params']}  fit {res.info['fit']}  "
            f"orientation {res.info['orientation']}",
            f"ok          {counts.get('ok', 0)} ({counts.get('ok', 0) / n:.2%})",
            f"failures    {failed if failed else 'none'}",
            f"k1          {percentiles(res.k1)}",
            f"k2          {percentiles(res.k2)}",
            f"time        read {t_read:.2f}s  estimate {t_est:.2f}s  write {t_write:.2f}s  "
            f"({n / max(t_est, 1e-9):,.0f} points/s)",
            f"output      {args.output}",
        ]
        print("\n".join(lines), file=sys.stderr)
    return 0


def cmd_info(args) -> int:
    cloud = read(args.input)
    pts = cloud.points
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    from scipy.spatial import cKDTree

    sample = pts[np.linspace(0, len(pts) - 1, min(len(pts), 20000)).astype(np.int64)]
    dist, _ = cKDTree(pts).query(sample, k=2)
    spacing = np.percentile(dist[:, 1], [5, 50, 95])
    print(f"file        {args.input}")
    print(f"points      {len(pts)}" + (f" ({cloud.dropped} NaN rows dropped)"
                                       if cloud.dropped else ""))
    print(f"faces       {0 if cloud.faces is None else len(cloud.faces)}")
    print(f"normals     {'yes' if cloud.normals is not None else 'no'}")
    print(f"properties  {', '.join(sorted(cloud.properties)) or 'none'}")
    print(f"bbox min    {np.array2string(lo, precision=5)}")
    print(f"bbox max    {np.array2string(hi, precision=5)}")
    print(f"bbox diag   {np.linalg.norm(hi - lo):.6g}")
    print(f"spacing     p5 {spacing[0]:.4g}  p50 {spacing[1]:.4g}  p95 {spacing[2]:.4g} "
          "(nearest neighbor distance)")
    return 0


def cmd_neighbors(args) -> int:
    cloud = read(args.input)
    pts = as_points(cloud.points)
    if not 0 <= args.index < len(pts):
        raise CurvatureInputError(f"--index {args.index} is outside 0..{len(pts) - 1}")
    finder = make_finder(pts, args.method, faces=cloud.faces, **chosen_method_params(args))
    nbhd = finder.query(np.array([args.index], np.int64))
    idx = nbhd[0]
    p = pts[args.index]
    print(f"point {args.index} at {np.array2string(p, precision=6)}; method {args.method} "
          f"{finder.params}; {len(idx)} neighbors")
    print(f"{'rank':>4} {'index':>9} {'distance':>12}   x y z")
    for rank, j in enumerate(idx):
        q = pts[j]
        print(f"{rank:>4} {int(j):>9} {np.linalg.norm(q - p):>12.6g}   "
              f"{q[0]:.6g} {q[1]:.6g} {q[2]:.6g}")
    return 0


def cmd_bench(args) -> int:
    from . import paper_study

    if args.seeds is not None and args.seeds < 1:
        raise CurvatureInputError(f"--seeds must be >= 1, got {args.seeds}")
    data = Path(args.data) if args.data else paper_study.default_data_dir()
    scan = data / paper_study.SCAN_NAME
    if not scan.is_file():
        raise CurvatureInputError(f"{scan} not found; point --data at the folder holding "
                                  f"{paper_study.SCAN_NAME}")
    changes = {"scan": str(scan), "workers": args.workers}
    if args.seeds is not None:
        changes["seeds"] = tuple(range(1, args.seeds + 1))
    config = (paper_study.StudyConfig.quick if args.quick
              else paper_study.StudyConfig.full)(**changes)
    paper_study.run_study(config, args.out)
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["synthetic"]:  # its own parser lives with the shapes
        from . import synthetic

        return synthetic.main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    commands = {"estimate": cmd_estimate, "info": cmd_info, "neighbors": cmd_neighbors,
                "bench": cmd_bench}
    try:
        return commands[args.command](args)
    except (ValueError, OSError) as exc:  # CurvatureInputError and friends are ValueErrors
        print(f"curvature {args.command}: error: {exc}", file=sys.stderr)
        return 2
