"""The client against a scripted transport: headers, uploads, problem documents, polling with
backoff, transient failures, timeouts and the progress bar."""

from __future__ import annotations

import io
import json

import httpx
import numpy as np
import pytest

from curvature_client import (
    CurvatureAPIError,
    CurvatureClient,
    CurvatureConnectionError,
    Job,
    JobCancelledError,
    JobFailedError,
    JobTimeoutError,
)
from curvature_client.client import format_from_path, parse_npz
from curvature_client.progress import JobProgressBar

PROBLEM = "application/problem+json"


def job_doc(status="queued", progress=0.0, **more):
    return {"id": "j1", "status": status, "progress": progress, "n_points": 12, "error": None,
            **more}


class Script:
    """A transport answering from a list of (method, path) handlers, recording requests."""

    def __init__(self, handler):
        self.handler = handler
        self.requests: list[httpx.Request] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        self.requests.append(request)
        return self.handler(request)

    def client(self, **kwargs) -> CurvatureClient:
        return CurvatureClient("http://svc.test/", transport=httpx.MockTransport(self), **kwargs)


def test_bearer_key_and_client_id_are_sent():
    script = Script(lambda r: httpx.Response(200, json={"methods": []}))
    with script.client(api_key="k" * 20, client_id="me") as client:
        assert client.methods() == {"methods": []}
    request = script.requests[0]
    assert request.headers["authorization"] == "Bearer " + "k" * 20
    assert request.headers["x-client-id"] == "me"
    assert str(request.url) == "http://svc.test/v1/methods"


def test_no_key_no_authorization_header():
    script = Script(lambda r: httpx.Response(200, json={}))
    script.client().methods()
    assert "authorization" not in script.requests[0].headers


def test_arrays_are_uploaded_as_an_exact_npz_with_params():
    seen = {}

    def handler(request):
        body = request.read()
        boundary = request.headers["content-type"].split("boundary=")[1].encode()
        for part in body.split(b"--" + boundary):
            head, _, data = part.partition(b"\r\n\r\n")
            if b'name="file"' in head:
                seen["file_head"] = head
                seen["npz"] = np.load(io.BytesIO(data[:-2]))
            elif b'name="params"' in head:
                seen["params"] = json.loads(data[:-2])
        return httpx.Response(202, json=job_doc())

    points = np.random.default_rng(0).normal(size=(50, 3))
    normals = np.tile([0.0, 0.0, 1.0], (50, 1))
    job = Script(handler).client().submit(points, "tc", normals=normals, fit="monge",
                                          viewpoint=np.array([0.0, 0.0, 5.0]))
    assert job == Job(id="j1", status="queued", progress=0.0, n_points=12)
    assert b'filename="cloud.npz"' in seen["file_head"]
    assert np.array_equal(seen["npz"]["points"], points)  # bit-exact float64
    assert np.array_equal(seen["npz"]["normals"], normals)
    assert seen["params"] == {"method": "tc", "fit": "monge", "viewpoint": [0.0, 0.0, 5.0]}


def form_parts(request: httpx.Request) -> dict[str, bytes]:
    """The multipart fields of a request by name (values without their trailing CRLF)."""
    body = request.read()
    boundary = request.headers["content-type"].split("boundary=")[1].encode()
    parts = {}
    for part in body.split(b"--" + boundary)[1:-1]:
        head, _, data = part.partition(b"\r\n\r\n")
        name = head.split(b'name="')[1].split(b'"')[0].decode()
        parts[name] = data[:-2]
    return parts


def test_without_method_the_service_default_applies(tmp_path):
    source = tmp_path / "scan.xyz"
    source.write_text("0 0 0\n1 0 0\n0 1 0\n")
    submitted = []

    def handler(request):
        if request.url.path == "/v1/methods":
            return httpx.Response(200, json={"default_method": "auto", "methods": []})
        submitted.append(form_parts(request))
        return httpx.Response(202, json=job_doc())

    client = Script(handler).client()
    client.submit(source)  # nothing chosen: no params at all, the service decides
    assert set(submitted[0]) == {"file"} and submitted[0]["file"] == source.read_bytes()
    client.submit(source, k=30)  # parameters name their method: the service's default
    assert json.loads(submitted[1]["params"]) == {"method": "auto", "k": 30}


def test_bad_array_shape_and_missing_file_fail_before_any_request(tmp_path):
    script = Script(lambda r: httpx.Response(500))
    client = script.client()
    with pytest.raises(ValueError, match=r"expected shape \(n, 3\)"):
        client.submit(np.zeros((10, 2)))
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        client.submit(tmp_path / "nope.ply")
    assert script.requests == []


