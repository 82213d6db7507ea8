"""Command line: ``curvature estimate|synthetic|info|neighbors``, plus plugin sub-commands.

Plugins are functions ``register(subparsers)`` found in the ``curvature.cli`` entry-point
group (``curvature remote`` from ``curvature_client``, ``curvature bench`` from
:mod:`curvature.studies.cli`); the core never imports them by name.
"""

from __future__ import annotations

import argparse
import sys
import time
from importlib.metadata import entry_points

import numpy as np

from .errors import CurvatureInputError
from .estimators.auto import AUTO_PARAMS
from .fitting import FIT_PARAMS, FITS, SOLVERS
from .io import read, write
from .neighborhoods import FINDERS, make_finder
from .pipeline import DEFAULT_METHOD, ORIENTATIONS, PRESETS, estimate
from .preview import FIELDS as PREVIEW_FIELDS
from .preview import VIEWS as PREVIEW_VIEWS
from .preview import check_available as check_preview_available
from .preview import render_preview
from .progress import ProgressBar
from .validation import as_points


def method_specs(with_auto: bool) -> dict:
    """Parameter specs of every method: the neighborhood methods, plus "auto" if asked."""
    specs = {name: finder.PARAMS for name, finder in sorted(FINDERS.items())}
    return {"auto": AUTO_PARAMS, **specs} if with_auto else specs


def method_param_specs(with_auto: bool = False) -> dict:
    """Every method parameter by name (the union over methods), for CLI options."""
    specs = {}
    for params in method_specs(with_auto).values():
        for spec in params:
            specs.setdefault(spec.name, spec)
    return specs


def add_method_options(parser: argparse.ArgumentParser, with_auto: bool = False) -> None:
    """``--method`` and one option per method parameter (defaults shown per method)."""
    methods = method_specs(with_auto)
    default = DEFAULT_METHOD if with_auto else "knn"
    parser.add_argument("--method", default=None, choices=sorted(methods),
                        help=f"method (default: {default}"
                             + ("; 'auto' measures noise and spacing and picks model and scale"
                                if with_auto else "") + ")")
    parser.set_defaults(default_method=default, with_auto=with_auto)
    for name, spec in method_param_specs(with_auto).items():
        defaults = ", ".join(f"{m}: {next(s.default for s in ps if s.name == name)}"
                             for m, ps in methods.items() if any(s.name == name for s in ps))
        parser.add_argument(f"--{name.replace('_', '-')}", dest=name, type=spec.kind,
                            default=None, help=f"{spec.help} [{defaults}]")


def chosen_method_params(args, method: str | None = None) -> dict:
    """Method parameters given on the command line; reject those of another method.

    Fit parameters that share a name with a method parameter (``normal_k`` of fit "nfr")
    are let through for the fit to check.
    """
    method = method or args.method or args.default_method
    own = {s.name for s in method_specs(args.with_auto)[method]}
    own |= {s.name for s in FIT_PARAMS} if method != "auto" else set()
    given = {name: getattr(args, name) for name in method_param_specs(args.with_auto)
             if getattr(args, name) is not None}
    foreign = sorted(set(given) - own)
    if foreign:
        opts = ", ".join("--" + f.replace("_", "-") for f in foreign)
        raise CurvatureInputError(f"{opts} does not apply to method '{method}'")
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
    add_method_options(est, with_auto=True)
    est.add_argument("--preset", default=None, choices=sorted(PRESETS),
                     help="named configuration: 'paper' is Territory Claiming with 10 neighbors "
                          "and the implicit quadric")
    est.add_argument("--fit", default=None, choices=FITS,
                     help="fit model of a neighborhood method (default: adaptive, the "
                          "implicit quadric where it fits, the height function elsewhere)")
    est.add_argument("--solver", default=None, choices=SOLVERS,
                     help="implicit quadric solver (default taubin)")
    est.add_argument("--orientation", default=None, choices=ORIENTATIONS,
                     help="normal orientation (default: normals if the file has them, else auto)")
    est.add_argument("--viewpoint", type=float, nargs=3, metavar=("X", "Y", "Z"),
                     help="scanner position; implies --orientation viewpoint")
    est.add_argument("--workers", type=int, default=None, help="threads (default: all cores)")
    est.add_argument("--tile-points", type=int, default=None,
                     help="compute in spatial tiles of this many points, identical results in "
                          "less memory (default: 1000000 above 2M points; 0: never)")
    est.add_argument("--ascii", action="store_true", help="write ascii PLY instead of binary")
    est.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    est.add_argument("--preview", metavar="PNG", default=None,
                     help="also write a picture of the cloud colored by curvature "
                          "(needs matplotlib)")
    est.add_argument("--preview-field", default="mean", choices=list(PREVIEW_FIELDS),
                     help="field that colors the preview (default: mean)")
    est.add_argument("--preview-view", default="iso", choices=sorted(PREVIEW_VIEWS),
                     help="camera of the preview, z up (default: iso)")

    sub.add_parser("synthetic", add_help=False,
                   help="sample an analytic test shape with exact curvature "
                        "(curvature synthetic -h)")

    info = sub.add_parser("info", help="describe a point cloud file")
    info.add_argument("input")

    nb = sub.add_parser("neighbors", help="print one point's neighborhood")
    nb.add_argument("input")
    nb.add_argument("--index", type=int, required=True, help="the query point's index")
    add_method_options(nb)

    add_plugins(sub)
    return parser


PLUGIN_GROUP = "curvature.cli"


