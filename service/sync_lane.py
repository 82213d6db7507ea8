"""Worker processes of synchronous requests, each one killable on its own.

``POST /v1/curvature`` must not outlive its time limit nor its client. A thread cannot be
stopped and a shared pool can only be killed whole (taking the jobs of other clients with it),
so every synchronous slot is a one-process pool of its own: a request takes a free slot, and
when it runs past the limit or the client hangs up, that slot's process is killed and the slot
is replaced by a fresh one. Jobs never run here, so nothing else is disturbed.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
from collections.abc import Awaitable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from . import worker
from .problems import HTTPProblem
from .settings import Settings

log = logging.getLogger("service.sync")


class SyncAborted(Exception):
    """The client went away before its synchronous answer was ready; the run was killed."""


def new_pool(settings: Settings, workers: int) -> ProcessPoolExecutor:
    """A process pool of ``workers`` with the service's start method and initializer."""
    context = multiprocessing.get_context(settings.start_method)
    if settings.start_method == "forkserver":
        # Import numpy/scipy/numba/curvature once in the fork server, not in every worker.
        context.set_forkserver_preload(["service.worker"])
    return ProcessPoolExecutor(max_workers=workers, mp_context=context,
                               initializer=worker.init_worker,
                               initargs=(settings.log_level, os.getpid(),
                                         settings.worker_nice))


def kill_pool(pool: ProcessPoolExecutor) -> None:
    """Kill a pool's processes at once and release its queues."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.kill()
        process.join(timeout=5)
    pool.shutdown(wait=True, cancel_futures=True)


class SyncLane:
    """``settings.sync_workers`` one-process pools that synchronous requests take turns on.

    Parameters
    ----------
    settings : Settings
    on_stop : callable, optional
        Called with the reason (``"time-limit"``, ``"disconnect"``, ``"crashed"``) whenever a
        run is ended by killing its slot.
    """

    def __init__(self, settings: Settings, on_stop=None):
        self.settings = settings
        self.on_stop = on_stop or (lambda reason: None)
        self._free: asyncio.Queue[ProcessPoolExecutor] | None = None
        self._all: set[ProcessPoolExecutor] = set()
        self.waiting = 0

    def start(self, warm: bool) -> None:
        """Create the slots; with ``warm`` each compiles the kernels now."""
        self._free = asyncio.Queue()
        for _ in range(self.settings.sync_workers):
            self._free.put_nowait(self._new_slot(warm))

    def _new_slot(self, warm: bool) -> ProcessPoolExecutor:
        pool = new_pool(self.settings, 1)
        self._all.add(pool)
        if warm:
            pool.submit(worker.warmup)  # queued before any request's task: runs first
        return pool

    def stop(self) -> None:
        for pool in list(self._all):
            kill_pool(pool)
        self._all.clear()

    def pids(self) -> list[int]:
        """Process ids of the slots' workers (those started so far)."""
        return [p.pid for pool in self._all
                for p in list((getattr(pool, "_processes", None) or {}).values())
                if p.pid is not None]

    async def run(self, fn, *args, time_limit: float,
                  disconnected: Awaitable[None] | None = None):
        """Run ``fn(*args)`` on a free slot; kill it past ``time_limit`` s or on disconnect.

        Raises
        ------
        HTTPProblem
            ``time-limit`` when the run took too long, ``internal-error`` when its process
            died by itself.
        SyncAborted
            ``disconnected`` completed first (the client hung up).
        """
        self.waiting += 1
        try:
            slot = await self._free.get()
        finally:
            self.waiting -= 1
        future = asyncio.wrap_future(slot.submit(fn, *args))
        watcher = asyncio.ensure_future(disconnected) if disconnected is not None else None
        replace = False
        try:
            waits = {future} | ({watcher} if watcher is not None else set())
            done, _ = await asyncio.wait(waits, timeout=time_limit,
                                         return_when=asyncio.FIRST_COMPLETED)
            if future in done:
                try:
                    return future.result()
                except BrokenProcessPool:
                    replace = True
                    self.on_stop("crashed")
                    raise HTTPProblem("internal-error", "the worker process died during the "
                                      "request; the cloud may need more memory than a worker "
                                      "has") from None
            replace = True
            if watcher is not None and watcher in done:
                self.on_stop("disconnect")
                log.warning("synchronous request: client disconnected; its run was killed")
                raise SyncAborted()
            self.on_stop("time-limit")
            raise HTTPProblem("time-limit", (
                f"the synchronous computation ran for more than {time_limit:g} s, the "
                "synchronous time limit (CURVATURE_SYNC_TIME_LIMIT_SECONDS); submit it to "
                "POST /v1/jobs, or use cheaper parameters"))
        except asyncio.CancelledError:
            replace = True  # the request task itself was cancelled (server shutting down)
            raise
        finally:
            if watcher is not None:
                watcher.cancel()
            if replace:
                self._all.discard(slot)
                # Killing joins the process; off the event loop.
                await asyncio.get_running_loop().run_in_executor(None, kill_pool, slot)
                slot = self._new_slot(warm=self.settings.warmup)
            self._free.put_nowait(slot)
