"""Runs jobs in a local process pool, fed from the durable job store.

The store, not the pool, holds the queue: a dispatcher task hands the oldest queued jobs to
the pool, never more than there are workers, so a restart loses nothing (queued rows are simply
picked up again) and synchronous requests wait behind at most one job per worker. The pool is
created when the app starts, with an explicit multiprocessing start method.

A watchdog task ends runs past the per-job time limit that did not stop by themselves (the
pool is killed and rebuilt; the other runs it held are re-queued without counting against
them), and re-queues running jobs no run of this process owns any more (their outcome could
not be recorded), so no job stays ``running`` for ever.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import sqlite3
import time
import uuid
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

import anyio.to_thread

from curvature.warmup import cache_is_warm

from . import dask_tiles, result_files, worker
from .metrics import ServiceMetrics
from .problem_types import ProblemError
from .problems import HTTPProblem
from .settings import Settings
from .store import FAILED, JobStore
from .sync_lane import SyncLane, new_pool

log = logging.getLogger("service.executor")



def worker_crashed(runs: int) -> dict:
    """The error of a job quarantined for killing its worker ``runs`` times."""
    return ProblemError(
        "worker-crashed", f"quarantined: the worker process died while running this job "
        f"{runs} time(s) (CURVATURE_MAX_ATTEMPTS), so it is not run again; the cloud may "
        "need more memory than a worker has, or the parameters may be too costly").to_dict()


# How long the processes of a broken pool are given to report how they ended.
_EXIT_WAIT_SECONDS = 5.0
# How long the watchdog's read of the running jobs waits for a locked store: not the store's
# own 30 s, because the lock may be held by the very run the watchdog has to end.
WATCH_BUSY_SECONDS = 1.0
OUTCOME_LOST = ProblemError(
    "worker-crashed", "the outcome of this job could not be recorded, too many times "
    "(is the server's disk full?)").to_dict()


@dataclass(eq=False)
class _Pool:
    """A process pool, whether it was killed on purpose (time limit) rather than broke, and
    every worker process it started (kept to learn how each ended once it broke)."""

    executor: ProcessPoolExecutor
    killed_on_purpose: bool = False
    processes: dict = field(default_factory=dict)

    def note_processes(self) -> None:
        self.processes.update(getattr(self.executor, "_processes", None) or {})  # no API

    def culprits(self) -> set[int] | None:
        """Pids of the workers that died by themselves (killed, crashed, out of memory).

        When one worker dies, the pool terminates the others (SIGTERM) and fails every run;
        the victims are told apart by that exit. Waits briefly for all exits to be known;
        ``None`` when they are not (then nobody can be cleared).
        """
        deadline = time.monotonic() + _EXIT_WAIT_SECONDS
        while any(p.exitcode is None for p in self.processes.values()):
            if time.monotonic() > deadline:
                return None
            time.sleep(0.05)
        return {pid for pid, p in self.processes.items() if p.exitcode != -signal.SIGTERM}


@dataclass(eq=False)
class _InFlight:
    """A job handed to the pool: its future, pool, run token, hand-over time, and the start
    of its run as last read from the store (None until the watchdog has seen it running)."""

    future: Future
    pool: _Pool
    token: str
    handed_at: float
    started_at: float | None = None


class LocalPoolExecutor:
    """Process pool plus the dispatcher that feeds it from the store.

    Parameters
    ----------
    settings : Settings
    store : JobStore
    metrics : ServiceMetrics
    """

    def __init__(self, settings: Settings, store: JobStore, metrics: ServiceMetrics):
        self.settings = settings
        self.store = store
        self.metrics = metrics
        self.workers = settings.workers
        self._pool: _Pool | None = None
        self._in_flight: dict[str, _InFlight] = {}
        self._orphan_suspects: dict[str, str | None] = {}
        self._timed_out: set[str] = set()  # runs being ended by the watchdog
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sync_pending = 0
        self.sync_lane = SyncLane(settings, lambda reason: metrics.sync_stopped.inc(
            reason=reason))
        self._stopping = False
        self.warmed_up = not settings.warmup
        self.compiling = False  # warm-up is compiling kernels (a cold numba cache)
        self.compile_started = 0.0

    @property
    def _options(self) -> dict:
        """What each run needs to know of the settings (read at every dispatch)."""
        s = self.settings
        return {"estimate_workers": s.estimate_workers,
                "progress_interval": s.progress_interval_seconds,
                "result_ttl": s.result_ttl_seconds, "time_limit": s.job_time_limit_seconds,
                "max_points": s.max_points, "busy_timeout": s.store_busy_timeout_seconds}

    # -- lifecycle ---------------------------------------------------------------------------

    def _new_pool(self) -> _Pool:
        return _Pool(new_pool(self.settings, self.workers))

    async def start(self) -> None:
        """Create the pool, start warm-up and the dispatcher."""
        self._loop = asyncio.get_running_loop()
        self._pool = self._new_pool()
        self.sync_lane.start(warm=self.settings.warmup)
        self.metrics.pool_workers.set(self.workers)
        if self.settings.warmup:
            self._tasks.append(asyncio.create_task(self._warm_up()))
        self._tasks.append(asyncio.create_task(self._dispatch_loop()))
        self._tasks.append(asyncio.create_task(self._watch_loop()))
        self.wake()

    async def stop(self) -> None:
        """Stop dispatching and end the workers; running jobs are re-queued at next start."""
        self._stopping = True
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            try:
                await task
            except (asyncio.CancelledError, Exception):
                pass
        if self._pool is not None:
            _terminate(self._pool.executor)
            self._pool = None
        self.sync_lane.stop()
        # Drop every reference to the old pool so its named semaphores are released (and
        # unregistered from the resource tracker) now rather than never.
        self._in_flight.clear()
        self._tasks.clear()

    @property
    def ready(self) -> bool:
        return self._pool is not None and self.warmed_up and not self._stopping

    @property
    def in_flight(self) -> int:
        return len(self._in_flight)

    def busy_ids(self) -> set[str]:
        """Jobs handed to the pool and not finished there (their files are in use)."""
        return set(self._in_flight)

    def worker_pids(self) -> list[int]:
        """Process ids of the current pool's workers."""
        if self._pool is None:
            return []
        processes = getattr(self._pool.executor, "_processes", None) or {}  # no API < 3.14
        return [p.pid for p in list(processes.values()) if p.pid is not None]

    def wake(self) -> None:
        """Ask the dispatcher to look at the queue now (a job was added or a slot freed)."""
        self._wake.set()

    async def _warm_up(self) -> None:
        started = time.perf_counter()
        submit = self._pool.executor.submit
        try:
            pids = []
            if not cache_is_warm():
                # Compiling takes minutes; one worker fills numba's cache, the others then
                # load from it instead of compiling the same kernels at the same time.
                self.compiling = True
                self.compile_started = time.monotonic()
                log.warning("compiling the numeric kernels (numba cache missing or stale; "
                            "`make venv` or `python -m curvature.warmup` does this at "
                            "install): not ready until done, progress in the worker's log")
                try:
                    pids.append(await asyncio.wrap_future(submit(worker.warmup, True)))
                finally:
                    self.compiling = False
            # One task per worker also makes the pool start all its processes now.
            pids += await asyncio.gather(*(asyncio.wrap_future(submit(worker.warmup))
                                           for _ in range(self.workers)))
            log.info("pool warm: %d task(s) on %d process(es) in %.1f s", len(pids),
                     len(set(pids)), time.perf_counter() - started)
        except BrokenProcessPool:
            log.error("the pool broke during warm-up")
        self.warmed_up = True

    # -- dispatching -------------------------------------------------------------------------

    async def _dispatch_loop(self) -> None:
        while True:
            try:
                await asyncio.wait_for(self._wake.wait(),
                                       timeout=self.settings.dispatch_poll_seconds)
            except TimeoutError:
                pass
            self._wake.clear()
            try:
                await self._dispatch()
            except Exception:
                log.exception("dispatch failed; retrying")

    async def _dispatch(self) -> None:
        free = self.workers - len(self._in_flight)
        if free <= 0 or self._pool is None:
            return
        s = self.settings
        # With two workers or more, one is kept for small jobs (no head-of-line blocking).
        large_slots = max(1, self.workers - s.small_job_workers)
        ids = await anyio.to_thread.run_sync(lambda: self.store.next_queued(
            free, set(self._in_flight), large_bytes=s.small_job_bytes,
            large_slots=large_slots))
        options = self._options
        for job_id in ids:
            if job_id in self._in_flight:
                continue
            pool = self._pool
            token = uuid.uuid4().hex
            try:
                future = pool.executor.submit(worker.run_job, str(self.settings.db_path),
                                              str(self.settings.jobs_dir), job_id, token,
                                              options)
            except (BrokenProcessPool, RuntimeError):
                self._replace_pool(pool)
                return
            pool.note_processes()  # the pool starts a process on submit when one is missing
            self._in_flight[job_id] = _InFlight(future, pool, token, time.perf_counter())
            future.add_done_callback(self._done_callback(job_id))
        self.metrics.pool_busy.set(len(self._in_flight))

    def _done_callback(self, job_id: str):
        loop = self._loop

        def callback(future: Future) -> None:
            # Runs in the pool's manager thread; hop to the event loop.
            try:
                loop.call_soon_threadsafe(self._on_done, job_id, future)
            except RuntimeError:  # loop already closed at shutdown
                pass

        return callback

    def _on_done(self, job_id: str, future: Future) -> None:
        entry = self._in_flight.pop(job_id, None)
        self.metrics.pool_busy.set(len(self._in_flight))
        if self._stopping:
            return
        token = entry.token if entry is not None else None
        if job_id in self._timed_out:
            outcome = "time-limit"  # the watchdog records the outcome
        elif future.cancelled():
            outcome = "not-started"
        elif isinstance(future.exception(), BrokenProcessPool):
            outcome = "crashed"
            pool = entry.pool if entry else None
            self._tasks.append(asyncio.create_task(self._after_crash(job_id, token, pool)))
        elif future.exception() is not None:
            outcome = "error"
            log.error("job %s: pool error %r", job_id, future.exception())
            self._tasks.append(asyncio.create_task(self._after_crash(job_id, token, None)))
        else:
            outcome = future.result()
        self.metrics.jobs_finished.inc(outcome=outcome)
        if entry is not None:
            self.metrics.job_seconds.observe(time.perf_counter() - entry.handed_at,
                                             outcome=outcome)
        self._tasks = [t for t in self._tasks if not t.done()]
        self.wake()

    async def _after_crash(self, job_id: str, token: str | None, pool: _Pool | None,
                           error: dict | None = None) -> None:
        # A pool killed on purpose stopped this run for another job's time limit.
        on_purpose = pool is not None and pool.killed_on_purpose
        innocent = on_purpose or (pool is not None
                                  and await anyio.to_thread.run_sync(self._innocent, job_id,
                                                                     pool))
        max_attempts = self.settings.max_attempts
        try:
            status = await anyio.to_thread.run_sync(lambda: self.store.requeue_after_crash(
                job_id, token, max_attempts, error or worker_crashed(max_attempts),
                count_attempt=not innocent, ttl=self.settings.result_ttl_seconds))
        except Exception:  # e.g. the store is locked or full: the watchdog tries again
            log.exception("job %s: could not re-queue it after its run ended", job_id)
            status = "left running (retried by the watchdog)"
        if status is not None:
            log.warning("job %s: its run ended without an outcome%s; job is now %s", job_id,
                        " (pool stopped for a time limit)" if on_purpose else
                        " (another job's worker died; not charged)" if innocent else "",
                        status)
        if pool is not None:
            self._replace_pool(pool)
        self.wake()

    def _innocent(self, job_id: str, pool: _Pool) -> bool:
        """True when the job's own worker was only stopped because another one died."""
        job = self.store.get(job_id)
        if job is None or job.worker_pid is None or job.worker_pid not in pool.processes:
            return False
        culprits = pool.culprits()
        return bool(culprits) and job.worker_pid not in culprits

    def _replace_pool(self, broken: _Pool, on_purpose: bool = False) -> None:
        """Swap a broken pool for a new one (once, however many jobs report it)."""
        if self._pool is not broken or self._stopping:
            return
        broken.killed_on_purpose = broken.killed_on_purpose or on_purpose
        log.warning("worker pool %s; starting a new one",
                    "killed to end a run past its time limit" if on_purpose else "broken")
        _terminate(broken.executor, grace=0.0, kill=on_purpose)
        self._pool = self._new_pool()

    def cancel(self, job_id: str) -> None:
        """Drop a cancelled job from the pool's queue if it has not started yet.

        A job already running notices the cancellation in its next progress report.
        """
        entry = self._in_flight.get(job_id)
        if entry is not None:
            entry.future.cancel()

    # -- watchdog ----------------------------------------------------------------------------

    async def _watch_loop(self) -> None:
        while True:
            await asyncio.sleep(min(1.0, self.settings.dispatch_poll_seconds))
            try:
                await self.watch()
            except Exception:
                log.exception("watchdog failed; retrying")

    async def watch(self) -> None:
        """End runs past their time limit; re-queue running jobs that no run here owns."""
        try:
            rows = await anyio.to_thread.run_sync(self.store.running, WATCH_BUSY_SECONDS)
        except sqlite3.OperationalError as exc:
            # A worker stopped in the middle of a commit can leave the store unreadable until
            # it is gone; the runs' start times read before still tell which one is overdue,
            # so the kill that frees the store does not wait for the store.
            log.warning("watchdog: the job store is locked (%s); time limits checked against "
                        "the start times read before", exc)
            await self._stop_overdue_runs(
                (job_id, e.token, e.started_at) for job_id, e in list(self._in_flight.items()))
            return
        # Read the in-flight table after the store: a job claimed before the query was
        # handed to the pool before it, so it is in the table unless its run has ended.
        suspects: dict[str, str | None] = {}
        for job_id, token, started_at in rows:
            entry = self._in_flight.get(job_id)
            if entry is not None and entry.token == token:
                entry.started_at = started_at
                continue
            if self._orphan_suspects.get(job_id, "") == token:
                # Seen without a run twice in a row: its outcome was lost.
                await self._after_crash(job_id, token, None, OUTCOME_LOST)
            else:
                suspects[job_id] = token
        self._orphan_suspects = suspects
        await self._stop_overdue_runs(rows)

    async def _stop_overdue_runs(self, runs) -> None:
        """End the runs here, of ``(job id, run token, started_at)``, past limit + grace."""
        limit = self.settings.job_time_limit_seconds + self.settings.time_limit_grace_seconds
        now = time.time()
        for job_id, token, started_at in list(runs):
            entry = self._in_flight.get(job_id)
            if (entry is not None and entry.token == token and started_at is not None
                    and now - started_at > limit):
                await self._stop_overdue(job_id, entry)

    async def _stop_overdue(self, job_id: str, entry: _InFlight) -> None:
        settings = self.settings
        log.warning("job %s: still running %g s past its time limit of %g s; killing the "
                    "worker pool", job_id, settings.time_limit_grace_seconds,
                    settings.job_time_limit_seconds)
        # Kill first: a wedged worker may hold the store's write lock, and the outcome could
        # not be written before it is gone.
        self._timed_out.add(job_id)
        try:
            self._replace_pool(entry.pool, on_purpose=True)
            error = worker.time_limit_problem(settings.job_time_limit_seconds).to_dict()
            await anyio.to_thread.run_sync(lambda: self.store.finish(
                job_id, entry.token, status=FAILED, ttl=settings.result_ttl_seconds,
                error=error))
        finally:
            self._timed_out.discard(job_id)

    # -- direct calls ------------------------------------------------------------------------

    async def call(self, fn, *args):
        """Run ``fn(*args)`` in the pool and await its result (render, synchronous compute)."""
        pool = self._pool
        if pool is None:
            raise HTTPProblem("not-ready", "the worker pool is not running")
        try:
            return await asyncio.wrap_future(pool.executor.submit(fn, *args))
        except BrokenProcessPool:
            self._replace_pool(pool)
            raise HTTPProblem("internal-error", "the worker process died during the request; "
                              "the cloud may need more memory than a worker has") from None

    @property
    def sync_waiting(self) -> int:
        """Synchronous requests handed to the pool and not answered yet."""
        return self._sync_pending

    async def run_sync(self, *args, disconnected=None) -> str:
        """``worker.run_sync(*args)`` on the synchronous lane, under the synchronous time
        limit, killed if ``disconnected`` (an awaitable) completes first."""
        s = self.settings
        self._sync_pending += 1
        try:
            return await self.sync_lane.run(
                worker.run_sync, *args, disconnected=disconnected,
                time_limit=min(s.sync_time_limit_seconds, s.job_time_limit_seconds))
        finally:
            self._sync_pending -= 1

    async def render(self, job_dir: Path, fmt: str, canonical_sha256: str | None = None,
                     expected: str | None = None) -> tuple[str, str]:
        """:func:`result_files.render` in the pool: path and digest of the file."""
        return await self.call(result_files.render, str(job_dir), fmt, canonical_sha256,
                               expected)


