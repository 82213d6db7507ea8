"""``curvature bench paper|accuracy|parts``: regenerate a benchmark study.

Registered in the ``curvature.cli`` entry-point group (pyproject.toml) like any plugin, so the
core command line never imports the studies.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import CurvatureInputError


def register(subparsers) -> None:
    """Add ``bench`` to the ``curvature`` command line.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command set of the ``curvature`` parser.
    """
    bench = subparsers.add_parser("bench", help="regenerate a benchmark study (CSV and PNG plots)")
    bench.add_argument("study", choices=["paper", "accuracy", "parts"],
                       help="paper: the accuracy study of Khameneifar & Feng (2019); "
                            "accuracy: the default estimator against issue 6's targets, beside "
                            "the paper preset, APSS (when pymeshlab is installed) and CGAL's "
                            "jet fitting at k = 24/96/384, degree 2/4 (when CGAL is installed; "
                            "issue 23's ratio to the best setting), then the part shapes; "
                            "parts: the part shapes alone, per region, beside APSS "
                            "and CGAL jet fitting (when installed)")
    bench.add_argument("--out", required=True, help="output folder")
    bench.add_argument("--quick", action="store_true",
                       help="reduced grid (about a minute; accuracy with CGAL's jet grid: a "
                            "few minutes)")
    bench.add_argument("--seeds", type=int, default=None,
                       help="seeds per configuration (paper: 3, quick 2; "
                            "accuracy: 2, quick 1)")
    bench.add_argument("--workers", type=int, default=None,
                       help="threads of each estimate (default: all cores)")
    bench.add_argument("--data", default=None,
                       help="folder holding bun000.ply (default: ../shared/data next to the "
                            "repository)")
    bench.add_argument("--no-apss", action="store_true",
                       help="accuracy, parts: leave MeshLab's APSS out even if pymeshlab is "
                            "installed")
    bench.add_argument("--no-jets", action="store_true",
                       help="accuracy: leave CGAL's jet-fitting grid out even if CGAL is "
                            "installed")
    bench.add_argument("--noise-models", default=None,
                       help="accuracy: comma-separated noise models of curvature.synthetic "
                            "(default: axis,view)")
    bench.set_defaults(handler=cmd_bench)


def cmd_bench(args) -> int:
    from . import paper as paper_study

    if args.seeds is not None and args.seeds < 1:
        raise CurvatureInputError(f"--seeds must be >= 1, got {args.seeds}")
    if args.study == "accuracy":
        return bench_accuracy(args)
    if args.study == "parts":
        return bench_parts(args, args.out)
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


def bench_accuracy(args) -> int:
    from . import accuracy as accuracy_study

    changes = {"workers": args.workers}
    if args.seeds is not None:
        changes["seeds"] = tuple(range(1, args.seeds + 1))
    if args.no_apss:
        changes["estimators"] = ("default", "paper")
    if args.no_jets:
        changes["jets"] = ()
    if args.noise_models is not None:
        from ..synthetic import NOISE_MODELS

        models = tuple(m.strip() for m in args.noise_models.split(",") if m.strip())
        bad = [m for m in models if m not in NOISE_MODELS]
        if not models or bad:
            raise CurvatureInputError(f"--noise-models takes a comma-separated list of "
                                      f"{', '.join(NOISE_MODELS)}; got {args.noise_models!r}")
        changes["noise_models"] = models
    config = (accuracy_study.AccuracyConfig.quick if args.quick
              else accuracy_study.AccuracyConfig.full)(**changes)
    accuracy_study.run_accuracy(config, args.out)
    return bench_parts(args, Path(args.out) / "parts")


def bench_parts(args, out) -> int:
    from . import parts as parts_study

    estimators = [e for e in parts_study.ESTIMATORS if not (args.no_apss and e == "apss")]
    parts_study.run_parts(out, quick=args.quick, estimators=estimators)
    return 0
