"""Durable job store on SQLite (WAL mode).

The store is the single source of truth of every job: a job exists once its row is committed,
before any work is scheduled, and the worker processes update their own rows (claim, progress,
outcome) through their own connections. A ``run_token`` written at claim time fences stale
workers: after a restart re-queues a job, updates from an older run match no row.
"""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED = (
    "queued", "running", "succeeded", "failed", "cancelled")
STATUSES = (QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED)
FINAL_STATUSES = (SUCCEEDED, FAILED, CANCELLED)

SCHEMA_VERSION = 2
_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    owner TEXT NOT NULL,
    status TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    params TEXT NOT NULL,
    input_kind TEXT NOT NULL,
    input_file TEXT NOT NULL,
    input_name TEXT,
    input_format TEXT,
    input_bytes INTEGER NOT NULL,
    n_points INTEGER,
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    expires_at REAL,
    attempts INTEGER NOT NULL DEFAULT 0,
    run_token TEXT,
    error TEXT,
    summary TEXT,
    restarts INTEGER NOT NULL DEFAULT 0,
    worker_pid INTEGER,
    result_sha256 TEXT,
    checksums TEXT
);
CREATE INDEX IF NOT EXISTS jobs_owner_seq ON jobs (owner, seq);
CREATE INDEX IF NOT EXISTS jobs_status_seq ON jobs (status, seq);
CREATE INDEX IF NOT EXISTS jobs_expires ON jobs (expires_at);
CREATE TABLE IF NOT EXISTS write_probe (id INTEGER PRIMARY KEY, at REAL NOT NULL);
"""
# Columns added after version 1, with their definitions, for stores created before them.
_ADDED_COLUMNS = {"restarts": "INTEGER NOT NULL DEFAULT 0", "worker_pid": "INTEGER",
                  "result_sha256": "TEXT", "checksums": "TEXT"}


@dataclass
class Job:
    """One row of the ``jobs`` table, JSON columns decoded."""

    seq: int
    id: str
    owner: str
    status: str
    progress: float
    params: dict
    input_kind: str
    input_file: str
    input_name: str | None
    input_format: str | None
    input_bytes: int
    n_points: int | None
    created_at: float
    started_at: float | None
    finished_at: float | None
    expires_at: float | None
    attempts: int
    run_token: str | None
    error: dict | None
    summary: dict | None
    restarts: int = 0  # server restarts that interrupted a run (not held against the job)
    worker_pid: int | None = None  # process of the current or last run
    result_sha256: str | None = None  # digest of the canonical result file
    checksums: dict | None = None  # digests of the rendered result files, by format

    @classmethod
    def from_row(cls, row: sqlite3.Row) -> Job:
        values = dict(row)
        for key in ("params", "error", "summary", "checksums"):
            if values[key] is not None:
                values[key] = json.loads(values[key])
        return cls(**values)

    @property
    def is_final(self) -> bool:
        return self.status in FINAL_STATUSES


def new_job_id() -> str:
    """A random, unguessable job id (32 hex digits)."""
    return uuid.uuid4().hex


class QueueLimitError(Exception):
    """A new job would exceed a queue limit; nothing was inserted.

    Attributes
    ----------
    scope : {"owner", "total"}
        Which limit: the owner's unfinished jobs, or all unfinished jobs.
    count, limit : int
        Unfinished jobs now, and the limit.
    """

    def __init__(self, scope: str, count: int, limit: int):
        super().__init__(scope, count, limit)
        self.scope, self.count, self.limit = scope, count, limit


def connect(db_path: str | Path, busy_timeout: float = 30.0) -> sqlite3.Connection:
    """Open a connection in autocommit mode; transactions are explicit (``BEGIN IMMEDIATE``).

    ``synchronous=FULL`` makes every commit durable even against power loss; commits are few
    (a handful per job plus throttled progress), so the fsyncs are cheap. A lock held by
    another connection is waited for up to ``busy_timeout`` seconds, then the operation
    raises ``sqlite3.OperationalError`` (database is locked) having changed nothing.
    """
    conn = sqlite3.connect(str(db_path), timeout=busy_timeout, isolation_level=None,
                           check_same_thread=False)
    conn.row_factory = sqlite3.Row
    conn.execute(f"PRAGMA busy_timeout = {int(busy_timeout * 1000)}")
    conn.execute("PRAGMA synchronous = FULL")
    conn.execute("PRAGMA foreign_keys = ON")
    return conn


class JobStore:
    """All reads and writes of job rows.

    A connection is opened per operation: it is cheap for SQLite, keeps every method
    thread-safe, and works the same in the server and in worker processes.

    Parameters
    ----------
    db_path : path
        The SQLite file; created with its folder by :meth:`initialize`.
    busy_timeout : float
        Seconds an operation waits for a lock held elsewhere before it fails.
    """

    def __init__(self, db_path: str | Path, busy_timeout: float = 30.0):
        self.db_path = Path(db_path)
        self.busy_timeout = busy_timeout

    @contextmanager
    def _conn(self, busy_timeout: float | None = None) -> Iterator[sqlite3.Connection]:
        conn = connect(self.db_path, self.busy_timeout if busy_timeout is None else busy_timeout)
        try:
            yield conn
        finally:
            conn.close()

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with self._conn() as conn:
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
            except BaseException:
                # SQLite rolls back by itself on some errors (SQLITE_FULL among them); a
                # second ROLLBACK would fail and hide the error that matters.
                if conn.in_transaction:
                    with suppress(sqlite3.Error):
                        conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")

    # -- setup and recovery ------------------------------------------------------------------

    def initialize(self) -> None:
        """Create the file and schema, switch the journal to WAL (a persistent setting)."""
        self.db_path.parent.mkdir(parents=True, exist_ok=True)
        with self._conn() as conn:
            mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
            if mode.lower() != "wal":
                raise RuntimeError(f"{self.db_path}: SQLite refused WAL mode (got {mode!r})")
            conn.executescript(_SCHEMA)
            present = {r[1] for r in conn.execute("PRAGMA table_info(jobs)").fetchall()}
            for name, definition in _ADDED_COLUMNS.items():
                if name not in present:
                    conn.execute(f"ALTER TABLE jobs ADD COLUMN {name} {definition}")
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def ping(self) -> bool:
        """True when the database answers a trivial query."""
        try:
            with self._conn() as conn:
                conn.execute("SELECT 1 FROM jobs LIMIT 1").fetchall()
            return True
        except sqlite3.Error:
            return False

    def writable(self) -> bool:
        """True when the database takes a write (a read-only file or mount does not)."""
        try:
            with self._transaction() as conn:
                conn.execute("INSERT OR REPLACE INTO write_probe (id, at) VALUES (1, ?)",
                             (time.time(),))
            return True
        except sqlite3.Error:
            return False

    def requeue_interrupted(self, max_restarts: int, error: dict,
                            ttl: float | None = None) -> tuple[int, int]:
        """After a restart: put jobs left ``running`` back in the queue.

        The interrupted run is not an attempt of the job (the server stopped, not the job's
        worker): it is counted in ``restarts`` instead, and a job interrupted by
        ``max_restarts`` restarts is marked failed with ``error`` (kept for ``ttl``
        seconds), so a job that takes the whole server down cannot loop forever.

        Returns
        -------
        requeued, failed : int
        """
        now = time.time()
        with self._transaction() as conn:
            conn.execute("UPDATE jobs SET restarts = restarts + 1, "
                         "attempts = MAX(attempts - 1, 0) WHERE status = ?", (RUNNING,))
            failed = conn.execute(
                "UPDATE jobs SET status = ?, finished_at = ?, expires_at = ?, error = ?, "
                "run_token = NULL WHERE status = ? AND restarts >= ?",
                (FAILED, now, None if ttl is None else now + ttl, json.dumps(error), RUNNING,
                 max_restarts)).rowcount
            requeued = conn.execute(
                "UPDATE jobs SET status = ?, progress = 0, run_token = NULL WHERE status = ?",
                (QUEUED, RUNNING)).rowcount
        return requeued, failed

    # -- server side -------------------------------------------------------------------------

    def insert(self, *, job_id: str, owner: str, params: dict, input_kind: str,
               input_file: str, input_name: str | None, input_format: str | None,
               input_bytes: int, n_points: int | None, max_unfinished: int | None = None,
               max_owner_unfinished: int | None = None) -> Job:
        """Commit a new ``queued`` job and return it.

        The limits are checked in the same write transaction as the insert, so concurrent
        submissions cannot overshoot them.

        Raises
        ------
        QueueLimitError
            The owner already has ``max_owner_unfinished`` unfinished jobs, or the store
            ``max_unfinished``.
        """
        with self._transaction() as conn:
            if max_owner_unfinished is not None:
                count = conn.execute(
                    "SELECT COUNT(*) FROM jobs WHERE owner = ? AND status IN (?, ?)",
                    (owner, QUEUED, RUNNING)).fetchone()[0]
                if count >= max_owner_unfinished:
                    raise QueueLimitError("owner", count, max_owner_unfinished)
            if max_unfinished is not None:
                count = conn.execute("SELECT COUNT(*) FROM jobs WHERE status IN (?, ?)",
                                     (QUEUED, RUNNING)).fetchone()[0]
                if count >= max_unfinished:
                    raise QueueLimitError("total", count, max_unfinished)
            conn.execute(
                "INSERT INTO jobs (id, owner, status, params, input_kind, input_file, "
                "input_name, input_format, input_bytes, n_points, created_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (job_id, owner, QUEUED, json.dumps(params), input_kind, input_file, input_name,
                 input_format, input_bytes, n_points, time.time()))
            row = conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return Job.from_row(row)

    def get(self, job_id: str) -> Job | None:
        with self._conn() as conn:
            row = conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else Job.from_row(row)

    def list_jobs(self, owner: str, *, limit: int, before_seq: int | None = None,
             status: str | None = None) -> list[Job]:
        """The owner's jobs, newest first, starting below ``before_seq`` (keyset paging)."""
        sql = "SELECT * FROM jobs WHERE owner = ?"
        args: list[Any] = [owner]
        if before_seq is not None:
            sql += " AND seq < ?"
            args.append(before_seq)
        if status is not None:
            sql += " AND status = ?"
            args.append(status)
        sql += " ORDER BY seq DESC LIMIT ?"
        args.append(limit)
        with self._conn() as conn:
            rows = conn.execute(sql, args).fetchall()
        return [Job.from_row(r) for r in rows]

    def count_unfinished(self, owner: str | None = None) -> int:
        """Queued and running jobs, of ``owner`` or of everyone."""
        sql = "SELECT COUNT(*) FROM jobs WHERE status IN (?, ?)"
        args: list[Any] = [QUEUED, RUNNING]
        if owner is not None:
            sql += " AND owner = ?"
            args.append(owner)
        with self._conn() as conn:
            return conn.execute(sql, args).fetchone()[0]

    def count_by_status(self) -> dict[str, int]:
        with self._conn() as conn:
            rows = conn.execute("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetchall()
        counts = dict.fromkeys(STATUSES, 0)
        counts.update({r[0]: r[1] for r in rows})
        return counts

    def next_queued(self, limit: int, exclude: set[str], *, large_bytes: int | None = None,
                    large_slots: int | None = None, window: int = 1000) -> list[str]:
        """Ids of the queued jobs to run next, not in ``exclude`` (already in the pool).

        Fair share: each pick goes to the owner with the fewest jobs running or picked, the
        oldest of that owner's jobs first, so one key's backlog does not hold up another's.
        Size classes: a job of more than ``large_bytes`` input bytes is large, and at most
        ``large_slots`` large jobs run at once, so a worker stays free for small jobs. Only
        the ``window`` oldest queued jobs are considered (plain FIFO without the options).
        """
        with self._conn() as conn:
            queued = conn.execute(
                "SELECT id, owner, input_bytes FROM jobs WHERE status = ? ORDER BY seq LIMIT ?",
                (QUEUED, window + len(exclude))).fetchall()
            running = conn.execute("SELECT id, owner, input_bytes FROM jobs WHERE status = ?",
                                   (RUNNING,)).fetchall()
        busy = {r[0]: r for r in running}
        busy.update({r[0]: r for r in queued if r[0] in exclude})
        candidates = [r for r in queued if r[0] not in exclude]
        if large_bytes is None:
            return [r[0] for r in candidates[:limit]]
        share = Counter(r[1] for r in busy.values())
        large = sum(r[2] > large_bytes for r in busy.values())
        picked: list[str] = []
        while candidates and len(picked) < limit:
            allowed = [r for r in candidates
                       if large_slots is None or r[2] <= large_bytes or large < large_slots]
            if not allowed:
                break
            fewest = min(share[r[1]] for r in allowed)
            row = next(r for r in allowed if share[r[1]] == fewest)  # oldest of that share
            candidates.remove(row)
            picked.append(row[0])
            share[row[1]] += 1
            large += row[2] > large_bytes
        return picked

    def cancel(self, job_id: str, ttl: float) -> Job | None:
        """Mark a queued or running job cancelled; the running worker notices and stops.

        Returns the updated job, or ``None`` when it was not queued or running.
        """
        now = time.time()
        with self._transaction() as conn:
            changed = conn.execute(
                "UPDATE jobs SET status = ?, finished_at = ?, expires_at = ? "
                "WHERE id = ? AND status IN (?, ?)",
                (CANCELLED, now, now + ttl, job_id, QUEUED, RUNNING)).rowcount
            row = conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return Job.from_row(row) if changed else None

    def delete(self, job_id: str) -> bool:
        with self._transaction() as conn:
            return conn.execute("DELETE FROM jobs WHERE id = ?", (job_id,)).rowcount > 0

    def requeue_after_crash(self, job_id: str, run_token: str | None, max_attempts: int,
                            error: dict, *, count_attempt: bool = True,
                            ttl: float | None = None) -> str | None:
        """The worker of a running job died: queue it again, or fail it after too many runs.

        Parameters
        ----------
        job_id, run_token : str
            The job and the run that died; a later run of the same job is left alone.
        max_attempts : int
            Runs after which the job fails with ``error`` instead.
        count_attempt : bool
            False when the run was ended on purpose for another job's sake (the pool was
            killed to stop a run past its time limit): the run is not held against this job.
        ttl : float, optional
            Retention of a job failed here.

        Returns
        -------
        str or None
            The new status, or ``None`` when this run no longer owned a running job.
        """
        with self._transaction() as conn:
            row = conn.execute("SELECT status, attempts, run_token FROM jobs WHERE id = ?",
                               (job_id,)).fetchone()
            if row is None or row["status"] != RUNNING or row["run_token"] != run_token:
                return None
            attempts = row["attempts"] - (0 if count_attempt else 1)
            if attempts >= max_attempts:
                now = time.time()
                conn.execute(
                    "UPDATE jobs SET status = ?, finished_at = ?, expires_at = ?, error = ?, "
                    "run_token = NULL WHERE id = ?",
                    (FAILED, now, None if ttl is None else now + ttl, json.dumps(error),
                     job_id))
                return FAILED
            conn.execute("UPDATE jobs SET status = ?, progress = 0, attempts = ?, "
                         "run_token = NULL WHERE id = ?", (QUEUED, attempts, job_id))
            return QUEUED

    def running(self, busy_timeout: float | None = None
                ) -> list[tuple[str, str | None, float | None]]:
        """``(id, run_token, started_at)`` of every running job; waits up to ``busy_timeout``
        seconds (default: the store's) for a lock held elsewhere."""
        with self._conn(busy_timeout) as conn:
            rows = conn.execute("SELECT id, run_token, started_at FROM jobs WHERE status = ?",
                                (RUNNING,)).fetchall()
        return [(r[0], r[1], r[2]) for r in rows]

    def expired(self, now: float) -> list[str]:
        """Ids of final jobs whose retention time has passed."""
        with self._conn() as conn:
            rows = conn.execute(
                "SELECT id FROM jobs WHERE expires_at IS NOT NULL AND expires_at <= ? "
                "AND status IN (?, ?, ?)", (now, *FINAL_STATUSES)).fetchall()
        return [r[0] for r in rows]

    def delete_expired(self, job_id: str, now: float) -> bool:
        """Delete a job only if it is still final and expired (checked in the same step)."""
        with self._transaction() as conn:
            return conn.execute(
                "DELETE FROM jobs WHERE id = ? AND expires_at IS NOT NULL AND expires_at <= ? "
                "AND status IN (?, ?, ?)", (job_id, now, *FINAL_STATUSES)).rowcount > 0

    def all_ids(self) -> set[str]:
        with self._conn() as conn:
            return {r[0] for r in conn.execute("SELECT id FROM jobs").fetchall()}

    # -- worker side -------------------------------------------------------------------------

    def claim(self, job_id: str, run_token: str, worker_pid: int | None = None) -> Job | None:
        """Move a queued job to running under ``run_token`` in process ``worker_pid``;
        ``None`` if it is not queued."""
        with self._transaction() as conn:
            changed = conn.execute(
                "UPDATE jobs SET status = ?, started_at = ?, progress = 0, "
                "attempts = attempts + 1, run_token = ?, worker_pid = ? "
                "WHERE id = ? AND status = ?",
                (RUNNING, time.time(), run_token, worker_pid, job_id, QUEUED)).rowcount
            row = conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return Job.from_row(row) if changed else None

    def report_progress(self, job_id: str, run_token: str, progress: float) -> bool:
        """Store progress; False when this run no longer owns the job (cancelled, re-queued)."""
        with self._conn() as conn:
            changed = conn.execute(
                "UPDATE jobs SET progress = ? WHERE id = ? AND run_token = ? AND status = ?",
                (float(progress), job_id, run_token, RUNNING)).rowcount
        return changed > 0

    def set_points(self, job_id: str, run_token: str, n_points: int) -> None:
        with self._conn() as conn:
            conn.execute("UPDATE jobs SET n_points = ? WHERE id = ? AND run_token = ?",
                         (n_points, job_id, run_token))

    def finish(self, job_id: str, run_token: str, *, status: str, ttl: float,
               error: dict | None = None, summary: dict | None = None,
               result_sha256: str | None = None) -> bool:
        """Record the outcome of a run (with the digest of its canonical result file);
        False when the run no longer owns the job."""
        now = time.time()
        with self._transaction() as conn:
            changed = conn.execute(
                "UPDATE jobs SET status = ?, progress = CASE WHEN ? THEN 1.0 ELSE progress END, "
                "finished_at = ?, expires_at = ?, error = ?, summary = ?, result_sha256 = ?, "
                "checksums = NULL WHERE id = ? AND run_token = ? AND status = ?",
                (status, status == SUCCEEDED, now, now + ttl,
                 None if error is None else json.dumps(error),
                 None if summary is None else json.dumps(summary), result_sha256,
                 job_id, run_token, RUNNING)).rowcount
        return changed > 0

    def set_checksum(self, job_id: str, fmt: str, digest: str) -> None:
        """Record the digest of a rendered result file of a succeeded job."""
        with self._transaction() as conn:
            row = conn.execute("SELECT checksums FROM jobs WHERE id = ? AND status = ?",
                               (job_id, SUCCEEDED)).fetchone()
            if row is None:
                return
            checksums = json.loads(row[0]) if row[0] else {}
            checksums[fmt] = digest
            conn.execute("UPDATE jobs SET checksums = ? WHERE id = ?",
                         (json.dumps(checksums), job_id))

    def fail_lost(self, job_id: str, error: dict) -> bool:
        """Mark a succeeded job failed with ``error``: its result and input are both lost."""
        with self._transaction() as conn:
            return conn.execute("UPDATE jobs SET status = ?, error = ?, summary = NULL "
                                "WHERE id = ? AND status = ?",
                                (FAILED, json.dumps(error), job_id, SUCCEEDED)).rowcount > 0

    def requeue_for_recompute(self, job_id: str) -> bool:
        """Put a succeeded job whose result was lost back in the queue (its input is kept).

        Its attempts start over: the loss was the storage's fault, not the job's.
        """
        with self._transaction() as conn:
            return conn.execute(
                "UPDATE jobs SET status = ?, progress = 0, finished_at = NULL, "
                "expires_at = NULL, summary = NULL, result_sha256 = NULL, checksums = NULL, "
                "attempts = 0, run_token = NULL WHERE id = ? AND status = ?",
                (QUEUED, job_id, SUCCEEDED)).rowcount > 0
