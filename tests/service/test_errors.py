"""Every error path answers application/problem+json with a stable type, never a traceback."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from service_helpers import changed_settings, sphere, wait_for_job

import curvature

PROBLEM = "application/problem+json"


def assert_problem(response, status: int, slug: str) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    body = response.json()
    assert body["type"] == f"/problems/{slug}"
    assert body["status"] == status
    assert body["title"] and body["detail"]
    assert body["instance"] == response.request.url.path
    assert "Traceback" not in response.text
    return body


def upload(client, path: str, name: str, content: bytes, params=None, **kwargs):
    data = {} if params is None else {"params": params}
    return client.post(path, files={"file": (name, content)}, data=data, **kwargs)


def failed_job(client, name: str, content: bytes) -> dict:
    """Submit a file as a job (accepted: it is read by a worker) and wait for its failure."""
    response = upload(client, "/v1/jobs", name, content)
    assert response.status_code == 202, response.text
    job = wait_for_job(client, response.json()["id"])
    assert job["status"] == "failed", job
    return job


def ascii_ply(points, extra_header: str = "") -> bytes:
    lines = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property float x",
             "property float y", "property float z", "end_header"]
    body = [" ".join(str(v) for v in p) for p in points]
    return ("\n".join(lines) + extra_header + "\n" + "\n".join(body) + "\n").encode()


@pytest.fixture(scope="module")
def binary_ply() -> bytes:
    buffer = io.BytesIO()
    curvature.io.write_stream(buffer, sphere(200), "ply")
    return buffer.getvalue()


# -- files -------------------------------------------------------------------------------------

def test_truncated_binary_ply_sync(client, binary_ply):
    response = upload(client, "/v1/curvature", "cut.ply", binary_ply[: len(binary_ply) // 2])
    body = assert_problem(response, 422, "malformed-file")
    assert body["detail"].startswith("cut.ply")
    assert "/jobs/" not in body["detail"] and "tmp" not in body["detail"]  # no server paths


def test_truncated_binary_ply_job_fails_with_the_problem(client, binary_ply):
    job = failed_job(client, "cut.ply", binary_ply[:-100])
    assert job["error"]["type"] == "/problems/malformed-file"
    assert job["error"]["status"] == 422
    assert "cut.ply" in job["error"]["detail"]
    response = client.get(f"/v1/jobs/{job['id']}/result")
    assert_problem(response, 409, "job-failed")


def test_malformed_ascii_ply(client):
    content = ascii_ply(sphere(20)).split(b"end_header\n")[0] + b"end_header\n1 2 x\n"
    assert_problem(upload(client, "/v1/curvature", "bad.ply", content), 422, "malformed-file")


def test_garbage_file(client):
    assert_problem(upload(client, "/v1/curvature", "noise.ply", b"\x00\x01garbage" * 10),
                   422, "malformed-file")


def test_unknown_format_is_415_before_the_upload_is_stored(client):
    response = upload(client, "/v1/jobs", "scan.docx", b"x" * 1000)
    body = assert_problem(response, 415, "unknown-format")
    assert "scan.docx" in body["detail"]
    assert_problem(upload(client, "/v1/curvature", "noextension", b"1 2 3\n"), 415,
                   "unknown-format")


def test_unsupported_request_media_type(client):
    response = client.post("/v1/jobs", content=b"1 2 3", headers={"Content-Type": "text/plain"})
    assert_problem(response, 415, "unsupported-media-type")


def test_nan_coordinates_in_a_file(client):
    pts = sphere(30).tolist()
    pts[4][1] = float("nan")
    content = ascii_ply(pts)
    assert_problem(upload(client, "/v1/curvature", "nan.ply", content), 422,
                   "non-finite-coordinates")
    job = failed_job(client, "nan.ply", content)
    assert job["error"]["type"] == "/problems/non-finite-coordinates"


def test_too_few_points_in_a_file(client):
    content = ascii_ply(sphere(5))
    assert_problem(upload(client, "/v1/curvature", "five.ply", content), 422, "too-few-points")


# -- JSON bodies -------------------------------------------------------------------------------

@pytest.mark.parametrize("path", ["/v1/jobs", "/v1/curvature"])
def test_nan_coordinates_in_json(client, path):
    pts = sphere(30).tolist()
    pts[7][2] = float("nan")
    body = json.dumps({"points": pts})  # Python writes the NaN literal JSON lacks
    response = client.post(path, content=body, headers={"Content-Type": "application/json"})
    problem = assert_problem(response, 422, "non-finite-coordinates")
    assert "index 7" in problem["detail"]
    pts[7][2] = None
    response = client.post(path, json={"points": pts})
    assert_problem(response, 422, "non-finite-coordinates")


@pytest.mark.parametrize("path", ["/v1/jobs", "/v1/curvature"])
def test_too_few_points_in_json(client, path):
    assert_problem(client.post(path, json={"points": sphere(9).tolist()}), 422,
                   "too-few-points")


@pytest.mark.parametrize("body", [
    {"points": [[1, 2], [3, 4]]},
    {"points": [[1, 2, 3], [4, 5]]},
    {"points": "abc"},
    {"points": sphere(20).tolist(), "normals": [[0, 0, 1]]},
    {"points": sphere(20).tolist(), "faces": [[0, 1, 99]]},
    {"points": sphere(20).tolist(), "faces": [[0, 1, 2.5]]},
])
def test_invalid_cloud_shapes(client, body):
    assert_problem(client.post("/v1/jobs", json=body), 422, "invalid-cloud")


@pytest.mark.parametrize("body", [
    {"points": sphere(20).tolist(), "colour": "red"},
    {"normals": []},
    [1, 2, 3],
])
def test_invalid_request_members(client, body):
    assert_problem(client.post("/v1/jobs", json=body), 422, "invalid-request")


def test_malformed_json(client):
    response = client.post("/v1/jobs", content=b'{"points": [[1,2,3]',
                           headers={"Content-Type": "application/json"})
    assert_problem(response, 400, "malformed-request")


def test_malformed_multipart(client):
    multipart = {"Content-Type": "multipart/form-data; boundary=xyz"}
    response = client.post("/v1/jobs", content=b"--xyz\r\ngarbage", headers=multipart)
    assert_problem(response, 400, "malformed-request")
    truncated = (b'--xyz\r\nContent-Disposition: form-data; name="file"; filename="a.ply"'
                 b"\r\n\r\nply\nformat ascii 1.0\n")
    response = client.post("/v1/jobs", content=truncated, headers=multipart)
    assert_problem(response, 400, "malformed-request")
    response = client.post("/v1/jobs", content=b"abc",
                           headers={"Content-Type": "multipart/form-data"})
    assert_problem(response, 400, "malformed-request")


def test_multipart_without_file(client):
    response = client.post("/v1/jobs", data={"params": "{}"},
                           files={"other": ("a.txt", b"1")})
    assert_problem(response, 422, "invalid-request")
    response = client.post("/v1/jobs", files={"params": (None, b'{"method": "knn"}')})
    assert_problem(response, 422, "invalid-request")


# -- parameters --------------------------------------------------------------------------------

@pytest.mark.parametrize(("params", "where"), [
    ({"method": "knn", "k": 2}, "params.k"),
    ({"method": "knn", "k": 100000}, "params.k"),
    ({"method": "knn", "k": "many"}, "params.k"),
    ({"method": "knn", "neighbours": 3}, "params.neighbours"),
    ({"method": "nope"}, "params"),
    ({"k": 10}, "params"),
    ({"method": "knn", "fit": "cubic"}, "params.fit"),
    ({"method": "knn", "fit": "monge", "solver": "taubin"}, "params"),
    ({"method": "knn", "orientation": "viewpoint"}, "params"),
    ({"method": "knn", "viewpoint": [0, 0]}, "params.viewpoint"),
])
def test_bad_parameters_json(client, params, where):
    response = client.post("/v1/jobs", json={"points": sphere(20).tolist(), "params": params})
    body = assert_problem(response, 422, "invalid-parameters")
    assert body["detail"].startswith(where)
    assert body["errors"] and all({"loc", "msg", "type"} <= set(e) for e in body["errors"])


def test_bad_parameters_multipart(client, mesh_ply):
    content = mesh_ply.read_bytes()
    body = assert_problem(upload(client, "/v1/jobs", "m.ply", content, params="{not json"),
                          422, "invalid-parameters")
    assert "not valid JSON" in body["detail"]
    assert_problem(upload(client, "/v1/curvature", "m.ply", content,
                          params=json.dumps({"method": "knn", "k": 0})),
                   422, "invalid-parameters")


def test_bad_query_parameters(client):
    assert_problem(client.get("/v1/jobs", params={"limit": 0}), 422, "invalid-request")
    assert_problem(client.get("/v1/jobs", params={"status": "lost"}), 422, "invalid-request")
    assert_problem(client.get("/v1/jobs", params={"cursor": "9" * 5000}), 422,
                   "invalid-request")


# -- jobs and results --------------------------------------------------------------------------

def test_unknown_job(client):
    for response in (client.get("/v1/jobs/0123456789abcdef"),
                     client.get("/v1/jobs/0123456789abcdef/result"),
                     client.delete("/v1/jobs/0123456789abcdef")):
        body = assert_problem(response, 404, "job-not-found")
        assert body["job_id"] == "0123456789abcdef"


def test_result_not_ready(client):
    buffer = io.BytesIO()
    np.save(buffer, np.random.default_rng(1).normal(size=(150_000, 3)))
    response = upload(client, "/v1/jobs", "slow.npy", buffer.getvalue(),
                      params=json.dumps({"method": "knn", "k": 5}))
    job_id = response.json()["id"]
    body = assert_problem(client.get(f"/v1/jobs/{job_id}/result"), 409, "result-not-ready")
    assert body["job_status"] in ("queued", "running")
    assert client.get(f"/v1/jobs/{job_id}/result").headers["retry-after"] == "1"
    client.delete(f"/v1/jobs/{job_id}")


def test_not_acceptable(client):
    job = client.post("/v1/jobs", json={"points": sphere(50).tolist()}).json()
    wait_for_job(client, job["id"])
    response = client.get(f"/v1/jobs/{job['id']}/result", headers={"Accept": "image/png"})
    assert_problem(response, 406, "not-acceptable")
    response = client.get(f"/v1/jobs/{job['id']}/result?format=xlsx")
    assert_problem(response, 422, "invalid-request")


# -- limits ------------------------------------------------------------------------------------

def test_too_large_by_content_length(client, mesh_ply):
    with changed_settings(client, max_upload_bytes=2000):
        body = assert_problem(upload(client, "/v1/jobs", "m.ply", mesh_ply.read_bytes()),
                              413, "too-large")
        assert "2000" in body["detail"]
    with changed_settings(client, max_json_bytes=1000):
        assert_problem(client.post("/v1/jobs", json={"points": sphere(100).tolist()}), 413,
                       "too-large")


def test_too_large_while_streaming_without_content_length(client):
    boundary = "b0undary"

    def body():
        yield (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; "
               f"filename=\"big.xyz\"\r\n\r\n").encode()
        for _ in range(100):
            yield b"1.0 2.0 3.0\n" * 100

    with changed_settings(client, max_upload_bytes=50_000):
        response = client.post("/v1/jobs", content=body(), headers={
            "Content-Type": f"multipart/form-data; boundary={boundary}"})
        assert_problem(response, 413, "too-large")
    jobs_dir = client.app.state.settings.jobs_dir
    assert not any((d / ".upload.part").exists() for d in jobs_dir.iterdir())


def test_too_many_points_for_a_synchronous_answer(client, mesh_ply):
    with changed_settings(client, sync_max_points=100):
        assert_problem(client.post("/v1/curvature", json={"points": sphere(101).tolist()}),
                       413, "too-many-points")
        assert_problem(upload(client, "/v1/curvature", "m.ply", mesh_ply.read_bytes()),
                       413, "too-many-points")


def test_queue_full(client):
    with changed_settings(client, max_queued_jobs=0, retry_after_seconds=7):
        response = client.post("/v1/jobs", json={"points": sphere(20).tolist()})
        assert_problem(response, 503, "queue-full")
        assert response.headers["retry-after"] == "7"
    with changed_settings(client, max_pending_sync=0):
        response = client.post("/v1/curvature", json={"points": sphere(20).tolist()})
        assert_problem(response, 503, "queue-full")
        assert response.headers["retry-after"]


# -- generic -----------------------------------------------------------------------------------

def test_unknown_route_and_method(client):
    assert_problem(client.get("/v2/nothing"), 404, "not-found")
    assert_problem(client.put("/v1/methods"), 405, "method-not-allowed")


def test_unexpected_error_is_a_bare_500_problem(client, monkeypatch):
    import service.routes.methods as methods_route

    def explode():
        raise RuntimeError("secret internal state /etc/passwd")

    monkeypatch.setattr(methods_route, "methods_response", explode)
    body = assert_problem(client.get("/v1/methods"), 500, "internal-error")
    assert "secret" not in json.dumps(body)


def test_problem_types_are_documented(client):
    listing = client.get("/problems").json()
    slugs = {p["type"].rsplit("/", 1)[1] for p in listing}
    assert {"malformed-file", "unknown-format", "non-finite-coordinates", "too-few-points",
            "invalid-parameters", "job-not-found", "result-not-ready", "too-large",
            "queue-full", "internal-error"} <= slugs
    one = client.get("/problems/too-large").json()
    assert one["status"] == 413 and one["type"] == "/problems/too-large"
    assert_problem(client.get("/problems/nonsense"), 404, "not-found")