def test_problem_document_becomes_the_exception():
    problem = {"type": "/problems/invalid-parameters", "title": "Invalid parameters",
               "status": 422, "detail": "params.k: Input should be greater than or equal to 1",
               "instance": "/v1/jobs", "errors": [{"loc": ["params", "k"]}]}
    script = Script(lambda r: httpx.Response(422, json=problem, headers={"content-type": PROBLEM}))
    with pytest.raises(CurvatureAPIError) as caught:
        script.client().submit(np.zeros((20, 3)), k=0)
    err = caught.value
    assert err.status == 422 and err.problem == problem
    assert err.type == "/problems/invalid-parameters"
    assert str(err) == ("422 Invalid parameters: params.k: Input should be greater than or "
                        "equal to 1 (/problems/invalid-parameters)")


def test_non_json_error_still_carries_status_and_text():
    script = Script(lambda r: httpx.Response(502, text="<html>Bad gateway</html>"))
    with pytest.raises(CurvatureAPIError) as caught:
        script.client().get("j1")
    assert caught.value.status == 502
    assert caught.value.title == "Bad Gateway" and "Bad gateway" in caught.value.detail


def test_retry_after_is_parsed():
    script = Script(lambda r: httpx.Response(
        503, json={"title": "Queue full", "status": 503}, headers={"Retry-After": "7"}))
    with pytest.raises(CurvatureAPIError) as caught:
        script.client().submit(np.zeros((20, 3)))
    assert caught.value.retry_after == 7.0


def test_connection_failure_is_a_client_error():
    def refuse(request):
        raise httpx.ConnectError("connection refused", request=request)

    with pytest.raises(CurvatureConnectionError, match="GET http://svc.test/v1/jobs/j1"):
        Script(refuse).client().get("j1")


def sequence(*docs):
    """A handler answering GET /v1/jobs/j1 with each document in turn (the last repeats)."""
    answers = list(docs)

    def handler(request):
        answer = answers.pop(0) if len(answers) > 1 else answers[0]
        return answer if isinstance(answer, httpx.Response) else httpx.Response(200, json=answer)

    return handler


def test_wait_follows_progress_and_draws_a_bar(monkeypatch):
    sleeps = []
    monkeypatch.setattr("curvature_client.client.time.sleep", sleeps.append)
    script = Script(sequence(job_doc(), job_doc(), job_doc(), job_doc("running", 0.5),
                             job_doc("succeeded", 1.0, result={"status_counts": {"ok": 12}})))
    stream = io.StringIO()
    job = script.client().wait("j1", stream=stream, poll_interval=0.1, max_interval=0.2)
    assert job.status == "succeeded" and job.data["result"]["status_counts"] == {"ok": 12}
    # Backoff while nothing changes (capped), back to the start after a change.
    assert sleeps == pytest.approx([0.1, 0.15, 0.2, 0.1])
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("job j1 queued") and "0.0%" in lines[0]
    assert "running" in lines[1] and "50.0%" in lines[1]
    assert "succeeded" in lines[-1] and "100.0%" in lines[-1]


def test_wait_without_progress_prints_nothing(monkeypatch, capsys):
    monkeypatch.setattr("curvature_client.client.time.sleep", lambda s: None)
    Script(sequence(job_doc("running", 0.3), job_doc("succeeded", 1.0))).client().wait(
        "j1", progress=False)
    assert capsys.readouterr().err == ""


def test_wait_raises_with_the_jobs_problem_when_it_fails(monkeypatch):
    monkeypatch.setattr("curvature_client.client.time.sleep", lambda s: None)
    error = {"type": "/problems/malformed-file", "title": "Malformed file", "status": 422,
             "detail": "scan.ply (byte 120): truncated"}
    script = Script(sequence(job_doc("running"), job_doc("failed", 0.0, error=error)))
    with pytest.raises(JobFailedError) as caught:
        script.client().wait("j1", progress=False)
    assert caught.value.problem == error and caught.value.status == 422
    assert caught.value.job.status == "failed"
    assert "truncated" in str(caught.value)


def test_wait_raises_when_cancelled(monkeypatch):
    monkeypatch.setattr("curvature_client.client.time.sleep", lambda s: None)
    with pytest.raises(JobCancelledError, match="was cancelled") as caught:
        Script(sequence(job_doc("cancelled"))).client().wait("j1", progress=False)
    assert caught.value.type == "/problems/job-cancelled"


def test_wait_times_out_and_says_the_job_goes_on():
    script = Script(sequence(job_doc("running", 0.25)))
    with pytest.raises(JobTimeoutError, match="still running .25% done. after 0.3 s") as caught:
        script.client().wait("j1", progress=False, timeout=0.3, poll_interval=0.05)
    assert isinstance(caught.value, TimeoutError)
    assert caught.value.job.progress == 0.25


