"""Jobs through the in-process app: both input paths, every result format, listing, cancel."""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import time

import numpy as np
import pytest
from service_helpers import KEY_B, bearer, sphere, wait_for_job

import curvature


def submit_json(client, points, params=None, headers=None, **extra) -> dict:
    body = {"points": np.asarray(points).tolist(), **extra}
    if params is not None:
        body["params"] = params
    response = client.post("/v1/jobs", json=body, headers=headers or {})
    assert response.status_code == 202, response.text
    return response.json()


@pytest.fixture(scope="module")
def sphere_job(app_client):
    """A finished job on a sphere of radius 2 (k1 = k2 = 0.5 with outward normals)."""
    job = submit_json(app_client, sphere(400), {"method": "knn", "k": 12})
    return wait_for_job(app_client, job["id"])


def test_json_submission_is_accepted_with_location(client, sphere_points):
    response = client.post("/v1/jobs", json={"points": sphere_points.tolist()})
    assert response.status_code == 202
    job = response.json()
    assert response.headers["location"] == f"/v1/jobs/{job['id']}"
    assert job["status"] in ("queued", "running", "succeeded")
    assert job["input"] == {"kind": "arrays", "filename": None, "format": "json",
                            "bytes": len(response.request.content)}
    # core default: method auto with its own neighborhood sizes
    assert job["params"]["method"] == "auto" and job["params"]["k"] == 1536
    assert job["n_points"] == len(sphere_points)


def test_job_succeeds_with_correct_curvature(sphere_job):
    assert sphere_job["status"] == "succeeded", sphere_job
    assert sphere_job["progress"] == 1.0
    assert sphere_job["error"] is None
    assert sphere_job["result"]["status_counts"] == {"ok": 400}
    assert sphere_job["links"]["result"] == f"/v1/jobs/{sphere_job['id']}/result"
    for key in ("created_at", "started_at", "finished_at", "expires_at"):
        assert sphere_job[key] is not None
    assert sphere_job["attempts"] == 1


def test_result_json_is_columnar_with_null_for_nan(client, sphere_job):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result")
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/json"
    doc = response.json()
    assert doc["n"] == 400
    k1 = np.array(doc["fields"]["k1"], dtype=float)
    assert k1.shape == (400,)
    assert np.allclose(np.median(k1), 0.5, rtol=0.05)
    assert len(doc["fields"]["normals"]) == 400 and len(doc["fields"]["normals"][0]) == 3


def test_result_ply_parses_back_with_the_library(client, sphere_job, tmp_path):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result?format=ply")
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/x-ply"
    assert response.headers["content-disposition"] == \
        f'attachment; filename="{sphere_job["id"]}.ply"'
    assert response.content.startswith(b"ply\nformat binary_little_endian")
    path = tmp_path / "result.ply"
    path.write_bytes(response.content)
    cloud = curvature.read(path)
    assert cloud.points.shape == (400, 3)
    assert {"k1", "k2", "mean", "gaussian", "status"} <= set(cloud.properties)
    assert np.allclose(np.median(cloud.properties["k1"]), 0.5, rtol=0.05)


def test_result_csv_parses(client, sphere_job):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result", params={"format": "csv"})
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert len(rows) == 400
    assert {"x", "y", "z", "k1", "k2", "mean", "gaussian", "status"} <= set(rows[0])
    assert np.allclose(np.median([float(r["k2"]) for r in rows]), 0.5, rtol=0.05)


def test_result_npz_parses(client, sphere_job):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result?format=npz")
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/x-npz"
    with np.load(io.BytesIO(response.content)) as data:
        assert data["points"].shape == (400, 3)
        assert data["k1"].shape == (400,)
        assert np.allclose(np.median(data["mean"]), 0.5, rtol=0.05)


@pytest.mark.parametrize(("accept", "expected"), [
    ("application/json", "application/json"),
    ("application/x-ply", "application/x-ply"),
    ("model/ply", "application/x-ply"),
    ("application/octet-stream", "application/x-ply"),
    ("text/csv", "text/csv; charset=utf-8"),
    ("application/x-npz", "application/x-npz"),
    ("text/html;q=0.9, text/csv;q=0.5, application/x-npz;q=0.7", "application/x-npz"),
    ("*/*", "application/json"),
])
def test_accept_header_selects_the_format(client, sphere_job, accept, expected):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result", headers={"Accept": accept})
    assert response.status_code == 200
    assert response.headers["content-type"] == expected


def test_format_parameter_wins_over_accept(client, sphere_job):
    response = client.get(f"/v1/jobs/{sphere_job['id']}/result?format=csv",
                          headers={"Accept": "application/json"})
    assert response.headers["content-type"].startswith("text/csv")


def test_multipart_upload_keeps_faces_in_the_ply_result(client, mesh_ply, tmp_path):
    with open(mesh_ply, "rb") as fh:
        response = client.post("/v1/jobs", files={"file": ("bump.ply", fh)},
                               data={"params": json.dumps({"method": "knn", "k": 8,
                                                           "fit": "monge"})})
    assert response.status_code == 202, response.text
    job = response.json()
    assert job["input"]["kind"] == "file" and job["input"]["filename"] == "bump.ply"
    assert job["params"]["fit"] == "monge"
    job = wait_for_job(client, job["id"])
    assert job["status"] == "succeeded", job
    assert job["n_points"] == 120
    ply = client.get(f"/v1/jobs/{job['id']}/result?format=ply")
    path = tmp_path / "out.ply"
    path.write_bytes(ply.content)
    cloud = curvature.read(path)
    original = curvature.read(mesh_ply)
    assert np.array_equal(cloud.faces, original.faces)
    assert np.allclose(cloud.points, original.points)


