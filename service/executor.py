"""Runs jobs in a local process pool, fed from the durable job store.

The store, not the pool, holds the queue: a dispatcher task hands the oldest queued jobs to
the pool, never more than there are workers, so a restart loses nothing (queued rows are simply
picked up again) and synchronous requests wait behind at most one job per worker. The pool is
created when the app starts, with an explicit multiprocessing start method.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import time
import uuid
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import anyio.to_thread

from . import result_files, worker
from .metrics import ServiceMetrics
from .problem_types import ProblemError
from .problems import HTTPProblem
from .settings import Settings
from .store import JobStore

log = logging.getLogger("service.executor")

WORKER_CRASHED = ProblemError(
    "worker-crashed", "the worker process died while running this job, too many times "
    "(the cloud may need more memory than the worker has)").to_dict()


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
        self._pool: ProcessPoolExecutor | None = None
        self._in_flight: dict[str, tuple[Future, ProcessPoolExecutor, float]] = {}
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sync_pending = 0
        self._stopping = False
        self.warmed_up = not settings.warmup
        self._options = {"estimate_workers": settings.estimate_workers,
                         "progress_interval": settings.progress_interval_seconds,
                         "result_ttl": settings.result_ttl_seconds}

    # -- lifecycle ---------------------------------------------------------------------------

    def _new_pool(self) -> ProcessPoolExecutor:
        context = multiprocessing.get_context(self.settings.start_method)
        if self.settings.start_method == "forkserver":
            # Import numpy/scipy/numba/curvature once in the fork server, not in every worker.
            context.set_forkserver_preload(["service.worker"])
        return ProcessPoolExecutor(max_workers=self.workers, mp_context=context,
                                   initializer=worker.init_worker,
                                   initargs=(self.settings.log_level, os.getpid()))

    async def start(self) -> None:
        """Create the pool, start warm-up and the dispatcher."""
        self._loop = asyncio.get_running_loop()
        self._pool = self._new_pool()
        self.metrics.pool_workers.set(self.workers)
        if self.settings.warmup:
            self._tasks.append(asyncio.create_task(self._warm_up()))
        self._tasks.append(asyncio.create_task(self._dispatch_loop()))
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
            _terminate(self._pool)
            self._pool = None
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

    def wake(self) -> None:
        """Ask the dispatcher to look at the queue now (a job was added or a slot freed)."""
        self._wake.set()

    async def _warm_up(self) -> None:
        # One task per worker also makes the pool start all its processes now.
        started = time.perf_counter()
        futures = [asyncio.wrap_future(self._pool.submit(worker.warmup))
                   for _ in range(self.workers)]
        try:
            pids = await asyncio.gather(*futures)
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
        ids = await anyio.to_thread.run_sync(self.store.next_queued, free,
                                             set(self._in_flight))
        for job_id in ids:
            if job_id in self._in_flight:
                continue
            pool = self._pool
            token = uuid.uuid4().hex
            try:
                future = pool.submit(worker.run_job, str(self.settings.db_path),
                                     str(self.settings.jobs_dir), job_id, token, self._options)
            except (BrokenProcessPool, RuntimeError):
                self._replace_pool(pool)
                return
            self._in_flight[job_id] = (future, pool, time.perf_counter())
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
        if future.cancelled():
            outcome = "not-started"
        elif isinstance(future.exception(), BrokenProcessPool):
            outcome = "crashed"
            pool = entry[1] if entry else None
            self._tasks.append(asyncio.create_task(self._after_crash(job_id, pool)))
        elif future.exception() is not None:
            outcome = "error"
            log.error("job %s: pool error %r", job_id, future.exception())
            self._tasks.append(asyncio.create_task(self._after_crash(job_id, None)))
        else:
            outcome = future.result()
        self.metrics.jobs_finished.inc(outcome=outcome)
        if entry is not None:
            self.metrics.job_seconds.observe(time.perf_counter() - entry[2], outcome=outcome)
        self.wake()

    async def _after_crash(self, job_id: str, pool: ProcessPoolExecutor | None) -> None:
        status = await anyio.to_thread.run_sync(
            self.store.requeue_after_crash, job_id, self.settings.max_attempts, WORKER_CRASHED)
        log.warning("job %s: worker process died; job is now %s", job_id, status)
        if pool is not None:
            self._replace_pool(pool)
        self.wake()

    def _replace_pool(self, broken: ProcessPoolExecutor) -> None:
        """Swap a broken pool for a new one (once, however many jobs report it)."""
        if self._pool is not broken or self._stopping:
            return
        log.warning("worker pool broken; starting a new one")
        _terminate(broken, grace=0.0)
        self._pool = self._new_pool()

    def cancel(self, job_id: str) -> None:
        """Drop a cancelled job from the pool's queue if it has not started yet.

        A job already running notices the cancellation in its next progress report.
        """
        entry = self._in_flight.get(job_id)
        if entry is not None:
            entry[0].cancel()

    # -- direct calls ------------------------------------------------------------------------

    async def call(self, fn, *args):
        """Run ``fn(*args)`` in the pool and await its result (render, synchronous compute)."""
        pool = self._pool
        if pool is None:
            raise HTTPProblem("not-ready", "the worker pool is not running")
        try:
            return await asyncio.wrap_future(pool.submit(fn, *args))
        except BrokenProcessPool:
            self._replace_pool(pool)
            raise HTTPProblem("internal-error", "the worker process died during the request; "
                              "the cloud may need more memory than a worker has") from None

    @property
    def sync_waiting(self) -> int:
        """Synchronous requests handed to the pool and not answered yet."""
        return self._sync_pending

    async def run_sync(self, *args) -> str:
        """``worker.run_sync(*args)`` in the pool."""
        self._sync_pending += 1
        try:
            return await self.call(worker.run_sync, *args)
        finally:
            self._sync_pending -= 1

    async def render(self, job_dir: Path, fmt: str) -> str:
        return await self.call(result_files.render, str(job_dir), fmt)


def _terminate(pool: ProcessPoolExecutor, grace: float = 2.0) -> None:
    """Shut a pool down without waiting for running jobs (they are re-queued on restart).

    Idle workers get the normal stop message and exit cleanly; workers still busy after
    ``grace`` seconds are terminated.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())  # no API before 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace
    for process in processes:
        process.join(timeout=max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.terminate()
            process.join(timeout=5)
    # The manager thread now sees the workers gone and releases the pool's queues.
    pool.shutdown(wait=True)


def create_executor(settings: Settings, store: JobStore,
                    metrics: ServiceMetrics) -> LocalPoolExecutor:
    """The executor named by ``settings.executor``."""
    if settings.executor == "dask":
        raise RuntimeError("CURVATURE_EXECUTOR=dask is not available yet; use 'local'")
    return LocalPoolExecutor(settings, store, metrics)
