"""Abuse and fault cases of issue 18, one test per finding (kept fast: seconds each).

Each test fails on the service as it was before the issue: sync requests without a time
limit, a pool-wide crash charging every job, restarts counted as attempts, a read-only store
answering 500, unchecked result files, bombs in NPY/NPZ members, keys in access logs.
"""

from __future__ import annotations

import time

import httpx
import numpy as np
import pytest
from service_helpers import KEY_A, ServerProcess, changed_executor, changed_settings, sphere
from test_limits import assert_problem

# EGG with 1000 candidates: inside the schema's bounds, minutes of work on a few thousand
# points (every candidate is tested against every nearer one, at 14 alpha levels).
EXPLOSIVE_EGG = {"method": "egg", "candidates": 1000}


def _metric(text: str, name: str, **labels: str) -> float:
    want = ",".join(f'{k}="{v}"' for k, v in sorted(labels.items()))
    for line in text.splitlines():
        if line.startswith(f"{name}{{{want}}} ") or (not labels and line.startswith(name + " ")):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


# -- finding 1: synchronous requests are bounded ----------------------------------------------

def test_sync_explosive_parameters_are_refused_before_any_work(client):
    body = {"points": sphere(2000).tolist(), "params": EXPLOSIVE_EGG}
    problem = assert_problem(client.post("/v1/curvature", json=body), 413, "too-costly")
    assert "candidates" in problem["detail"] and "POST /v1/jobs" in problem["detail"]
    # The same request as a job is accepted (jobs have their own time limit).
    job = client.post("/v1/jobs", json=body)
    assert job.status_code == 202
    client.delete(f"/v1/jobs/{job.json()['id']}")


def test_sync_past_its_time_limit_is_killed_and_the_lane_recovers(client):
    lane = client.app.state.executor.sync_lane
    before = set(lane.pids())
    body = {"points": sphere(3000).tolist(), "params": EXPLOSIVE_EGG}
    with changed_settings(client, sync_max_cost=1e18), \
            changed_executor(client, sync_time_limit_seconds=1.0):
        problem = assert_problem(client.post("/v1/curvature", json=body), 422, "time-limit")
    assert "CURVATURE_SYNC_TIME_LIMIT_SECONDS" in problem["detail"]
    assert before.isdisjoint(lane.pids()) or not before  # the slot's process was replaced
    small = client.post("/v1/curvature", json={"points": sphere(200).tolist()})
    assert small.status_code == 200, small.text
    assert _metric(client.get("/metrics").text, "curvature_sync_stopped_total",
                   reason="time-limit") >= 1


def test_sync_request_is_killed_when_its_client_hangs_up(tmp_path):
    server = ServerProcess(tmp_path / "data", tmp_path / "server.log", api_key=KEY_A,
                           api_keys=KEY_A, sync_max_cost=1e18, warmup="false").start()
    try:
        body = {"points": sphere(3000).tolist(), "params": EXPLOSIVE_EGG}
        with pytest.raises(httpx.ReadTimeout):
            server.client.post("/v1/curvature", json=body, timeout=2.0)
        deadline = time.monotonic() + 30
        while _metric(server.client.get("/metrics").text, "curvature_sync_stopped_total",
                      reason="disconnect") < 1:
            assert time.monotonic() < deadline, server.log()
            time.sleep(0.2)
        # The lane answers the next request (its slot was replaced, not left computing).
        small = server.client.post("/v1/curvature", json={"points": sphere(200).tolist()})
        assert small.status_code == 200, small.text
    finally:
        server.stop()


def test_sync_cost_grows_with_candidates_and_rounds():
    from service.sync_cost import cost_per_point

    base = {"method": "tc", "candidates": 30, "beta_min": 1.0, "beta_max": 2.0,
            "beta_step": 0.1, "min_neighbors": 10}
    assert cost_per_point({**base, "candidates": 60}) == 4 * cost_per_point(base)
    assert cost_per_point({**base, "min_neighbors": 60}) == 5 * cost_per_point(base)
    egg = {"method": "egg", "candidates": 30, "alpha_start": 0.7, "alpha_step": 0.05,
           "min_neighbors": 10}
    assert cost_per_point(egg) == 900 * 14
    assert np.isclose(cost_per_point({**egg, "alpha_step": 0.001}), 900 * 700)


# -- finding 2: a dying worker charges only its own job -----------------------------------------

