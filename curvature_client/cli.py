"""``curvature remote ...``: the service from the command line.

Registered through the ``curvature.cli`` entry-point group (see pyproject.toml), so the core
CLI runs it without importing this package by name.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from curvature.cli import add_method_options, chosen_method_params

from .client import (
    DEFAULT_URL,
    PREVIEW_FIELDS,
    PREVIEW_UP_CHOICES,
    PREVIEW_VIEWS,
    RESULT_FORMATS,
    CurvatureClient,
    format_from_path,
)
from .errors import CurvatureClientError
from .models import Job

URL_ENV = "CURVATURE_URL"
KEY_ENV = "CURVATURE_API_KEY"


def register(subparsers) -> None:
    """Add ``remote`` and its sub-commands to the ``curvature`` command line.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command set of the ``curvature`` parser.
    """
    remote = subparsers.add_parser(
        "remote", help="send work to a curvature service (submit, status, result, preview, "
                       "cancel, list)",
        description="Use a curvature service: submit a file, follow the job with a progress "
                    f"bar and download the result. The service URL and API key come from "
                    f"--url/--api-key or ${URL_ENV}/${KEY_ENV}.")
    commands = remote.add_subparsers(dest="remote_command", required=True, metavar="COMMAND")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--url", default=os.environ.get(URL_ENV, DEFAULT_URL),
                        help=f"service base URL (default: ${URL_ENV} or {DEFAULT_URL})")
    common.add_argument("--api-key", default=os.environ.get(KEY_ENV),
                        help=f"API key, sent as a Bearer token (default: ${KEY_ENV})")
    common.add_argument("--request-timeout", type=float, default=60.0, metavar="SECONDS",
                        help="limit for each HTTP request (default 60)")
    common.add_argument("-q", "--quiet", action="store_true", help="no progress bar")

    submit = commands.add_parser("submit", parents=[common], help="submit a cloud as a job",
                                 description="Upload a point cloud or mesh file as a job and "
                                             "print its id; with --wait or -o, follow it "
                                             "and download the result.")
    submit.add_argument("input", help="point cloud or mesh file (ply, pcd, xyz, csv, txt, asc, "
                                      "npy, npz, obj, stl, off)")
    add_method_options(submit, with_auto=True)
    submit.add_argument("--fit", help="fit model (implicit, monge, ...; the service's default "
                                      "when omitted)")
    submit.add_argument("--solver", help="implicit quadric solver")
    submit.add_argument("--orientation", help="normal orientation (auto, normals, viewpoint)")
    submit.add_argument("--viewpoint", type=float, nargs=3, metavar=("X", "Y", "Z"),
                        help="scanner position")
    submit.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="any other parameter, VALUE as JSON (e.g. include_self=false); "
                             "repeatable")
    submit.add_argument("--wait", action="store_true", help="follow the job until it ends")
    submit.add_argument("-o", "--output", help="download the result here (implies --wait)")
    _add_format(submit)
    submit.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                        help="give up waiting after this long (the job keeps running)")
    submit.set_defaults(handler=run, remote_handler=cmd_submit)

    status = commands.add_parser("status", parents=[common], help="print a job as JSON")
    status.add_argument("job", help="job id")
    status.set_defaults(handler=run, remote_handler=cmd_status)

    wait = commands.add_parser("wait", parents=[common], help="follow a job until it ends")
    wait.add_argument("job", help="job id")
    wait.add_argument("-o", "--output", help="then download the result here")
    _add_format(wait)
    wait.add_argument("--timeout", type=float, default=None, metavar="SECONDS")
    wait.set_defaults(handler=run, remote_handler=cmd_wait)

    result = commands.add_parser("result", parents=[common], help="download a job's result")
    result.add_argument("job", help="job id")
    result.add_argument("-o", "--output", required=True, help="result file")
    _add_format(result)
    result.set_defaults(handler=run, remote_handler=cmd_result)

    preview = commands.add_parser("preview", parents=[common],
                                  help="download a PNG of the cloud colored by curvature")
    preview.add_argument("job", help="job id")
    preview.add_argument("-o", "--output", required=True, help="PNG file")
    preview.add_argument("--field", default="mean", choices=PREVIEW_FIELDS)
    preview.add_argument("--view", default="iso", choices=PREVIEW_VIEWS)
    preview.add_argument("--up", default="auto", choices=PREVIEW_UP_CHOICES,
                         help="the world's up axis (auto: from the cloud's principal axes)")
    preview.set_defaults(handler=run, remote_handler=cmd_preview)

    cancel = commands.add_parser("cancel", parents=[common],
                                 help="cancel a job (a finished job is deleted)")
    cancel.add_argument("job", help="job id")
    cancel.set_defaults(handler=run, remote_handler=cmd_cancel)

    listing = commands.add_parser("list", parents=[common], help="list your jobs")
    listing.add_argument("--status", help="only jobs with this status")
    listing.add_argument("--limit", type=int, default=50, help="at most this many (default 50)")
    listing.set_defaults(handler=run, remote_handler=cmd_list)


def _add_format(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--format", choices=RESULT_FORMATS, default=None,
                        help="result format (default: from the output's extension)")


def _client(args) -> CurvatureClient:
    return CurvatureClient(args.url, api_key=args.api_key, timeout=args.request_timeout)


def submitted_params(args) -> dict:
    """Method and fit parameters from the options (only those given)."""
    params = chosen_method_params(args)
    for name in ("fit", "solver", "orientation"):
        if getattr(args, name) is not None:
            params[name] = getattr(args, name)
    if args.viewpoint is not None:
        params["viewpoint"] = list(args.viewpoint)
    for item in args.param:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--param {item!r}: expected NAME=VALUE")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw  # a bare word such as monge
        params[name.strip()] = value
    return params


def check_output(args) -> None:
    """Refuse an output the result cannot be written to before waiting for a job."""
    if not getattr(args, "output", None):
        return
    if args.format is None:
        format_from_path(args.output)  # ValueError names the usable extensions
    folder = Path(args.output).resolve().parent
    if not folder.is_dir():
        raise ValueError(f"-o {args.output}: folder {folder} does not exist")


def _finish(client: CurvatureClient, job: Job, args) -> Job:
    """Wait for the job (progress bar unless quiet), then download the result if asked."""
    done = client.wait(job, progress=not args.quiet, timeout=args.timeout)
    if args.output:
        client.result(done, args.format, path=args.output)
    if not args.quiet:
        counts = (done.data.get("result") or {}).get("status_counts") or {}
        text = ", ".join(f"{k} {v}" for k, v in counts.items()) or "no summary"
        where = f"; wrote {args.output}" if args.output else ""
        print(f"job {done.id} succeeded: {done.n_points} points ({text}){where}",
              file=sys.stderr)
    return done


def cmd_submit(args) -> int:
    params = submitted_params(args)
    check_output(args)
    with _client(args) as client:
        job = client.submit(args.input, args.method, **params)
        print(job.id, flush=True)
        if args.wait or args.output:
            _finish(client, job, args)
    return 0


def cmd_wait(args) -> int:
    check_output(args)
    with _client(args) as client:
        _finish(client, args.job, args)
    return 0


def cmd_status(args) -> int:
    with _client(args) as client:
        print(json.dumps(client.get(args.job).data, indent=2))
    return 0


def cmd_result(args) -> int:
    check_output(args)
    with _client(args) as client:
        client.result(args.job, args.format, path=args.output)
    return 0


def cmd_preview(args) -> int:
    with _client(args) as client:
        client.preview(args.job, args.field, view=args.view, up=args.up, path=args.output)
    return 0


def cmd_cancel(args) -> int:
    with _client(args) as client:
        job = client.cancel(args.job)
    print(f"job {args.job} " + ("deleted" if job is None else job.status))
    return 0


def cmd_list(args) -> int:
    with _client(args) as client:
        jobs = client.jobs(status=args.status, limit=args.limit)
    for job in jobs:
        print(f"{job.id}  {job.status:<9} {job.progress:6.1%}  {job.data.get('method', ''):<5} "
              f"{job.data.get('created_at', '')}")
    return 0


def run(args) -> int:
    """Run a ``remote`` sub-command; service and job errors become exit status 1."""
    try:
        return args.remote_handler(args)
    except CurvatureClientError as exc:  # also failed, cancelled and timed-out jobs
        print(f"curvature remote {args.remote_command}: error: {exc}", file=sys.stderr)
        return 1
