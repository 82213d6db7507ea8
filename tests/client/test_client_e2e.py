"""The client and ``curvature remote`` against a real service process."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from service_helpers import ServerProcess, free_port, grid_mesh

import curvature
from curvature.cli import main
from curvature.io import read_result
from curvature_client import (
    CurvatureAPIError,
    CurvatureClient,
    CurvatureConnectionError,
    JobCancelledError,
    JobFailedError,
    JobTimeoutError,
    RemoteResult,
)

PARAMS = {"k": 12, "fit": "monge"}
SERVICE_KEYS = ("client-test-key-one-0123456789", "client-test-key-two-0123456789")
FIELDS = ("k1", "k2", "mean", "gaussian", "normals", "dir1", "dir2", "residual", "status",
          "neighbor_count")


@pytest.fixture(scope="module")
def keyed_server(tmp_path_factory):
    """A service that requires one of :data:`SERVICE_KEYS`."""
    root = tmp_path_factory.mktemp("client-keyed-server")
    proc = ServerProcess(root / "data", root / "server.log",
                         api_keys=",".join(SERVICE_KEYS)).start()
    yield proc
    proc.stop()


@pytest.fixture(scope="module")
def cloud():
    return curvature.synthetic.torus(1500, major=2.0, minor=0.6, noise=0.05, seed=4).points


@pytest.fixture(scope="module")
def local(cloud):
    return curvature.estimate(cloud, "knn", **PARAMS)


def big_cloud(n=300_000):
    return np.random.default_rng(1).normal(size=(n, 3))


def assert_same_result(remote, local):
    assert np.array_equal(remote["points"], local.points)
    for name in FIELDS:
        assert np.array_equal(remote[name], getattr(local, name), equal_nan=True), name


def test_submit_array_wait_and_get_the_librarys_arrays(server, cloud, local):
    with CurvatureClient(server.url) as client:
        job = client.submit(cloud, "knn", **PARAMS)
        assert job.status in ("queued", "running", "succeeded")
        stream = io.StringIO()
        done = client.wait(job, stream=stream)
        assert done.status == "succeeded" and done.n_points == len(cloud)
        assert f"job {job.id} succeeded" in stream.getvalue()
        result = client.result(job)
    assert isinstance(result, RemoteResult)
    assert_same_result(result, local)  # bit for bit: same library, same float64 input


def test_mesh_file_result_as_ply_file_and_json(server, tmp_path):
    pts, faces = grid_mesh(20, 16)
    source = tmp_path / "bump.ply"
    curvature.write(source, curvature.PointCloud(points=pts, faces=faces))
    local = curvature.estimate(curvature.read(source), "mesh")
    with CurvatureClient(server.url) as client:
        job = client.wait(client.submit(source, "mesh"), progress=False)
        path = client.result(job, path=tmp_path / "bump_curvature.ply")
        doc = client.result(job, "json")
    back = read_result(path)
    assert np.array_equal(back.faces, faces)
    assert np.allclose(back.k1, local.k1, equal_nan=True, rtol=1e-6, atol=1e-9)
    assert len(doc["fields"]["k1"]) == len(pts)


def test_preview_through_the_client(server, cloud, tmp_path):
    with CurvatureClient(server.url) as client:
        job = client.wait(client.submit(cloud, "knn", **PARAMS), progress=False)
        png = client.preview(job, "gaussian", view="top")
        path = client.preview(job, "gaussian", view="top", path=tmp_path / "p.png")
    assert Image.open(io.BytesIO(png)).size == (800, 600)
    assert path.read_bytes() == png  # the cached picture
    with CurvatureClient(server.url) as client:
        assert client.preview(job, "gaussian", view="top", up="x") != png
        with pytest.raises(ValueError, match="up must be one of"):
            client.preview(job, up="w")


def test_fields_one_at_a_time_through_the_client(server, cloud, local):
    with CurvatureClient(server.url) as client:
        job = client.wait(client.submit(cloud, "knn", **PARAMS), progress=False)
        listing = client.fields(job)
        k1 = client.field(job, "k1")
        normals = client.field(job, "normals")
        point = client.point(job, 3)
        with pytest.raises(CurvatureAPIError) as caught:
            client.field(job, "nothing")
    assert listing["n"] == len(cloud) and listing["fields"][0]["name"] == "points"
    assert k1.dtype == np.float32 and np.array_equal(k1, local.k1.astype(np.float32),
                                                     equal_nan=True)
    assert normals.shape == (len(cloud), 3)
    assert point["k1"] == local.k1[3] and point["normals"] == local.normals[3].tolist()
    assert caught.value.status == 404 and caught.value.type == "/problems/field-not-found"


def test_cancel_a_running_job(server):
    with CurvatureClient(server.url) as client:
        job = client.submit(big_cloud(), "knn", k=30)
        cancelled = client.cancel(job)
        assert cancelled.status == "cancelled"
        with pytest.raises(JobCancelledError):
            client.wait(job, progress=False, timeout=60)
        with pytest.raises(CurvatureAPIError) as caught:
            client.result(job)
        assert caught.value.status == 409 and caught.value.type == "/problems/job-cancelled"
        assert client.cancel(job) is None  # a finished job is deleted
        with pytest.raises(CurvatureAPIError) as caught:
            client.get(job)
        assert caught.value.status == 404


def test_wait_timeout_leaves_the_job_running(server):
    with CurvatureClient(server.url) as client:
        job = client.submit(big_cloud(), "knn", k=30)
        try:
            with pytest.raises(JobTimeoutError) as caught:
                client.wait(job, progress=False, timeout=0.2)
            assert not caught.value.job.is_final
            assert not client.get(job).is_final
        finally:
            client.cancel(job)


def test_errors_carry_the_problem_document(server, tmp_path):
    with CurvatureClient(server.url) as client:
        with pytest.raises(CurvatureAPIError) as caught:
            client.submit(np.zeros((20, 3)), "knn", k=0)
        err = caught.value
        assert err.status == 422 and err.type == "/problems/invalid-parameters"
        assert "k" in err.detail and err.problem["status"] == 422
        assert "Invalid parameters" in str(err)

        with pytest.raises(CurvatureAPIError) as caught:
            client.get("no-such-job")
        assert caught.value.status == 404 and caught.value.type == "/problems/job-not-found"

        broken = tmp_path / "broken.ply"
        broken.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 50\nproperty float x\n"
                           b"property float y\nproperty float z\nend_header\n1 2 3\n")
        job = client.submit(broken)
        with pytest.raises(JobFailedError) as caught:
            client.wait(job, progress=False)
        assert caught.value.type == "/problems/malformed-file"
        assert "broken.ply" in caught.value.detail


def test_unreachable_service_is_a_connection_error():
    with CurvatureClient(f"http://127.0.0.1:{free_port()}", timeout=5) as client, \
            pytest.raises(CurvatureConnectionError):
        client.methods()


def test_api_keys_are_sent_and_jobs_are_private(keyed_server, cloud):
    with CurvatureClient(keyed_server.url) as anonymous, pytest.raises(CurvatureAPIError) as caught:
        anonymous.submit(cloud)
    assert caught.value.status == 401 and caught.value.type == "/problems/unauthorized"
    with CurvatureClient(keyed_server.url, api_key=SERVICE_KEYS[0]) as owner, \
            CurvatureClient(keyed_server.url, api_key=SERVICE_KEYS[1]) as other:
        job = owner.wait(owner.submit(cloud, "knn", **PARAMS), progress=False)
        assert [j.id for j in owner.jobs()] == [job.id]
        assert other.jobs() == []
        for call in (other.get, other.result, other.preview):
            with pytest.raises(CurvatureAPIError) as caught:
                call(job)
            assert caught.value.status == 404
        assert owner.preview(job)[:4] == b"\x89PNG"


# -- curvature remote ----------------------------------------------------------------------

def test_remote_submit_wait_writes_the_result(server, cloud, local, tmp_path, capsys):
    source = tmp_path / "torus.npy"
    np.save(source, cloud)
    out = tmp_path / "torus_curvature.ply"
    assert main(["remote", "submit", str(source), "--url", server.url, "--method", "knn",
                 "--k", "12", "--fit", "monge", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    job_id = captured.out.strip()
    assert len(job_id) > 8 and "\n" not in job_id
    assert f"job {job_id} succeeded: {len(cloud)} points" in captured.err
    assert "100.0%" in captured.err  # the progress bar followed the job
    back = read_result(out)
    assert np.allclose(back.k1, local.k1, equal_nan=True, rtol=1e-6, atol=1e-9)
    assert np.array_equal(back.status, local.status)

    assert main(["remote", "status", job_id, "--url", server.url]) == 0
    assert '"status": "succeeded"' in capsys.readouterr().out
    npz = tmp_path / "again.npz"
    assert main(["remote", "result", job_id, "--url", server.url, "-o", str(npz)]) == 0
    assert np.array_equal(read_result(npz).mean, local.mean, equal_nan=True)
    png = tmp_path / "p.png"
    assert main(["remote", "preview", job_id, "--url", server.url, "-o", str(png),
                 "--field", "k2"]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert main(["remote", "list", "--url", server.url]) == 0
    assert job_id in capsys.readouterr().out


def test_remote_errors_exit_1_with_the_problem(server, tmp_path, capsys):
    source = tmp_path / "c.npy"
    np.save(source, np.random.default_rng(0).normal(size=(30, 3)))
    code = main(["remote", "submit", str(source), "--url", server.url,
                 "--param", "k=0", "--wait"])
    assert code == 1
    err = capsys.readouterr().err
    assert "curvature remote submit: error: 422 Invalid parameters" in err
    assert "/problems/invalid-parameters" in err
    assert main(["remote", "submit", str(source), "--url", server.url, "--param", "k"]) == 2
    assert "expected NAME=VALUE" in capsys.readouterr().err
    assert main(["remote", "status", "nope", "--url", server.url]) == 1
    assert "404 Job not found" in capsys.readouterr().err
    # An output that cannot be written is refused before anything is submitted.
    before = len(CurvatureClient(server.url).jobs())
    assert main(["remote", "submit", str(source), "--url", server.url, "-o",
                 str(tmp_path / "out.txt")]) == 2
    assert "cannot tell the result format" in capsys.readouterr().err
    assert main(["remote", "submit", str(source), "--url", server.url, "-o",
                 str(tmp_path / "missing" / "out.ply")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert len(CurvatureClient(server.url).jobs()) == before


def test_remote_submit_uses_the_key_from_the_environment(keyed_server, tmp_path, capsys,
                                                         monkeypatch):
    source = tmp_path / "c.npy"
    np.save(source, np.random.default_rng(0).normal(size=(200, 3)))
    assert main(["remote", "submit", str(source), "--url", keyed_server.url, "-q"]) == 1
    assert "401 Unauthorized" in capsys.readouterr().err
    monkeypatch.setenv("CURVATURE_API_KEY", SERVICE_KEYS[1])
    monkeypatch.setenv("CURVATURE_URL", keyed_server.url)
    assert main(["remote", "submit", str(source), "--wait", "-q"]) == 0
    job_id = capsys.readouterr().out.strip()
    with CurvatureClient(keyed_server.url, api_key=SERVICE_KEYS[1]) as client:
        assert client.get(job_id).status == "succeeded"
