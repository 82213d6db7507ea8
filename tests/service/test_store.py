"""The SQLite job store: WAL, recovery after a crash, fencing of stale runs, expiry."""

from __future__ import annotations

import sqlite3
import time

import pytest
from service_helpers import make_settings

from service.cleanup import sweep
from service.store import JobStore, new_job_id

ERROR = {"type": "/problems/worker-crashed", "title": "t", "status": 500, "detail": "d"}


@pytest.fixture
def store(tmp_path) -> JobStore:
    s = JobStore(tmp_path / "jobs.sqlite3")
    s.initialize()
    return s


def add(store: JobStore, owner: str = "me") -> str:
    job_id = new_job_id()
    store.insert(job_id=job_id, owner=owner, params={"method": "knn"}, input_kind="arrays",
                 input_file="input.npz", input_name=None, input_format="json",
                 input_bytes=10, n_points=20)
    return job_id


def test_wal_mode_and_schema(store):
    conn = sqlite3.connect(store.db_path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 2
    conn.close()


def test_a_version_1_store_gets_the_new_columns(tmp_path):
    import service.store as store_module

    path = tmp_path / "old.sqlite3"
    conn = sqlite3.connect(path)
    old_schema = store_module._SCHEMA.split("    restarts INTEGER")[0].rstrip().rstrip(",")
    conn.executescript(old_schema + "\n);")
    conn.execute("INSERT INTO jobs (id, owner, status, params, input_kind, input_file, "
                 "input_bytes, created_at) VALUES ('j', 'o', 'queued', '{}', 'arrays', "
                 "'input.npz', 1, 0)")
    conn.commit()
    conn.close()
    old = JobStore(path)
    old.initialize()
    job = old.get("j")
    assert job.restarts == 0 and job.result_sha256 is None and job.checksums is None


def test_insert_is_durable_and_queued(store):
    job_id = add(store)
    again = JobStore(store.db_path).get(job_id)  # a fresh connection sees the commit
    assert again.status == "queued" and again.attempts == 0 and again.params == {
        "method": "knn"}


def test_claim_progress_finish(store):
    job_id = add(store)
    job = store.claim(job_id, "run-1")
    assert job.status == "running" and job.attempts == 1
    assert store.claim(job_id, "run-2") is None  # only queued jobs can be claimed
    assert store.report_progress(job_id, "run-1", 0.5)
    assert store.finish(job_id, "run-1", status="succeeded", ttl=60, summary={"a": 1})
    job = store.get(job_id)
    assert job.status == "succeeded" and job.progress == 1.0 and job.summary == {"a": 1}
    assert job.expires_at == pytest.approx(job.finished_at + 60)


def test_restart_requeues_running_jobs_and_fences_the_old_run(store):
    job_id = add(store)
    store.claim(job_id, "old-run")
    assert store.requeue_interrupted(max_restarts=3, error=ERROR) == (1, 0)
    assert store.get(job_id).status == "queued"
    # The orphaned old run can no longer write anything.
    assert not store.report_progress(job_id, "old-run", 0.9)
    assert not store.finish(job_id, "old-run", status="succeeded", ttl=60)
    # The restart is counted apart: it is not an attempt of the job.
    job = store.claim(job_id, "new-run")
    assert job.attempts == 1 and job.restarts == 1


def test_job_interrupted_by_too_many_restarts_is_not_requeued_forever(store):
    job_id = add(store)
    for attempt in range(3):
        store.claim(job_id, f"run-{attempt}")
        store.requeue_interrupted(max_restarts=3, error=ERROR)
    job = store.get(job_id)
    assert job.status == "failed" and job.error == ERROR
    assert job.restarts == 3 and job.attempts == 0


def test_requeue_after_worker_crash(store):
    job_id = add(store)
    store.claim(job_id, "r1")
    assert store.requeue_after_crash(job_id, "r1", max_attempts=2, error=ERROR) == "queued"
    store.claim(job_id, "r2")
    # A stale report of the first run changes nothing.
    assert store.requeue_after_crash(job_id, "r1", max_attempts=2, error=ERROR) is None
    assert store.requeue_after_crash(job_id, "r2", max_attempts=2, error=ERROR,
                                     ttl=60) == "failed"
    assert store.get(job_id).expires_at is not None  # failed jobs expire like others
    assert store.requeue_after_crash(job_id, "r2", max_attempts=2, error=ERROR) is None


def test_run_stopped_on_purpose_is_not_counted(store):
    job_id = add(store)
    for run in ("r1", "r2", "r3"):  # e.g. the pool killed three times for other jobs
        store.claim(job_id, run)
        assert store.requeue_after_crash(job_id, run, max_attempts=2, error=ERROR,
                                         count_attempt=False) == "queued"
    assert store.get(job_id).attempts == 0


def test_cancel_only_unfinished(store):
    job_id = add(store)
    assert store.cancel(job_id, ttl=10).status == "cancelled"
    assert store.cancel(job_id, ttl=10) is None
    assert store.claim(job_id, "r") is None


def test_next_queued_is_fifo_and_skips_handed_out(store):
    ids = [add(store) for _ in range(4)]
    assert store.next_queued(2, set()) == ids[:2]
    assert store.next_queued(2, {ids[0]}) == ids[1:3]


def test_sweep_removes_expired_jobs_and_orphans(tmp_path):
    settings = make_settings(tmp_path)
    store = JobStore(settings.db_path)
    store.initialize()
    keep, expire = add(store), add(store)
    for job_id in (keep, expire):
        (settings.jobs_dir / job_id).mkdir(parents=True)
        store.claim(job_id, "r")
    store.finish(keep, "r", status="succeeded", ttl=3600)
    store.finish(expire, "r", status="succeeded", ttl=1)
    orphan = settings.jobs_dir / "orphan"
    orphan.mkdir()
    assert sweep(settings, store, now=time.time() + 10) == 1
    assert store.get(expire) is None and not (settings.jobs_dir / expire).exists()
    assert store.get(keep) is not None and (settings.jobs_dir / keep).exists()
    assert orphan.exists()  # too young to be called abandoned
    sweep(settings, store, now=time.time() + 7200)
    assert not orphan.exists()
