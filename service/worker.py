"""Code that runs inside the worker processes of the pool.

Everything here is a plain top-level function so it can be sent to a spawned or
forkserver-started process. Workers talk to the job store through their own SQLite
connections: they claim a job, write its progress, notice a cancellation (the progress
callback raises, which aborts ``curvature.estimate``) and record the outcome.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import sqlite3
import sys
import threading
import time
from pathlib import Path

import numpy as np

import curvature
import curvature.warmup

from .dask_tiles import cluster_problem, tile_options
from .inputs import CloudInput, check_cloud, load_input
from .problem_types import ProblemError
from .result_files import CANONICAL_RESULT, save_canonical, write_result
from .storage_errors import storage_problem
from .store import CANCELLED, FAILED, SUCCEEDED, JobStore
from .sync_cost import sync_cost_problem

log = logging.getLogger("service.worker")

INTERNAL_ERROR_DETAIL = "unexpected error while computing; it has been logged on the server"

# Share of the progress bar spent before and inside the estimate (reading comes first).
_LOADED, _ESTIMATED = 0.05, 0.95


class JobAborted(Exception):
    """Raised from the progress callback when the job was cancelled or taken over."""


def time_limit_problem(limit: float) -> ProblemError:
    """The error of a job that ran past its time limit."""
    return ProblemError("time-limit", f"the job ran for more than {limit:g} s, the per-job "
                        "time limit (CURVATURE_JOB_TIME_LIMIT_SECONDS); use a smaller cloud "
                        "or cheaper parameters")


def init_worker(log_level: str = "INFO", server_pid: int | None = None,
                nice: int = 0) -> None:
    """Pool initializer: log to stderr, lower the priority by ``nice``, and exit as soon as
    the server process is gone.

    A worker must not outlive a killed server: the next server start runs the job again, and
    an orphan would keep burning a core on a result nobody records (the run token would
    reject it anyway).
    """
    logging.basicConfig(level=log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s[%(process)d]: %(message)s")
    if nice:
        # Computing at a lower priority than the server keeps polling fast on busy cores.
        with contextlib.suppress(OSError):
            os.nice(nice)
    if server_pid is not None:
        threading.Thread(target=_exit_with, args=(server_pid,), name="server-watchdog",
                         daemon=True).start()


def _exit_with(pid: int) -> None:
    """Block until process ``pid`` ends, then end this process at once.

    The parent-death signal cannot serve here: with the forkserver start method the
    parent is the fork server, which outlives the service.
    """
    try:
        fd = os.pidfd_open(pid)  # readable once the process has exited (Linux >= 5.3)
    except (AttributeError, OSError):
        fd = None
    if fd is not None:
        select.select([fd], [], [])
    else:
        while True:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            except PermissionError:
                pass
            time.sleep(1.0)
    os._exit(70)


def warmup(compile_all: bool = False) -> int:
    """Get the numba kernels into this worker before the first job.

    With ``compile_all`` every kernel is compiled (or loaded) by :mod:`curvature.warmup`,
    logging each step: what a cold cache needs, done in one worker while the others wait for
    the cache it fills. Otherwise a tiny estimate loads the common kernels from the cache.
    Returns the worker's pid (the pool uses it to count warmed workers).
    """
    try:
        if compile_all:
            curvature.warmup.run(report=log.info)
        else:
            golden = np.pi * (3.0 - np.sqrt(5.0))
            i = np.arange(400)
            z = 1.0 - 2.0 * (i + 0.5) / i.size
            r = np.sqrt(1.0 - z * z)
            sphere = np.column_stack([r * np.cos(golden * i), r * np.sin(golden * i), z])
            curvature.estimate(sphere, method="knn", k=10, workers=1)
    except Exception:  # warm-up is an optimisation; a failure must not take the pool down
        log.exception("warm-up failed")
    return os.getpid()


# -- computing -----------------------------------------------------------------------------

def compute(cloud: CloudInput, params: dict, workers: int, progress=None,
            tiles: dict | None = None):
    """Call ``curvature.estimate`` with the validated job parameters.

    ``params`` is the JSON form of a :mod:`service.schemas` method model: ``method``, the
    common fit/orientation fields, and the method's own parameters. ``tiles`` holds the
    ``executor`` and ``tile_points`` of a run on a Dask cluster (:mod:`service.dask_tiles`).
    """
    p = dict(params)
    method = p.pop("method")
    # "auto" has no fit field: it picks its own.
    common = {"fit": p.pop("fit", None), "orientation": p.pop("orientation", None),
              "viewpoint": p.pop("viewpoint", None)}
    solver = p.pop("solver", None)
    if solver is not None:
        p["solver"] = solver
    try:
        # A file's cloud goes in whole, so its attributes and viewpoint reach the result.
        given = {"normals": cloud.normals, "faces": cloud.faces} if cloud.cloud is None else {}
        result = curvature.estimate(cloud.points if cloud.cloud is None else cloud.cloud,
                                    method, **given, workers=workers or None,
                                    progress=progress, **common, **(tiles or {}), **p)
    except curvature.ParameterError as exc:
        raise ProblemError("invalid-parameters", str(exc)) from None
    except curvature.CurvatureInputError as exc:
        raise ProblemError("invalid-cloud", str(exc)) from None
    except Exception as exc:
        problem = cluster_problem(exc) if tiles else None
        if problem is None:
            raise
        log.error("cluster failure: %r", exc)
        raise problem from None
    if result.faces is None and cloud.faces is not None:
        result.faces = cloud.faces  # the result PLY keeps the input mesh
    return result


def summarize(result, cloud: CloudInput, seconds: float) -> dict:
    """What a finished job reports besides its files."""
    return {"n_points": len(result), "status_counts": result.status_counts(),
            "dropped_points": cloud.dropped, "compute_seconds": round(seconds, 3),
            "has_faces": result.faces is not None, "tiles": result.info.get("tiles")}


class ProgressReporter:
    """Throttled progress writes that double as the cancellation and time-limit checks.

    Parameters
    ----------
    store : JobStore
    job_id, run_token : str
    interval : float
        Minimum seconds between two progress writes.
    time_limit : float, optional
        Seconds from now after which the next call raises the ``time-limit`` problem.
    """

    def __init__(self, store: JobStore, job_id: str, run_token: str, interval: float,
                 time_limit: float | None = None):
        self.store, self.job_id, self.run_token = store, job_id, run_token
        self.interval = interval
        self.time_limit = time_limit
        self.deadline = float("inf") if time_limit is None else time.monotonic() + time_limit
        self.last = -float("inf")
        self.aborted = False

    def __call__(self, fraction: float, force: bool = False) -> None:
        now = time.monotonic()
        if self.aborted:
            raise JobAborted(self.job_id)
        if now > self.deadline:
            # Stopping here is clean; the executor kills the pool only if this is never
            # reached (a long stretch without progress calls).
            raise time_limit_problem(self.time_limit)
        if not force and now - self.last < self.interval:
            return
        self.last = now
        try:
            owned = self.store.report_progress(self.job_id, self.run_token, fraction)
        except sqlite3.OperationalError as exc:
            # Progress is advisory: a store locked past its timeout skips one report rather
            # than failing a computation that may be nearly done.
            log.warning("job %s: progress not stored (%s)", self.job_id, exc)
            return
        if not owned:
            self.aborted = True
            raise JobAborted(self.job_id)

    def on_estimate(self, done: int, total: int) -> None:
        """The ``progress(done, total)`` callback given to ``curvature.estimate``."""
        self(_LOADED + (_ESTIMATED - _LOADED) * done / max(total, 1))


def run_job(db_path: str, jobs_dir: str, job_id: str, run_token: str, options: dict) -> str:
    """Run one queued job to its end and record the outcome in the store.

    Parameters
    ----------
    db_path, jobs_dir : str
        Locations of the store and of the job folders.
    job_id, run_token : str
        The job, and the token that fences this run against stale ones.
    options : dict
        ``estimate_workers``, ``progress_interval``, ``result_ttl``, and optionally
        ``time_limit`` (seconds), ``max_points``, ``busy_timeout`` (seconds) and the Dask
        options ``dask_address``, ``dask_tile_points``, ``dask_connect_seconds``.

    Returns
    -------
    str
        The status this run left the job in, or ``"skipped"`` if it was no longer queued.
    """
    store = JobStore(db_path, options.get("busy_timeout", 30.0))
    job = store.claim(job_id, run_token, os.getpid())
    if job is None:
        return "skipped"
    folder = Path(jobs_dir) / job_id
    reporter = ProgressReporter(store, job_id, run_token, options["progress_interval"],
                                options.get("time_limit"))
    ttl = options["result_ttl"]
    started = time.perf_counter()
    try:
        cloud = load_input(folder / job.input_file, job.input_kind, job.input_name,
                           options.get("max_points"))
        check_cloud(cloud)
        store.set_points(job_id, run_token, len(cloud.points))
        check_point_limit(len(cloud.points), options.get("max_points"))
        reporter(_LOADED, force=True)
        result = compute(cloud, job.params, options["estimate_workers"], reporter.on_estimate,
                         tile_options(options))
        if reporter.aborted:
            raise JobAborted(job_id)
        reporter(_ESTIMATED, force=True)
        digest = save_canonical(result, folder / CANONICAL_RESULT)
        summary = summarize(result, cloud, time.perf_counter() - started)
        if not store.finish(job_id, run_token, status=SUCCEEDED, ttl=ttl, summary=summary,
                            result_sha256=digest):
            raise JobAborted(job_id)
        # The input is kept until the job expires: a result lost or corrupted on disk is
        # computed again from it.
        return SUCCEEDED
    except JobAborted:
        (folder / CANONICAL_RESULT).unlink(missing_ok=True)
        return CANCELLED
    except ProblemError as exc:
        store.finish(job_id, run_token, status=FAILED, ttl=ttl, error=exc.to_dict())
        return FAILED
    except MemoryError:
        log.error("job %s ran out of memory", job_id)
        store.finish(job_id, run_token, status=FAILED, ttl=ttl, error=ProblemError(
            "internal-error", "the worker ran out of memory for this cloud").to_dict())
        return FAILED
    except (OSError, sqlite3.OperationalError) as exc:
        problem = storage_problem(exc, "running the job")
        if problem is None:
            log.exception("job %s failed unexpectedly", job_id)
            problem = ProblemError("internal-error", INTERNAL_ERROR_DETAIL)
        else:
            log.error("job %s: %s", job_id, exc)
        (folder / CANONICAL_RESULT).unlink(missing_ok=True)
        # If the store cannot take this either, the exception leaves the worker and the
        # executor re-queues the run.
        store.finish(job_id, run_token, status=FAILED, ttl=ttl, error=problem.to_dict())
        return FAILED
    except Exception:
        log.exception("job %s failed unexpectedly", job_id)
        store.finish(job_id, run_token, status=FAILED, ttl=ttl,
                     error=ProblemError("internal-error", INTERNAL_ERROR_DETAIL).to_dict())
        return FAILED


def check_point_limit(n_points: int, max_points: int | None) -> None:
    """Refuse clouds above the service's point limit before any estimate runs."""
    if max_points is not None and n_points > max_points:
        raise ProblemError("cloud-too-large", f"the cloud has {n_points} points; this service "
                           f"accepts at most {max_points} (CURVATURE_MAX_POINTS)")