def _running_pid(client, job_id: str, not_pid: int | None = None, timeout: float = 60.0) -> int:
    """The worker pid of a job once it runs (in a process other than ``not_pid``)."""
    store = client.app.state.store
    deadline = time.monotonic() + timeout
    while True:
        job = store.get(job_id)
        if job.status == "running" and job.worker_pid not in (None, not_pid):
            return job.worker_pid
        assert time.monotonic() < deadline, f"job {job_id} not running: {job.status}"
        time.sleep(0.02)


def test_killed_worker_charges_and_quarantines_only_its_own_job(client):
    import os
    import signal

    from service_helpers import wait_for_job
    from test_limits import npy_upload

    # Both jobs are large: the small-job lane is switched off so that both run at once.
    with changed_executor(client, max_attempts=2, small_job_workers=0):
        victim = npy_upload(client, 400_000, seed=1).json()["id"]
        bystander = npy_upload(client, 400_000, seed=2).json()["id"]
        pid = None
        for _ in range(2):
            pid = _running_pid(client, victim, not_pid=pid)
            _running_pid(client, bystander)
            os.kill(pid, signal.SIGKILL)
            time.sleep(0.5)  # let the executor see the crash before looking again
            if client.app.state.store.get(victim).status == "failed":
                break
        failed = wait_for_job(client, victim, timeout=60)
        survived = wait_for_job(client, bystander, timeout=120)
    assert failed["status"] == "failed", failed
    assert failed["error"]["type"] == "/problems/worker-crashed"
    assert "quarantined" in failed["error"]["detail"] and "2 time(s)" in failed["error"]["detail"]
    assert failed["attempts"] == 2
    # The bystander's worker was stopped by the pool, not by its own fault: not charged.
    assert survived["status"] == "succeeded", survived
    assert survived["attempts"] == 1


# -- finding 5: a read-only store, corrupt and missing results ---------------------------------

class ReadOnlyStore:
    """Wraps the app's store so its connections open the database read-only (as on a
    read-only mount; chmod does not stop root)."""

    def __new__(cls, store):
        import sqlite3
        from contextlib import contextmanager

        from service.store import JobStore

        class _ReadOnly(JobStore):
            @contextmanager
            def _conn(self):
                conn = sqlite3.connect(f"file:{self.db_path}?mode=ro", uri=True,
                                       isolation_level=None, check_same_thread=False)
                conn.row_factory = sqlite3.Row
                try:
                    yield conn
                finally:
                    conn.close()

        return _ReadOnly(store.db_path, store.busy_timeout)


@pytest.fixture
def read_only_store(client):
    original = client.app.state.store
    done = client.post("/v1/jobs", json={"points": sphere(100).tolist()}).json()
    client.app.state.store = ReadOnlyStore(original)
    yield done["id"]
    client.app.state.store = original


def test_read_only_store_fails_readiness_and_answers_503(client, read_only_store):
    ready = client.get("/readyz")
    assert ready.status_code == 503 and ready.json()["checks"]["store"] is False
    folders = set((client.app.state.settings.jobs_dir).iterdir())
    problem = assert_problem(client.post("/v1/jobs", json={"points": sphere(50).tolist()}),
                             503, "store-read-only")
    assert "Retry-After" in client.post("/v1/jobs", json={"points": sphere(50).tolist()}
                                        ).headers
    assert "cannot be written" in problem["detail"]
    assert set(client.app.state.settings.jobs_dir.iterdir()) == folders  # nothing left
    assert_problem(client.delete(f"/v1/jobs/{read_only_store}"), 503, "store-read-only")


def _succeeded_job(client) -> dict:
    from service_helpers import wait_for_job

    job = client.post("/v1/jobs", json={"points": sphere(150).tolist()}).json()
    job = wait_for_job(client, job["id"])
    assert job["status"] == "succeeded"
    return job