def test_wait_rides_out_a_restart(monkeypatch):
    monkeypatch.setattr("curvature_client.client.time.sleep", lambda s: None)
    calls = {"n": 0}

    def handler(request):
        calls["n"] += 1
        if calls["n"] == 1:
            raise httpx.ConnectError("refused", request=request)
        if calls["n"] == 2:
            return httpx.Response(503, json={"title": "Service not ready", "status": 503},
                                  headers={"Retry-After": "1"})
        return httpx.Response(200, json=job_doc("succeeded", 1.0))

    assert Script(handler).client().wait("j1", progress=False).status == "succeeded"
    assert calls["n"] == 3


def test_wait_does_not_hide_a_404(monkeypatch):
    monkeypatch.setattr("curvature_client.client.time.sleep", lambda s: None)
    script = Script(lambda r: httpx.Response(404, json={"title": "Job not found",
                                                        "status": 404}))
    with pytest.raises(CurvatureAPIError) as caught:
        script.client().wait("j1", progress=False)
    assert caught.value.status == 404 and len(script.requests) == 1


def test_result_formats_and_download(tmp_path):
    arrays = {"points": np.arange(12.0).reshape(4, 3), "k1": np.array([1.0, np.nan, 2, 3]),
              "status": np.array([0, 2, 0, 0], np.int8)}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)

    def handler(request):
        fmt = request.url.params["format"]
        if fmt == "npz":
            return httpx.Response(200, content=buffer.getvalue())
        if fmt == "json":
            return httpx.Response(200, json={"fields": {}})
        return httpx.Response(200, content=f"{fmt} bytes".encode())

    client = Script(handler).client()
    res = client.result("j1")
    assert sorted(res) == ["k1", "points", "status"] and res.n_points == 4
    assert np.array_equal(res.k1, arrays["k1"], equal_nan=True) and res.status.dtype == np.int8
    with pytest.raises(AttributeError, match="no 'mean' array"):
        res.mean  # noqa: B018
    assert client.result("j1", "json") == {"fields": {}}
    assert client.result("j1", "ply") == b"ply bytes"
    target = client.result("j1", path=tmp_path / "out.csv")
    assert target.read_bytes() == b"csv bytes"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary file left
    with pytest.raises(ValueError, match="cannot tell the result format"):
        client.result("j1", path=tmp_path / "out.txt")
    with pytest.raises(ValueError, match="format must be one of"):
        client.result("j1", "xml")


def test_failed_download_leaves_no_file(tmp_path):
    script = Script(lambda r: httpx.Response(409, json={"title": "Result not ready",
                                                        "status": 409}))
    with pytest.raises(CurvatureAPIError, match="409 Result not ready"):
        script.client().result("j1", path=tmp_path / "out.ply")
    assert list(tmp_path.iterdir()) == []


def test_cancel_and_delete():
    answers = [httpx.Response(200, json=job_doc("cancelled")), httpx.Response(204)]
    script = Script(lambda r: answers.pop(0))
    client = script.client()
    assert client.cancel("j1").status == "cancelled"
    assert client.cancel(Job(id="j1", status="succeeded")) is None
    assert [r.method for r in script.requests] == ["DELETE", "DELETE"]


def test_jobs_follows_pages():
    def handler(request):
        cursor = request.url.params.get("cursor")
        if cursor is None:
            return httpx.Response(200, json={"items": [job_doc(), job_doc()],
                                             "next_cursor": "5"})
        return httpx.Response(200, json={"items": [job_doc("succeeded")], "next_cursor": None})

    jobs = Script(handler).client().jobs()
    assert [j.status for j in jobs] == ["queued", "queued", "succeeded"]
    assert len(Script(handler).client().jobs(limit=2)) == 2


def test_helpers():
    assert format_from_path("a/b.PLY") == "ply"
    with pytest.raises(TypeError, match="Job or a job id"):
        CurvatureClient("http://x").get(42)
    with pytest.raises(ValueError):
        parse_npz(b"not a zip")


def test_progress_bar_on_a_terminal_redraws_one_line():
    class Tty(io.StringIO):
        def isatty(self):
            return True

    stream = Tty()
    bar = JobProgressBar("abc", stream)
    bar.update("running", 0.5)
    bar.update("succeeded", 1.0)
    bar.close()
    text = stream.getvalue()
    assert text.count("\r") == 2 and text.endswith("\n") and text.count("\n") == 1
    assert "[###############...............]  50.0%" in text
