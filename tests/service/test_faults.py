"""Faults: a worker killed mid-job, a job whose outcome was lost, the server killed during an
upload, and a locked (busy) SQLite store. Every accepted job still reaches a final state."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import threading
import time

import httpx
import numpy as np
import pytest
from service_helpers import (
    KEY_A,
    KEYS,
    ServerProcess,
    changed_executor,
    sphere,
    wait_for_job,
)
from test_limits import assert_problem, job_folders, job_rows, npy_upload

from service.store import JobStore
from service.worker import ProgressReporter


@pytest.fixture
def write_lock(client):
    """Hold the store's write lock from another connection, as a busy writer would."""
    holders = []

    def take():
        conn = sqlite3.connect(client.app.state.settings.db_path, isolation_level=None)
        conn.execute("BEGIN IMMEDIATE")
        holders.append(conn)
        return conn

    yield take
    for conn in holders:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        conn.close()


# -- worker processes --------------------------------------------------------------------------

def test_worker_killed_too_often_fails_the_job_with_the_reason(client):
    """With one attempt allowed, a killed worker fails the job (never stuck running), the
    pool is rebuilt, and the next job runs."""
    executor = client.app.state.executor
    with changed_executor(client, max_attempts=1):
        job = npy_upload(client, 200_000).json()
        wait_for_job(client, job["id"], until=("running",))
        old = executor.worker_pids()
        for pid in old:
            os.kill(pid, signal.SIGKILL)
        job = wait_for_job(client, job["id"], timeout=60)
    assert job["status"] == "failed", job
    assert job["error"]["type"] == "/problems/worker-crashed"
    assert "worker process died" in job["error"]["detail"]
    assert job["expires_at"] is not None  # cleaned up like any finished job
    assert set(executor.worker_pids()).isdisjoint(old)
    again = client.post("/v1/jobs", json={"points": sphere(100).tolist()}).json()
    assert wait_for_job(client, again["id"])["status"] == "succeeded"


def test_running_job_without_a_run_is_requeued_by_the_watchdog(client):
    """A row left 'running' whose run is gone (its outcome could not be written) does not
    stay running: the watchdog queues it again and it completes."""
    settings = client.app.state.settings
    store = client.app.state.store
    job = client.post("/v1/jobs", json={"points": sphere(80).tolist()}).json()
    job = wait_for_job(client, job["id"])
    # Make it look like a run that died after claiming it: running, a token no run holds.
    folder = settings.jobs_dir / job["id"]
    np.savez(folder / "input.npz", points=sphere(80))
    conn = sqlite3.connect(settings.db_path, isolation_level=None)
    conn.execute("UPDATE jobs SET status = 'running', run_token = 'lost-run', progress = 0.4, "
                 "finished_at = NULL, expires_at = NULL WHERE id = ?", (job["id"],))
    conn.close()
    assert store.get(job["id"]).status == "running"
    final = wait_for_job(client, job["id"], timeout=30)
    assert final["status"] == "succeeded"
    assert final["attempts"] == 2


# -- a busy store ------------------------------------------------------------------------------

@pytest.fixture
def impatient_store(client):
    """The app's store with a busy timeout of 0.3 s (Starlette's State defeats monkeypatch)."""
    original = client.app.state.store
    client.app.state.store = JobStore(original.db_path, busy_timeout=0.3)
    yield
    client.app.state.store = original


def test_busy_store_answers_503_and_changes_nothing(client, write_lock, impatient_store):
    settings = client.app.state.settings
    done = wait_for_job(client, client.post(
        "/v1/jobs", json={"points": sphere(50).tolist()}).json()["id"])
    lock = write_lock()
    rows, folders = job_rows(client), job_folders(client)
    response = client.post("/v1/jobs", json={"points": sphere(30).tolist()})
    body = assert_problem(response, 503, "store-busy")
    assert response.headers["retry-after"] == str(settings.retry_after_seconds)
    assert "nothing was changed" in body["detail"]
    assert job_folders(client) == folders  # the stored upload was removed again
    # Readers are not blocked (WAL): status and results still answer during the lock.
    assert client.get(f"/v1/jobs/{done['id']}").json()["status"] == "succeeded"
    assert client.get(f"/v1/jobs/{done['id']}/result?format=npz").status_code == 200
    lock.execute("ROLLBACK")
    assert job_rows(client) == rows
    assert client.post("/v1/jobs", json={"points": sphere(30).tolist()}).status_code == 202