def test_json_input_with_normals_and_faces(client, tmp_path):
    pts = sphere(200)
    normals = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    faces = [[0, 1, 2], [2, 3, 4]]
    job = submit_json(client, pts, {"method": "knn", "k": 10}, normals=normals.tolist(),
                      faces=faces)
    job = wait_for_job(client, job["id"])
    assert job["status"] == "succeeded", job
    ply = client.get(f"/v1/jobs/{job['id']}/result?format=ply")
    path = tmp_path / "out.ply"
    path.write_bytes(ply.content)
    assert curvature.read(path).faces.tolist() == faces
    doc = client.get(f"/v1/jobs/{job['id']}/result").json()
    # Given outward normals orient the result: positive curvature on a sphere.
    assert np.median(np.array(doc["fields"]["k1"], dtype=float)) > 0


def test_list_is_per_key_and_paginated(client, sphere_points):
    owner = bearer(KEY_B)
    # Key B's earlier jobs (other tests) are listed too: page through to the first of ours.
    ids = [submit_json(client, sphere_points[:50], headers=owner)["id"] for _ in range(5)]
    seen, cursor = [], None
    while True:
        params = {"limit": 2} | ({"cursor": cursor} if cursor else {})
        response = client.get("/v1/jobs", params=params, headers=owner)
        assert response.status_code == 200
        page = response.json()
        assert len(page["items"]) <= 2
        seen += [item["id"] for item in page["items"]]
        cursor = page["next_cursor"]
        if cursor is None:
            assert "link" not in response.headers
            break
        assert 'rel="next"' in response.headers["link"]
    assert seen[:5] == ids[::-1]  # newest first
    assert len(seen) == len(set(seen))  # each exactly once
    other = client.get("/v1/jobs", params={"limit": 200}).json()  # key A
    assert not set(ids) & {item["id"] for item in other["items"]}
    for job_id in ids:
        wait_for_job(client, job_id, headers=owner)
    done = client.get("/v1/jobs", params={"status": "succeeded", "limit": 200},
                      headers=owner).json()
    assert set(ids) <= {item["id"] for item in done["items"]}


def test_delete_finished_job_removes_it(client, sphere_points):
    job = wait_for_job(client, submit_json(client, sphere_points[:60])["id"])
    folder = client.app.state.settings.jobs_dir / job["id"]
    assert folder.exists()
    response = client.delete(f"/v1/jobs/{job['id']}")
    assert response.status_code == 204
    assert client.get(f"/v1/jobs/{job['id']}").status_code == 404
    assert not folder.exists()


def submit_big(client, n: int) -> dict:
    """A random cloud of ``n`` points uploaded as NPY (quicker to send than JSON)."""
    buffer = io.BytesIO()
    np.save(buffer, np.random.default_rng(7).normal(size=(n, 3)))
    response = client.post("/v1/jobs", files={"file": ("big.npy", buffer.getvalue())},
                           data={"params": json.dumps({"method": "knn", "k": 5})})
    assert response.status_code == 202, response.text
    return response.json()


def test_cancel_queued_job(client):
    # Fill both workers, then the next job waits in the queue.
    blockers = [submit_big(client, 120_000)
                for _ in range(2)]
    queued = submit_json(client, sphere(100))
    response = client.delete(f"/v1/jobs/{queued['id']}")
    assert response.status_code == 200
    assert response.json()["status"] == "cancelled"
    for job in blockers:
        client.delete(f"/v1/jobs/{job['id']}")
    for job in (*blockers, queued):
        assert wait_for_job(client, job["id"])["status"] == "cancelled"
    # A cancelled job has no result, and stays cancelled.
    response = client.get(f"/v1/jobs/{queued['id']}/result")
    assert response.status_code == 409
    assert response.json()["type"] == "/problems/job-cancelled"


def test_cancel_running_job_stops_the_computation(client):
    job = submit_big(client, 300_000)
    running = wait_for_job(client, job["id"], until=("running",) + ("succeeded", "failed"))
    assert running["status"] == "running", running
    # Wait until the estimate itself runs (the cloud is loaded), then cancel.
    deadline = time.monotonic() + 60
    while client.get(f"/v1/jobs/{job['id']}").json()["progress"] < 0.05:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    response = client.delete(f"/v1/jobs/{job['id']}")
    assert response.status_code == 200 and response.json()["status"] == "cancelled"
    # The worker notices at its next progress report and frees its slot.
    cancelled_at = time.monotonic()
    executor = client.app.state.executor
    while executor.in_flight:
        assert time.monotonic() - cancelled_at < 30, "the cancelled run did not stop"
        time.sleep(0.05)
    final = client.get(f"/v1/jobs/{job['id']}").json()
    assert final["status"] == "cancelled" and final["progress"] < 1.0
    assert not (client.app.state.settings.jobs_dir / job["id"] / "result.npz").exists()


def test_job_survives_a_worker_crash(client):
    """A worker dying mid-job (e.g. killed for memory) breaks the pool: the job runs again in
    a fresh pool and succeeds."""
    job = submit_big(client, 200_000)
    wait_for_job(client, job["id"], until=("running",))
    executor = client.app.state.executor
    for pid in executor.worker_pids():
        os.kill(pid, signal.SIGKILL)
    final = wait_for_job(client, job["id"], timeout=180)
    assert final["status"] == "succeeded", final
    assert final["attempts"] == 2
    # The new pool serves later work as usual.
    again = submit_json(client, sphere(100))
    assert wait_for_job(client, again["id"])["status"] == "succeeded"
