"""Removal of expired jobs, their files, and abandoned scratch files.

Never touched: the files of a job that is not final or that the pool still holds (a job
cancelled while running keeps computing until its next progress report), and folders of
uploads or synchronous requests in progress (the caller passes their names as ``busy``).
"""

from __future__ import annotations

import asyncio
import logging
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio.to_thread

from .settings import Settings
from .store import JobStore

log = logging.getLogger("service.cleanup")

# Folders without a job row (a crash between upload and insert) and scratch folders of
# synchronous requests are removed once they are this old.
ORPHAN_AGE_SECONDS = 3600.0


def remove_job_files(settings: Settings, job_id: str) -> None:
    shutil.rmtree(settings.jobs_dir / job_id, ignore_errors=True)


def _old_folders(root: Path, now: float, age: float) -> list[Path]:
    if not root.is_dir():
        return []
    out = []
    for entry in root.iterdir():
        try:
            if entry.is_dir() and now - entry.stat().st_mtime > age:
                out.append(entry)
        except FileNotFoundError:
            continue
    return out


def sweep(settings: Settings, store: JobStore, now: float | None = None,
          busy: frozenset[str] | set[str] = frozenset(),
          orphan_age: float = ORPHAN_AGE_SECONDS) -> int:
    """Delete expired jobs (row and folder) and stale orphan folders; return jobs removed.

    Parameters
    ----------
    settings : Settings
    store : JobStore
    now : float, optional
        The current time (tests pass a later one).
    busy : set of str
        Job ids and scratch folder names in use; skipped whatever their age.
    orphan_age : float
        Age after which a folder without a job row counts as abandoned (0 at startup, when
        no upload can be in progress).
    """
    now = time.time() if now is None else now
    removed = 0
    for job_id in store.expired(now):
        # The row goes first and only if still expired and final: a folder is never removed
        # for a job that could still run.
        if job_id in busy or not store.delete_expired(job_id, now):
            continue
        removed += 1
        remove_job_files(settings, job_id)
    known = store.all_ids()
    for folder in _old_folders(settings.jobs_dir, now, orphan_age):
        if folder.name not in known and folder.name not in busy:
            shutil.rmtree(folder, ignore_errors=True)
    for folder in _old_folders(settings.tmp_dir, now, orphan_age):
        if folder.name not in busy:
            shutil.rmtree(folder, ignore_errors=True)
    if removed:
        log.info("removed %d expired job(s)", removed)
    return removed


async def cleanup_loop(settings: Settings, store: JobStore,
                       busy: Callable[[], set[str]]) -> None:
    """Run :func:`sweep` every ``cleanup_interval_seconds`` until cancelled.

    ``busy()`` is called on the event loop (where the sets it reads change) before each sweep.
    """
    while True:
        try:
            await anyio.to_thread.run_sync(sweep, settings, store, None, frozenset(busy()))
        except Exception:
            log.exception("cleanup failed; retrying at the next interval")
        await asyncio.sleep(settings.cleanup_interval_seconds)


class BusyFolders:
    """Names of job or scratch folders that requests in progress are writing."""

    def __init__(self):
        self._names: set[str] = set()

    @contextmanager
    def hold(self, name: str) -> Iterator[None]:
        """Mark ``name`` busy for the duration of the ``with`` block."""
        self._names.add(name)
        try:
            yield
        finally:
            self._names.discard(name)

    def __call__(self) -> set[str]:
        return set(self._names)