def test_jobs_ride_out_a_store_locked_for_a_while(client, write_lock):
    """Workers wait for a lock (up to the busy timeout) instead of failing the job."""
    response = npy_upload(client, 200_000)
    assert response.status_code == 202, response.text
    job = wait_for_job(client, response.json()["id"], until=("running",))
    lock = write_lock()
    time.sleep(1.5)
    lock.execute("ROLLBACK")
    final = wait_for_job(client, job["id"], timeout=120)
    assert final["status"] == "succeeded" and final["attempts"] == 1


def test_progress_report_skips_a_busy_store(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite3", busy_timeout=0.1)
    store.initialize()
    holder = sqlite3.connect(store.db_path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    try:
        reporter = ProgressReporter(store, "job", "run", interval=0.0)
        reporter(0.5, force=True)  # no exception: progress is advisory
        assert not reporter.aborted
    finally:
        holder.execute("ROLLBACK")
        holder.close()


# -- the server killed during an upload --------------------------------------------------------

def test_server_killed_during_an_upload_loses_no_accepted_job(tmp_path):
    data_dir = tmp_path / "data"
    log = tmp_path / "server.log"
    first = ServerProcess(data_dir, log, api_key=KEY_A, api_keys=KEYS).start()
    accepted = [first.client.post("/v1/jobs", json={"points": sphere(200, seed=i).tolist()})
                .json()["id"] for i in range(3)]
    release = threading.Event()
    outcome = {}

    def body():
        yield (b'--b0\r\nContent-Disposition: form-data; name="file"; filename="scan.xyz"'
               b"\r\n\r\n" + b"1.0 2.0 3.0\n" * 1000)
        release.wait(30)
        yield b"4.0 5.0 6.0\n" * 1000

    def upload():
        try:
            with httpx.Client(base_url=first.url, headers=first.headers, timeout=30) as c:
                outcome["response"] = c.post("/v1/jobs", content=body(), headers={
                    "Content-Type": "multipart/form-data; boundary=b0"})
        except httpx.HTTPError as exc:
            outcome["error"] = exc

    thread = threading.Thread(target=upload)
    thread.start()
    deadline = time.monotonic() + 30
    while not list((data_dir / "jobs").glob("*/.upload.part")):
        assert time.monotonic() < deadline, "the upload never started"
        time.sleep(0.05)
    partial = list((data_dir / "jobs").glob("*/.upload.part"))[0].parent
    first.kill()
    release.set()
    thread.join(30)
    assert "response" not in outcome, outcome  # the client was never told 'accepted'
    assert partial.exists()  # what the dead server left behind

    second = ServerProcess(data_dir, log, api_key=KEY_A, api_keys=KEYS).start()
    try:
        assert not partial.exists()  # removed at startup: it has no job row
        listed = second.client.get("/v1/jobs", params={"limit": 200}).json()["items"]
        assert sorted(j["id"] for j in listed) == sorted(accepted)
        for job_id in accepted:
            assert wait_for_job(second.client, job_id, timeout=120)["status"] == "succeeded"
        # The service takes uploads as before.
        response = second.client.post(
            "/v1/jobs", files={"file": ("scan.xyz", "\n".join(
                " ".join(map(str, p)) for p in sphere(100).tolist()).encode())},
            data={"params": json.dumps({"method": "knn", "k": 8})})
        assert response.status_code == 202
        assert wait_for_job(second.client, response.json()["id"])["status"] == "succeeded"
    finally:
        second.stop()