def run_sync(input_path: str, kind: str, display_name: str | None, params: dict, fmt: str,
             out_dir: str, max_points: int, workers: int, max_cost: float = float("inf")) -> str:
    """Compute a small cloud right away and write the result in ``fmt``; return its path.

    Raises
    ------
    ProblemError
        Bad file, bad cloud, bad parameters, more than ``max_points`` points, or more work
        than ``max_cost`` units (:mod:`service.sync_cost`).
    """
    cloud = load_input(Path(input_path), kind, display_name, max_points)
    check_cloud(cloud)
    if len(cloud.points) > max_points:
        raise ProblemError("too-many-points",
                           f"the cloud has {len(cloud.points)} points; synchronous answers "
                           f"are limited to {max_points}; submit it to POST /v1/jobs")
    too_costly = sync_cost_problem(params, len(cloud.points), max_cost)
    if too_costly is not None:
        raise ProblemError("too-costly", too_costly)
    try:
        result = compute(cloud, params, workers)
        target = Path(out_dir) / f"result.{fmt}"
        write_result(result, target, fmt)
    except ProblemError:
        raise
    except Exception as exc:
        problem = storage_problem(exc, "writing the result")
        if problem is not None:
            raise problem from None
        log.exception("synchronous request failed unexpectedly")
        raise ProblemError("internal-error", INTERNAL_ERROR_DETAIL) from None
    return str(target)