@pytest.mark.parametrize("fmt", ["npz", "ply"])
def test_corrupt_result_is_a_problem_and_the_job_is_computed_again(client, fmt):
    from service_helpers import wait_for_job

    job = _succeeded_job(client)
    folder = client.app.state.settings.jobs_dir / job["id"]
    good = client.get(f"/v1/jobs/{job['id']}/result?format={fmt}")
    assert good.status_code == 200
    # Flip bytes in the middle of the canonical result (same size: a silent corruption).
    canonical = folder / "result.npz"
    data = bytearray(canonical.read_bytes())
    data[len(data) // 2: len(data) // 2 + 16] = bytes(16)
    canonical.write_bytes(bytes(data))
    if fmt != "npz":
        (folder / f"result.{fmt}").unlink()  # not rendered yet: must come from the canonical
    problem = assert_problem(client.get(f"/v1/jobs/{job['id']}/result?format={fmt}"), 503,
                             "result-corrupt")
    assert "checksum" in problem["detail"] and "compute it again" in problem["detail"]
    again = wait_for_job(client, job["id"])
    assert again["status"] == "succeeded"
    fresh = client.get(f"/v1/jobs/{job['id']}/result?format={fmt}")
    assert fresh.status_code == 200
    if fmt == "npz":  # the same numbers (the info member holds timings)
        import io

        with np.load(io.BytesIO(good.content)) as a, np.load(io.BytesIO(fresh.content)) as b:
            for key in set(a.files) - {"info"}:
                np.testing.assert_array_equal(a[key], b[key])
    else:
        assert fresh.content == good.content


def test_corrupt_rendered_file_is_rendered_again(client):
    job = _succeeded_job(client)
    good = client.get(f"/v1/jobs/{job['id']}/result?format=csv")
    path = client.app.state.settings.jobs_dir / job["id"] / "result.csv"
    path.write_bytes(path.read_bytes()[:100])  # truncated
    again = client.get(f"/v1/jobs/{job['id']}/result?format=csv")
    assert again.status_code == 200 and again.content == good.content


def test_missing_result_of_a_succeeded_job_is_not_job_not_found(client):
    from service_helpers import wait_for_job

    job = _succeeded_job(client)
    folder = client.app.state.settings.jobs_dir / job["id"]
    for path in folder.glob("result.*"):
        path.unlink()
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result?format=json"), 503,
                   "result-corrupt")
    assert wait_for_job(client, job["id"])["status"] == "succeeded"
    assert client.get(f"/v1/jobs/{job['id']}/result?format=json").status_code == 200


# -- finding 7: headers, Allow, keys out of logs, the schema says what is accepted --------------

def test_security_headers_on_every_response(client):
    for response in (client.get("/healthz"), client.get("/v1/jobs"),
                     client.get("/v1/jobs/nope"), client.post("/v1/jobs", content=b"x"),
                     client.get("/nowhere")):
        assert response.headers["x-content-type-options"] == "nosniff", response.url
        assert "cache-control" in response.headers, response.url


def test_options_and_405_name_every_method_of_the_path(client):
    options = client.options("/v1/jobs")
    assert options.status_code == 204
    assert set(options.headers["allow"].split(", ")) == {"GET", "POST", "OPTIONS"}
    not_allowed = client.put("/v1/jobs")
    assert not_allowed.status_code == 405
    assert {"GET", "POST"} <= set(not_allowed.headers["allow"].split(", "))
    one = client.options("/v1/jobs/abc")
    assert {"GET", "DELETE"} <= set(one.headers["allow"].split(", "))
    assert client.options("/nowhere").status_code == 404


def test_query_string_values_never_reach_the_access_log():
    import logging

    from service.middleware import RedactQueryFilter, redact_query

    record = logging.LogRecord("uvicorn.access", logging.INFO, __file__, 1,
                               '%s - "%s %s HTTP/%s" %d',
                               ("127.0.0.1:5", "GET", "/v1/jobs?api_key=SECRETKEY&limit=5",
                                "1.1", 401), None)
    RedactQueryFilter().filter(record)
    line = record.getMessage()
    assert "SECRETKEY" not in line and "limit=5" in line and "api_key=REDACTED" in line
    assert redact_query("/v1/jobs") == "/v1/jobs"
    assert "hunter2" not in redact_query("/x?token=hunter2&format=ply")
    assert "format=ply" in redact_query("/x?token=hunter2&format=ply")