def add_plugins(sub) -> None:
    """Sub-commands of the installed plugins (entry points of :data:`PLUGIN_GROUP`).

    Each entry point names a function ``register(subparsers)`` that adds its parsers and sets
    a ``handler(args) -> int`` default. A plugin that fails to load still gets a command,
    which explains why it is unavailable instead of breaking every other command.
    """
    for ep in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
        try:
            register = ep.load()
        except Exception as exc:  # e.g. the plugin's own dependencies are not installed
            _add_unavailable(sub, ep.name, f"{type(exc).__name__}: {exc}")
            continue
        register(sub)


def _add_unavailable(sub, name: str, reason: str) -> None:
    def handler(args) -> int:
        print(f"curvature {name}: unavailable: the plugin failed to load ({reason})",
              file=sys.stderr)
        return 2

    parser = sub.add_parser(name, help=f"(unavailable: {reason})", add_help=False)
    parser.add_argument("rest", nargs=argparse.REMAINDER)
    parser.set_defaults(handler=handler)


# What method "auto" did, by whether it measured the cloud as clean.
BRANCHES = {True: "clean: implicit quadric",
            False: "noisy: normal-constrained quadric or normal field"}


def percentiles(values: np.ndarray) -> str:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return "n/a"
    p = np.percentile(finite, [5, 25, 50, 75, 95])
    return "  ".join(f"p{q}={v:.4g}" for q, v in zip((5, 25, 50, 75, 95), p, strict=True))


def median_std(values: np.ndarray) -> str:
    """The median of the finite standard errors, or n/a."""
    finite = values[np.isfinite(values)]
    return f"{np.median(finite):.4g}" if finite.size else "n/a"


def cmd_estimate(args) -> int:
    if args.preview:  # fail before a long estimate, not after it
        try:
            check_preview_available()
        except ImportError as exc:
            raise CurvatureInputError(f"--preview: {exc}") from None
    t0 = time.perf_counter()
    cloud = read(args.input)
    t_read = time.perf_counter() - t0
    method = args.method
    if method is None:
        method = PRESETS[args.preset]["method"] if args.preset else args.default_method
    params = chosen_method_params(args, method)
    if args.solver is not None:
        params["solver"] = args.solver
    bar = None if args.quiet else ProgressBar("estimate")
    t1 = time.perf_counter()
    res = estimate(cloud, method, fit=args.fit, preset=args.preset, orientation=args.orientation,
                   viewpoint=args.viewpoint, workers=args.workers, progress=bar,
                   tile_points=args.tile_points, **params)
    t_est = time.perf_counter() - t1
    t2 = time.perf_counter()
    write(args.output, res, binary=not args.ascii)
    t_write = time.perf_counter() - t2
    t_preview = None
    if args.preview:
        t3 = time.perf_counter()
        render_preview(res, args.preview_field, view=args.preview_view, path=args.preview)
        t_preview = time.perf_counter() - t3
    if not args.quiet:
        n = len(res)
        counts = res.status_counts()
        failed = {k: v for k, v in counts.items() if k != "ok"}
        lines = [
            f"points      {n}" + (f" ({cloud.dropped} NaN rows dropped on read)"
                                  if cloud.dropped else ""),
            f"method      {res.info['method']} {res.info['params']}  fit {res.info['fit']}  "
            f"orientation {res.info['orientation']}",
            *([f"measured    spacing {plan['spacing']:.4g}, relative noise {plan['noise']:.4g}"
               f" -> {BRANCHES[plan['clean']]}"] if (plan := res.info.get("plan")) else []),
            *([f"tiles       {res.info['tiles']} of up to {res.info['tile_points']} points, "
               f"halo up to {res.info['halo_max']:.4g} (widened {res.info['regrown']} times)"]
              if "tiles" in res.info else []),
            f"ok          {counts.get('ok', 0)} ({counts.get('ok', 0) / n:.2%})",
            f"failures    {failed if failed else 'none'}",
            f"k1          {percentiles(res.k1)}",
            f"k2          {percentiles(res.k2)}",
            f"std         median standard error k1 {median_std(res.k1_std)}  "
            f"k2 {median_std(res.k2_std)}  H {median_std(res.mean_std)};  uncertain "
            f"{int(res.uncertain.sum())} ({res.uncertain.mean():.2%})",
            f"time        read {t_read:.2f}s  estimate {t_est:.2f}s  write {t_write:.2f}s  "
            f"({n / max(t_est, 1e-9):,.0f} points/s)",
            f"output      {args.output}",
        ]
        if t_preview is not None:
            lines.append(f"preview     {args.preview} ({args.preview_field}, "
                         f"{args.preview_view} view, {t_preview:.2f}s)")
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
    method = args.method or args.default_method
    finder = make_finder(pts, method, faces=cloud.faces, **chosen_method_params(args))
    nbhd = finder.query(np.array([args.index], np.int64))
    idx = nbhd[0]
    p = pts[args.index]
    print(f"point {args.index} at {np.array2string(p, precision=6)}; method {method} "
          f"{finder.params}; {len(idx)} neighbors")
    print(f"{'rank':>4} {'index':>9} {'distance':>12}   x y z")
    for rank, j in enumerate(idx):
        q = pts[j]
        print(f"{rank:>4} {int(j):>9} {np.linalg.norm(q - p):>12.6g}   "
              f"{q[0]:.6g} {q[1]:.6g} {q[2]:.6g}")
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["synthetic"]:  # its own parser lives with the shapes
        from . import synthetic

        return synthetic.main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    commands = {"estimate": cmd_estimate, "info": cmd_info, "neighbors": cmd_neighbors}
    try:
        handler = getattr(args, "handler", None) or commands[args.command]
        return handler(args)
    except (ValueError, OSError) as exc:  # CurvatureInputError and friends are ValueErrors
        print(f"curvature {args.command}: error: {exc}", file=sys.stderr)
        return 2
