"""Limits, each with a clear problem: jobs per key, queue length, points, parameters, time per
job, result expiry; and a full disk, which fails the request or job and corrupts nothing."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import signal
import sqlite3
import threading
import time

import numpy as np
import pytest
from service_helpers import (
    KEY_A,
    KEY_B,
    bearer,
    changed_executor,
    changed_settings,
    make_settings,
    sphere,
    wait_for_job,
)

from service import result_files, uploads, worker
from service.cleanup import sweep
from service.storage_errors import storage_problem
from service.store import JobStore, QueueLimitError, new_job_id

PROBLEM = "application/problem+json"
NO_SPACE = OSError(errno.ENOSPC, "No space left on device")


def assert_problem(response, status: int, slug: str) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    body = response.json()
    assert body["type"] == f"/problems/{slug}" and body["status"] == status
    assert "Traceback" not in response.text
    return body


def npy_upload(client, n: int, seed: int = 7, headers=None):
    buffer = io.BytesIO()
    np.save(buffer, np.random.default_rng(seed).normal(size=(n, 3)))
    return client.post("/v1/jobs", files={"file": ("cloud.npy", buffer.getvalue())},
                       data={"params": json.dumps({"method": "knn", "k": 5})},
                       headers=headers or {})


def job_rows(client) -> int:
    conn = sqlite3.connect(client.app.state.settings.db_path)
    try:
        return conn.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
    finally:
        conn.close()


def job_folders(client) -> set[str]:
    return {p.name for p in client.app.state.settings.jobs_dir.iterdir()}


# -- queue limits ------------------------------------------------------------------------------

def test_jobs_per_key_limit_is_429_and_spares_other_keys(client):
    store = client.app.state.store
    # Key B gets one more unfinished job than key A may have; the limit is per key.
    key_a = client.app.state.keyring.owner_of(KEY_A)
    key_b = client.app.state.keyring.owner_of(KEY_B)
    npy_upload(client, 300_000, headers=bearer(KEY_B))  # stays unfinished for a while
    mine = store.count_unfinished(key_b)
    assert mine > store.count_unfinished(key_a)
    with changed_settings(client, max_jobs_per_key=mine, retry_after_seconds=3):
        rows, folders = job_rows(client), job_folders(client)
        response = client.post("/v1/jobs", json={"points": sphere(30).tolist()},
                               headers=bearer(KEY_B))
        body = assert_problem(response, 429, "too-many-jobs")
        assert response.headers["retry-after"] == "3"
        assert "CURVATURE_MAX_JOBS_PER_KEY" in body["detail"]
        assert (job_rows(client), job_folders(client)) == (rows, folders)  # nothing stored
        # Key A has fewer unfinished jobs, so the same limit does not stop it.
        assert client.post("/v1/jobs", json={"points": sphere(30).tolist()}).status_code == 202
    for job in client.get("/v1/jobs", headers=bearer(KEY_B)).json()["items"]:
        if job["status"] in ("queued", "running"):
            client.delete(f"/v1/jobs/{job['id']}", headers=bearer(KEY_B))


def test_limits_hold_under_concurrent_submissions(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite3")
    store.initialize()
    accepted, refused = [], []

    def submit(owner):
        try:
            store.insert(job_id=new_job_id(), owner=owner, params={}, input_kind="arrays",
                         input_file="input.npz", input_name=None, input_format="json",
                         input_bytes=1, n_points=10, max_unfinished=7, max_owner_unfinished=5)
            accepted.append(owner)
        except QueueLimitError as exc:
            refused.append(exc.scope)

    threads = [threading.Thread(target=submit, args=(owner,))
               for owner in ["a"] * 20 + ["b"] * 20]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    # The checks run inside the insert's write transaction: no overshoot, whatever the timing.
    assert store.count_unfinished() == len(accepted) == 7
    assert store.count_unfinished("a") <= 5 and store.count_unfinished("b") <= 5
    assert len(refused) == 33 and set(refused) <= {"owner", "total"}


def test_refused_in_the_insert_leaves_no_files(client, monkeypatch):
    store = client.app.state.store

    def full(**kwargs):
        raise QueueLimitError("total", 5, 5)

    monkeypatch.setattr(store, "insert", full)
    folders = job_folders(client)
    response = client.post("/v1/jobs", json={"points": sphere(30).tolist()})
    assert_problem(response, 503, "queue-full")
    assert response.headers["retry-after"]
    assert job_folders(client) == folders


# -- size limits -------------------------------------------------------------------------------

def test_point_limit_for_json_is_413_at_once(client):
    with changed_settings(client, max_points=100):
        body = assert_problem(client.post("/v1/jobs", json={"points": sphere(101).tolist()}),
                              413, "cloud-too-large")
        assert "101 points" in body["detail"] and "100" in body["detail"]


def test_point_limit_for_files_fails_the_job(client, mesh_ply):
    with changed_executor(client, max_points=100):
        with open(mesh_ply, "rb") as fh:
            response = client.post("/v1/jobs", files={"file": ("bump.ply", fh)})
        job = wait_for_job(client, response.json()["id"])
    assert job["status"] == "failed"
    assert job["error"]["type"] == "/problems/cloud-too-large"
    assert "120 points" in job["error"]["detail"]


@pytest.mark.parametrize("raw", [
    '{"method": "knn", "k": 1' + "0" * 5000 + "}",       # longer than Python reads as int
    '{"method": "knn", "k": 1e999}',                       # infinite
    '{"method": "knn", "k": -9223372036854775809}',        # below int64
    '{"method": "knn", "viewpoint": [1e308, 1e309, 0]}',  # overflows to inf
    '{"method": "knn", "fit": "monge", "k": 1024.5}',
])
def test_out_of_bounds_parameters_are_422(client, raw):
    body = '{"points": ' + json.dumps(sphere(20).tolist()) + ', "params": ' + raw + "}"
    response = client.post("/v1/jobs", content=body, headers={"Content-Type": "application/json"})
    assert response.status_code in (400, 422), response.text
    assert response.headers["content-type"] == PROBLEM


# -- time limit --------------------------------------------------------------------------------

def test_time_limit_stops_a_run_cleanly(client):
    """A run past its limit fails itself at its next progress report; the pool survives."""
    pids = client.app.state.executor.worker_pids()
    with changed_executor(client, job_time_limit_seconds=0.3, time_limit_grace_seconds=60):
        job = npy_upload(client, 300_000).json()
        job = wait_for_job(client, job["id"], timeout=60)
    assert job["status"] == "failed", job
    assert job["error"]["type"] == "/problems/time-limit"
    assert "0.3 s" in job["error"]["detail"]
    assert job["attempts"] == 1
    assert client.app.state.executor.worker_pids() == pids
    assert not (client.app.state.settings.jobs_dir / job["id"] / "result.npz").exists()


def test_time_limit_kills_a_run_that_does_not_stop(client):
    """A worker that never reaches a progress report (here: stopped with SIGSTOP) is killed
    with its pool once past limit + grace; the job fails with the reason, a new pool serves."""
    executor = client.app.state.executor
    with changed_executor(client, job_time_limit_seconds=1.0, time_limit_grace_seconds=0.5):
        job = npy_upload(client, 300_000).json()
        wait_for_job(client, job["id"], until=("running",))
        old = executor.worker_pids()
        for pid in old:
            os.kill(pid, signal.SIGSTOP)
        try:
            job = wait_for_job(client, job["id"], timeout=30)
        finally:
            for pid in old:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGCONT)
    assert job["status"] == "failed", job
    assert job["error"]["type"] == "/problems/time-limit"
    assert not set(old) & set(executor.worker_pids())
    follow_up = client.post("/v1/jobs", json={"points": sphere(100).tolist()}).json()
    assert wait_for_job(client, follow_up["id"])["status"] == "succeeded"


def test_time_limit_ends_a_wedged_run_while_the_store_is_locked(client, monkeypatch):
    """A worker stopped in the middle of a commit can leave the store unreadable until it is
    gone; the watchdog must not wait for the store to end it (it would wait forever)."""
    executor = client.app.state.executor
    with changed_executor(client, job_time_limit_seconds=1.0, time_limit_grace_seconds=0.5):
        job_id = npy_upload(client, 300_000).json()["id"]
        wait_for_job(client, job_id, until=("running",))
        deadline = time.monotonic() + 30
        while getattr(executor._in_flight.get(job_id), "started_at", None) is None:
            assert time.monotonic() < deadline, "the watchdog never read the run's start"
            time.sleep(0.05)  # the watchdog reads the running jobs every 0.2 s
        old = executor.worker_pids()
        for pid in old:
            os.kill(pid, signal.SIGSTOP)

        def locked(*args, **kwargs):
            raise sqlite3.OperationalError("database is locked")

        monkeypatch.setattr(executor.store, "running", locked)
        try:
            job = wait_for_job(client, job_id, timeout=30)
        finally:
            for pid in old:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGCONT)
    assert job["status"] == "failed", job
    assert job["error"]["type"] == "/problems/time-limit"
    assert not set(old) & set(executor.worker_pids())


# -- expiry and cleanup ------------------------------------------------------------------------

def add_job(store: JobStore, settings, status: str, ttl: float | None = None) -> str:
    job_id = new_job_id()
    store.insert(job_id=job_id, owner="me", params={"method": "knn"}, input_kind="arrays",
                 input_file="input.npz", input_name=None, input_format="json", input_bytes=1,
                 n_points=20)
    (settings.jobs_dir / job_id).mkdir(parents=True)
    (settings.jobs_dir / job_id / "input.npz").write_bytes(b"x")
    if status != "queued":
        store.claim(job_id, "run")
    if status in ("succeeded", "failed"):
        store.finish(job_id, "run", status=status, ttl=ttl)
    if status == "cancelled":
        store.cancel(job_id, ttl=ttl)
    return job_id


def test_cleanup_never_removes_files_in_use(tmp_path):
    settings = make_settings(tmp_path)
    store = JobStore(settings.db_path)
    store.initialize()
    later = time.time() + 10 * 24 * 3600
    running = add_job(store, settings, "running")
    queued = add_job(store, settings, "queued")
    expired = add_job(store, settings, "succeeded", ttl=1)
    # Cancelled while running: final and expired in the store, but its worker may still write.
    stopping = add_job(store, settings, "cancelled", ttl=1)
    uploading = settings.jobs_dir / "upload-in-progress"
    uploading.mkdir()
    old = time.time() - 7200
    for folder in settings.jobs_dir.iterdir():
        os.utime(folder, (old, old))
    assert sweep(settings, store, now=later, busy={stopping, uploading.name}) == 1
    for job_id in (running, queued, stopping):
        assert store.get(job_id) is not None and (settings.jobs_dir / job_id).exists()
    assert uploading.exists()
    assert store.get(expired) is None and not (settings.jobs_dir / expired).exists()
    # Once out of the pool, the cancelled job goes too; the abandoned upload folder as well.
    assert sweep(settings, store, now=later) == 1
    assert store.get(stopping) is None and not uploading.exists()
    assert (settings.jobs_dir / running).exists()


def test_expired_jobs_disappear_through_the_api(client):
    job = wait_for_job(client, client.post("/v1/jobs",
                                           json={"points": sphere(50).tolist()}).json()["id"])
    settings = client.app.state.settings
    sweep(settings, client.app.state.store, now=time.time() + settings.result_ttl_seconds + 1,
          busy=client.app.state.executor.busy_ids())
    assert_problem(client.get(f"/v1/jobs/{job['id']}"), 404, "job-not-found")
    assert not (settings.jobs_dir / job["id"]).exists()


# -- full disk ---------------------------------------------------------------------------------

class FillingFile:
    """A file whose disk fills after ``budget`` bytes: the write that does not fit stores
    what fits, then raises ENOSPC, as a real full disk does."""

    def __init__(self, real, budget: int):
        self.real, self.budget = real, budget

    def write(self, data) -> int:
        data = bytes(data)
        if len(data) > self.budget:
            self.real.write(data[:self.budget])
            self.budget = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self.budget -= len(data)
        return self.real.write(data)

    def __getattr__(self, name):
        return getattr(self.real, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.real.close()


def disk_filling_open(budget: int):
    def fake_open(path, mode="r", *args, **kwargs):
        real = open(path, mode, *args, **kwargs)
        return FillingFile(real, budget) if "w" in mode else real
    return fake_open


@pytest.mark.parametrize("kind", ["multipart", "json"])
def test_full_disk_during_an_upload_is_507_and_stores_nothing(client, monkeypatch, kind):
    monkeypatch.setattr(uploads, "open", disk_filling_open(1000), raising=False)
    rows, folders = job_rows(client), job_folders(client)
    if kind == "multipart":
        response = npy_upload(client, 2000)
    else:
        response = client.post("/v1/jobs", json={"points": sphere(300).tolist()})
    body = assert_problem(response, 507, "insufficient-storage")
    assert "no space left" in body["detail"]
    assert (job_rows(client), job_folders(client)) == (rows, folders)
    monkeypatch.undo()  # space again: the same request goes through
    assert client.post("/v1/jobs", json={"points": sphere(300).tolist()}).status_code == 202


def test_full_job_store_is_507_and_removes_the_upload(client, monkeypatch):
    def full(**kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(client.app.state.store, "insert", full)
    folders = job_folders(client)
    body = assert_problem(client.post("/v1/jobs", json={"points": sphere(30).tolist()}),
                          507, "insufficient-storage")
    assert "job store" in body["detail"]
    assert job_folders(client) == folders


class FullStore(JobStore):
    """A store whose database file may not grow: SQLite itself answers SQLITE_FULL."""

    @contextlib.contextmanager
    def _conn(self):
        with super()._conn() as conn:
            pages = conn.execute("PRAGMA page_count").fetchone()[0]
            conn.execute(f"PRAGMA max_page_count = {pages}")
            yield conn


def test_real_sqlite_full_changes_nothing(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite3")
    store.initialize()
    kept = add_job(store, make_settings(tmp_path), "queued")
    full = FullStore(store.db_path)
    before = store.all_ids()
    with pytest.raises(sqlite3.OperationalError) as info:
        for _ in range(200):  # the first inserts may still fit in free pages
            full.insert(job_id=new_job_id(), owner="me", params={"pad": "x" * 4000},
                        input_kind="arrays", input_file="input.npz", input_name=None,
                        input_format="json", input_bytes=1, n_points=20)
    assert storage_problem(info.value, "testing").slug == "insufficient-storage"
    assert before <= store.all_ids()
    conn = sqlite3.connect(store.db_path)
    assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    conn.close()
    assert store.get(kept).status == "queued"


def test_full_disk_while_writing_a_result_fails_the_job_cleanly(tmp_path, monkeypatch):
    settings = make_settings(tmp_path)
    store = JobStore(settings.db_path)
    store.initialize()
    job_id = new_job_id()
    folder = settings.jobs_dir / job_id
    folder.mkdir(parents=True)
    np.savez(folder / "input.npz", points=sphere(200))
    store.insert(job_id=job_id, owner="me", params={"method": "knn", "k": 10},
                 input_kind="arrays", input_file="input.npz", input_name=None,
                 input_format="json", input_bytes=1, n_points=200)
    monkeypatch.setattr(result_files, "open", disk_filling_open(5000), raising=False)
    options = {"estimate_workers": 1, "progress_interval": 0.05, "result_ttl": 60}
    status = worker.run_job(str(settings.db_path), str(settings.jobs_dir), job_id, "run", options)
    assert status == "failed"
    job = store.get(job_id)
    assert job.status == "failed" and job.error["type"] == "/problems/insufficient-storage"
    assert "while running the job" in job.error["detail"]
    # No partial result (nor its temporary file) is left; the input is intact for a retry.
    assert sorted(p.name for p in folder.iterdir()) == ["input.npz"]
    with np.load(folder / "input.npz") as data:
        assert data["points"].shape == (200, 3)


def test_full_disk_while_rendering_a_result_is_507(client, monkeypatch):
    job = wait_for_job(client, client.post("/v1/jobs",
                                           json={"points": sphere(60).tolist()}).json()["id"])

    async def no_space(*args):
        raise NO_SPACE

    monkeypatch.setattr(client.app.state.executor, "render", no_space)
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result?format=csv"), 507,
                   "insufficient-storage")
    monkeypatch.undo()
    assert client.get(f"/v1/jobs/{job['id']}").json()["status"] == "succeeded"
    assert client.get(f"/v1/jobs/{job['id']}/result?format=csv").status_code == 200