def test_schema_refuses_what_the_server_refuses(client):
    import json

    import jsonschema_rs  # installed with schemathesis

    spec = client.get("/openapi.json").json()
    cloud = spec["components"]["schemas"]["CloudRequest"]
    # Refs point into #/components/schemas: validate against a document that has them.
    doc = json.loads(json.dumps({"components": spec["components"], **cloud}))
    validator = jsonschema_rs.Draft202012Validator(doc)
    points = sphere(20).tolist()
    bad = [{"points": points, "normals": []},
           {"points": points, "params": {"method": "knn", "fit": "nfr", "solver": "taubin"}},
           {"points": points, "params": {"method": "knn", "fit": "monge",
                                         "solver": "algebraic"}}]
    for body in bad:
        assert not validator.is_valid(body), body
        assert client.post("/v1/jobs", json=body).status_code == 422
    good = {"points": points, "params": {"method": "knn", "solver": "algebraic"}}
    assert validator.is_valid(good)
    # Found by schemathesis --checks all (scripts/api_fuzz.py): each refused by both.
    with_false = [p[:2] + [False] if i == 3 else p for i, p in enumerate(points)]
    with_text = [[str(v) for v in p] if i == 5 else p for i, p in enumerate(points)]
    bad = [{"points": with_false}, {"points": with_text},
           {"points": points, "normals": [[0, 0, None]] + points[1:]},
           {"points": points, "params": {"method": "knn", "k": True}},
           {"points": points, "params": {"method": "knn", "viewpoint": [0, 0, False]}},
           {"points": points, "params": {"method": "knn", "orientation": "viewpoint"}},
           {"points": points, "params": {"method": "knn", "orientation": "normals"}},
           {"points": points, "params": {"method": "egg", "fit": "nfr", "normal_k": -3}}]
    for body in bad:
        assert not validator.is_valid(body), body
        answer = client.post("/v1/jobs", json=body)
        assert answer.status_code == 422, (body, answer.text)
    for body in ({"points": points, "params": {}}, {"points": points, "params": {"k": 96}},
                 {"points": points, "normals": points,
                  "params": {"method": "knn", "orientation": "normals"}}):
        assert validator.is_valid(body), body
        answer = client.post("/v1/jobs", json=body)
        assert answer.status_code == 202, (body, answer.text)
        client.delete(f"/v1/jobs/{answer.json()['id']}")
    # A multipart body names only its two parts, the params part being the same object.
    upload = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["multipart/form-data"]
    assert spec["components"]["schemas"]["MultipartCloudRequest"]["additionalProperties"] \
        is False
    assert upload["encoding"]["params"]["contentType"] == "application/json"


# -- finding 3: memory bounded before work -------------------------------------------------------

def _upload(client, name: str, payload: bytes):
    return client.post("/v1/jobs", files={"file": (name, payload)},
                       data={"params": '{"method": "knn", "k": 5}'})


def test_npz_deflate_bomb_is_refused_at_upload(client):
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, points=np.zeros((2_000_000, 3)))  # 48 MB in ~50 kB
    assert len(buffer.getvalue()) < 500_000
    problem = assert_problem(_upload(client, "bomb.npz", buffer.getvalue()), 422,
                             "malformed-file")
    assert "expands" in problem["detail"] and "'points.npy'" in problem["detail"]


def test_npy_header_claiming_too_many_points_is_refused_without_reading(client):
    import io

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (62_500_000, 3)})
    payload = header.getvalue() + bytes(4096)  # the header claims 1.5 GB of data
    with changed_settings(client, max_points=1_000_000):
        problem = assert_problem(_upload(client, "liar.npy", payload), 413, "cloud-too-large")
    assert "(62500000, 3)" in problem["detail"]


def test_npz_member_header_claiming_too_many_points_is_refused(client):
    import io
    import zipfile

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (62_500_000, 3)})
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("points.npy", header.getvalue() + bytes(1000))
    with changed_settings(client, max_points=1_000_000):
        assert_problem(_upload(client, "liar.npz", buffer.getvalue()), 413, "cloud-too-large")


# -- finding 4: slow and piled-up uploads ---------------------------------------------------------

def _stalled_upload(port: int, key: str):
    """Open a multipart upload, send its head and a first chunk, then stall."""
    import socket

    boundary = "stall"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; "
            "filename=\"c.xyz\"\r\n\r\n0 0 0\n").encode()
    sock = socket.create_connection(("127.0.0.1", port))
    sock.sendall((f"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {key}\r\n"
                  f"Content-Type: multipart/form-data; boundary={boundary}\r\n"
                  "Content-Length: 1000000\r\n\r\n").encode() + head)
    return sock


def _answer(sock, timeout: float) -> str:
    sock.settimeout(timeout)
    data = b""
    try:
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
    finally:
        sock.close()
    return data.decode("latin-1")


def test_stalled_uploads_are_capped_per_key_and_timed_out(tmp_path):
    from service_helpers import KEY_B, KEYS

    server = ServerProcess(tmp_path / "data", tmp_path / "server.log", api_key=KEY_A,
                           api_keys=KEYS, warmup="false", max_uploads_per_key=2,
                           upload_read_timeout_seconds=2).start()
    try:
        stalled = [_stalled_upload(server.port, KEY_A) for _ in range(2)]
        time.sleep(0.5)  # both are being received
        third = _answer(_stalled_upload(server.port, KEY_A), timeout=10)
        assert third.startswith("HTTP/1.1 429"), third
        assert "retry-after" in third.lower()
        # Another key is not held up by the first key's stalled uploads.
        other = server.client.post("/v1/jobs", json={"points": sphere(50).tolist()},
                                   headers={"Authorization": f"Bearer {KEY_B}"})
        assert other.status_code == 202, other.text
        # The stalled ones are answered 408 after the read timeout, and leave no job folder.
        for sock in stalled:
            assert _answer(sock, timeout=20).startswith("HTTP/1.1 408")
        folders = list((tmp_path / "data" / "jobs").iterdir())
        assert [f.name for f in folders] == [other.json()["id"]]
    finally:
        server.stop()


