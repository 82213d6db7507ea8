"""Periodic removal of expired jobs, their files, and abandoned scratch files."""

from __future__ import annotations

import asyncio
import logging
import shutil
import time
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


def sweep(settings: Settings, store: JobStore, now: float | None = None) -> int:
    """Delete expired jobs (row and folder) and stale orphan folders; return jobs removed."""
    now = time.time() if now is None else now
    removed = 0
    for job_id in store.expired(now):
        if store.delete(job_id):
            removed += 1
        remove_job_files(settings, job_id)
    known = store.all_ids()
    for folder in _old_folders(settings.jobs_dir, now, ORPHAN_AGE_SECONDS):
        if folder.name not in known:
            shutil.rmtree(folder, ignore_errors=True)
    for folder in _old_folders(settings.tmp_dir, now, ORPHAN_AGE_SECONDS):
        shutil.rmtree(folder, ignore_errors=True)
    if removed:
        log.info("removed %d expired job(s)", removed)
    return removed


async def cleanup_loop(settings: Settings, store: JobStore) -> None:
    """Run :func:`sweep` every ``cleanup_interval_seconds`` until cancelled."""
    while True:
        try:
            await anyio.to_thread.run_sync(sweep, settings, store)
        except Exception:
            log.exception("cleanup failed; retrying at the next interval")
        await asyncio.sleep(settings.cleanup_interval_seconds)
