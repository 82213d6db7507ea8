"""Executor "dask": jobs run as tile tasks on a real distributed.LocalCluster (processes)."""

from __future__ import annotations

import io
import os
import signal
import time

import distributed
import numpy as np
import pytest
from fastapi.testclient import TestClient
from service_helpers import (
    KEY_A,
    bearer,
    changed_executor,
    free_port,
    make_settings,
    wait_for_job,
    wait_ready,
)

import curvature
from curvature import synthetic
from service.app import create_app

TILE_POINTS = 1000


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=40) as cluster, \
            distributed.Client(cluster, set_as_default=False) as client:
        yield cluster, client


@pytest.fixture(scope="module")
def dask_app(cluster, tmp_path_factory):
    settings = make_settings(tmp_path_factory.mktemp("dask-service"), executor="dask",
                             dask_address=cluster[0].scheduler_address,
                             dask_tile_points=TILE_POINTS, workers=1)
    with TestClient(create_app(settings), raise_server_exceptions=False,
                    headers=bearer(KEY_A)) as client:
        wait_ready(client)
        yield client


def submit(client, points, params=None) -> dict:
    body = {"points": points.tolist()} | ({"params": params} if params else {})
    response = client.post("/v1/jobs", json=body)
    assert response.status_code == 202, response.text
    return response.json()


def result_npz(client, job_id) -> dict:
    response = client.get(f"/v1/jobs/{job_id}/result?format=npz")
    assert response.status_code == 200, response.text
    with np.load(io.BytesIO(response.content)) as npz:
        return {name: npz[name] for name in npz.files}


def executed(client) -> int:
    counts = client.run(lambda dask_worker: dask_worker.state.executed_count)
    return sum(counts.values())


def assert_same_result(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for name in set(a) - {"info"}:  # info holds timings and the tile count
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_a_job_on_the_cluster_equals_the_local_pool(cluster, dask_app, app_client):
    _, dask_client = cluster
    points = synthetic.torus(6000, noise=0.3, seed=4).points
    before = executed(dask_client)
    remote = wait_for_job(dask_app, submit(dask_app, points)["id"])
    assert remote["status"] == "succeeded", remote
    assert remote["result"]["tiles"] == 6
    assert executed(dask_client) - before >= 6  # the tiles ran on the cluster's workers
    local = wait_for_job(app_client, submit(app_client, points)["id"])
    assert local["status"] == "succeeded" and local["result"]["tiles"] is None
    assert_same_result(result_npz(dask_app, remote["id"]), result_npz(app_client, local["id"]))


def test_other_methods_match_too(dask_app):
    points = synthetic.saddle(3000, noise=0.0, seed=2).points
    params = {"method": "tc", "fit": "monge", "min_neighbors": 16}
    job = wait_for_job(dask_app, submit(dask_app, points, params)["id"])
    assert job["status"] == "succeeded" and job["result"]["tiles"] == 3
    expected = curvature.estimate(points, "tc", fit="monge", min_neighbors=16, workers=1)
    got = result_npz(dask_app, job["id"])
    np.testing.assert_array_equal(got["k1"], expected.k1)
    np.testing.assert_array_equal(got["normals"], expected.normals)


def wait_progress(client, job_id, above: float, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] != "queued" and (job["progress"] > above or job["status"] != "running"):
            return job
        time.sleep(0.02)
    pytest.fail(f"job {job_id} made no progress past {above}")


def kill_a_busy_worker(client, timeout: float = 60.0) -> int:
    """SIGKILL a worker process while it computes a tile; returns its pid."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        busy = [addr for addr, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            return pid
        time.sleep(0.01)
    pytest.fail("no worker was ever busy")


def big_cloud():
    return synthetic.torus(30000, noise=0.3, seed=5).points


def test_a_killed_worker_does_not_lose_the_job(cluster, dask_app):
    _, dask_client = cluster
    points = big_cloud()
    job = submit(dask_app, points)
    running = wait_progress(dask_app, job["id"], 0.06)  # a first tile is in
    assert running["status"] == "running", running
    kill_a_busy_worker(dask_client)
    done = wait_for_job(dask_app, job["id"], timeout=300)
    assert done["status"] == "succeeded", done
    assert done["attempts"] == 1  # the same run went on: only the lost tiles were redone
    expected = curvature.estimate(points)
    got = result_npz(dask_app, job["id"])
    np.testing.assert_array_equal(got["k1"], expected.k1)
    np.testing.assert_array_equal(got["k2"], expected.k2)
    np.testing.assert_array_equal(got["normals"], expected.normals)
    dask_client.wait_for_workers(2, timeout=60)  # the nanny restarted it


def test_cancel_cancels_the_tiles_on_the_cluster(cluster, dask_app):
    _, dask_client = cluster
    job = submit(dask_app, big_cloud())
    assert wait_progress(dask_app, job["id"], 0.06)["status"] == "running"
    response = dask_app.delete(f"/v1/jobs/{job['id']}")
    assert response.status_code in (200, 202), response.text
    assert wait_for_job(dask_app, job["id"])["status"] == "cancelled"
    deadline = time.monotonic() + 30
    while dask_client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)):
        assert time.monotonic() < deadline, "tiles of a cancelled job stayed on the cluster"
        time.sleep(0.1)


def test_an_unreachable_scheduler_fails_the_job_clearly(dask_app):
    address = f"tcp://127.0.0.1:{free_port()}"
    with changed_executor(dask_app, dask_address=address, dask_connect_seconds=1.0):
        job = wait_for_job(dask_app, submit(dask_app, synthetic.sphere(500).points)["id"])
    assert job["status"] == "failed"
    assert job["error"]["type"] == "/problems/cluster-unavailable"
    assert address in job["error"]["detail"]


def test_compose_dask_profile_points_the_service_at_its_scheduler():
    import yaml
    from service_helpers import REPO

    from service.settings import Settings

    services = yaml.safe_load((REPO / "docker-compose.yml").read_text())["services"]
    env = services["curvature"]["environment"]
    address = env["CURVATURE_DASK_ADDRESS"]
    host, port = address.removeprefix("tcp://").split(":")
    assert services[host]["profiles"] == ["dask"]
    assert ["--port", port] == services[host]["command"][2:4]
    workers = [s for name, s in services.items() if name.startswith("dask-worker")]
    assert len(workers) == 2
    for worker in workers:
        assert address in worker["command"] and worker["profiles"] == ["dask"]
        assert worker["volumes"] == services["curvature"]["volumes"]  # the shared data volume
    settings = {k.removeprefix("CURVATURE_").lower() for k in env}
    assert settings <= set(Settings.model_fields)