def test_upload_gate_counts_and_releases():
    from service.problems import HTTPProblem
    from service.upload_gate import UploadGate

    gate = UploadGate(max_total=3, max_per_key=2)
    with gate.hold("a", 5), gate.hold("a", 5):
        with pytest.raises(HTTPProblem) as per_key:
            with gate.hold("a", 5):
                pass
        assert per_key.value.slug == "too-many-uploads"
        with gate.hold("b", 5):
            with pytest.raises(HTTPProblem) as total:
                with gate.hold("c", 5):
                    pass
            assert total.value.slug == "queue-full"
    assert gate.total == 0 and not gate.per_key


# -- finding 6: small jobs do not wait behind large ones ------------------------------------------

def _queue(store, owner: str, size: int) -> str:
    from service.store import new_job_id

    job_id = new_job_id()
    store.insert(job_id=job_id, owner=owner, params={"method": "knn"}, input_kind="file",
                 input_file="input.npy", input_name="c.npy", input_format="npy",
                 input_bytes=size, n_points=None)
    return job_id


def test_scheduler_keeps_a_worker_for_small_jobs_and_shares_between_keys(tmp_path):
    from service.store import JobStore

    store = JobStore(tmp_path / "jobs.sqlite3")
    store.initialize()
    big = 100 << 20
    large = [_queue(store, "a", big) for _ in range(5)]
    small_a = _queue(store, "a", 2000)
    small_b = _queue(store, "b", 2000)
    options = {"large_bytes": 4 << 20, "large_slots": 1}
    # Two free workers: one large job, and the other worker goes to a small one, of the key
    # with nothing running (b), not to the next large job of a.
    first = store.next_queued(2, set(), **options)
    assert first == [large[0], small_b]
    store.claim(large[0], "r1")
    store.claim(small_b, "r2")
    # b's job done, one worker free again: a's small job goes before its queued large ones.
    store.finish(small_b, "r2", status="succeeded", ttl=60)
    assert store.next_queued(1, set(), **options) == [small_a]
    # Without the options the old FIFO order remains.
    assert store.next_queued(2, set()) == large[1:3]


def test_json_body_above_the_point_limit_is_refused_before_parsing(tmp_path):
    import json
    import tracemalloc

    from service import uploads
    from service.problems import HTTPProblem

    body = b'{"points": [' + b",".join([b"[0,0,0]"] * 3_000_000) + b"]}"  # 24 MB
    tracemalloc.start()
    try:
        with pytest.raises(HTTPProblem) as refused:
            uploads._decode_cloud(body, tmp_path, max_points=1_000_000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert refused.value.slug == "cloud-too-large" and "3000000" in refused.value.detail
    # Parsing it would have taken about 11 bytes per byte (a list per point); the count
    # takes scratch space of a few bytes per chunk byte, whatever the body's size.
    assert peak < 10 << 20 < len(body) / 2, peak
    # Under the limit the same body is parsed and stored as before.
    small = json.dumps({"points": sphere(50).tolist()}).encode()
    assert uploads._decode_cloud(small, tmp_path, max_points=1_000_000)[1] == 50


def test_point_count_of_json_bodies_matches_the_parser():
    import json

    from service.json_count import member_rows

    rng = np.random.default_rng(3)
    for n in (10, 997, 20_000):
        doc = {"params": {"method": "tc", "viewpoint": [1, 2, 3]},
               "points": rng.normal(size=(n, 3)).tolist(), "faces": [[0, 1, 2]] * 5,
               "normals": rng.normal(size=(n, 3)).tolist()}
        body = json.dumps(doc).encode()
        for chunk in ((7, 4096) if n < 1000 else (4096, 1 << 18)):
            assert member_rows(body, chunk) == {"points": n, "normals": n, "faces": 5}
    tricky = b'{"params": {"method": "x]\\"[[["}, "points": [[1,2,3],[4,5,6]]}'
    assert member_rows(tricky, 5)["points"] == 2