def _terminate(pool: ProcessPoolExecutor, grace: float = 2.0, kill: bool = False) -> None:
    """Shut a pool down without waiting for running jobs (they are re-queued on restart).

    Idle workers get the normal stop message and exit cleanly; workers still busy after
    ``grace`` seconds are terminated, or killed at once with ``kill`` (a run past its time
    limit may be wedged, or stopped, and deaf to SIGTERM).
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())  # no API before 3.14
    if kill:
        for process in processes:
            if process.is_alive():
                process.kill()
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace
    for process in processes:
        process.join(timeout=max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.terminate()
            process.join(timeout=2)
    for process in processes:
        if process.is_alive():  # a stopped (SIGSTOP) or wedged worker ignores SIGTERM
            process.kill()
            process.join(timeout=5)
    # The manager thread now sees the workers gone and releases the pool's queues.
    pool.shutdown(wait=True)


class DaskExecutor(LocalPoolExecutor):
    """The local pool drives each job; its tiles run as tasks on a Dask cluster.

    Everything about jobs stays as with the local pool (the store holds the queue and the job
    records, cancellation, time limits, crash recovery); each run only gets the scheduler's
    address and connects to it (:mod:`service.dask_tiles`). The scheduler recomputes the
    tiles of a worker that dies, so the job goes on.
    """

    @property
    def _options(self) -> dict:
        s = self.settings
        return {**super()._options, "dask_address": s.dask_address,
                "dask_tile_points": s.dask_tile_points,
                "dask_connect_seconds": s.dask_connect_seconds}

    async def start(self) -> None:
        await super().start()
        self._tasks.append(asyncio.create_task(self._probe_cluster()))

    async def _probe_cluster(self) -> None:
        """Say at startup whether the cluster answers (jobs connect by themselves)."""
        address, timeout = self.settings.dask_address, self.settings.dask_connect_seconds
        try:
            count = await anyio.to_thread.run_sync(dask_tiles.cluster_workers, address,
                                                   timeout)
            log.info("Dask scheduler at %s has %d worker(s); tiles of %d points run there",
                     address, count, self.settings.dask_tile_points)
        except Exception as exc:  # jobs fail with 'cluster-unavailable' while it stays down
            log.error("Dask scheduler at %s did not answer: %s", address, exc)


def create_executor(settings: Settings, store: JobStore,
                    metrics: ServiceMetrics) -> LocalPoolExecutor:
    """The executor named by ``settings.executor``."""
    if settings.executor == "dask":
        return DaskExecutor(settings, store, metrics)
    return LocalPoolExecutor(settings, store, metrics)
