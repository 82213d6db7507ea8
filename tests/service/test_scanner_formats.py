"""Scanner files through the service: E57 in, LAS/LAZ and PLY out, every field kept."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from service_helpers import wait_for_job

import curvature

pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
pytest.importorskip("laspy", reason="LAS needs the 'formats' extra (laspy, lazrs)")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "core"))
from scanner_files import e57_file  # noqa: E402


@pytest.fixture(scope="module")
def e57_job(app_client, tmp_path_factory):
    path = tmp_path_factory.mktemp("e57") / "room.e57"
    # two scans, two poses: each sphere is seen from its own centre
    e57_file(path, scans=((0.2, -0.1, 0.3), (3.0, 0.5, -0.2)), n=300, invalid_every=11,
             rotations=[(1.0, 0.0, 0.0, 0.0), (np.cos(0.3), np.sin(0.3), 0.0, 0.0)])
    cloud = curvature.read(path)
    response = app_client.post("/v1/jobs", files={"file": ("room.e57", path.read_bytes())},
                               data={"params": json.dumps({"method": "knn", "k": 12})})
    assert response.status_code == 202, response.text
    return wait_for_job(app_client, response.json()["id"]), cloud


@pytest.mark.parametrize("fmt", ["las", "laz", "ply"])
def test_e57_to_las_laz_ply_keeps_every_field(client, e57_job, fmt, tmp_path):
    job, cloud = e57_job
    assert job["status"] == "succeeded", job
    response = client.get(f"/v1/jobs/{job['id']}/result?format={fmt}")
    assert response.status_code == 200, response.text
    path = tmp_path / f"result.{fmt}"
    path.write_bytes(response.content)
    back = curvature.io.read_result(path)
    np.testing.assert_allclose(back.points, cloud.points, atol=1e-6)
    np.testing.assert_array_equal(back.index, cloud.index)
    assert set(cloud.properties) == {"intensity", "red", "green", "blue", "scan"}
    for name, values in cloud.properties.items():
        # LAS colours are 16-bit: 8-bit channels come back scaled by 257 (255 -> 65535)
        scale = 257 if fmt != "ply" and name in ("red", "green", "blue") else 1
        np.testing.assert_array_equal(back.attributes[name], values.astype(np.int64) * scale
                                      if scale != 1 else values, err_msg=name)
    local = curvature.estimate(cloud, "knn", k=12)
    for name in ("k1", "k2", "mean", "gaussian", "residual", "normals", "dir1", "dir2",
                 "status", "neighbor_count"):
        np.testing.assert_array_equal(getattr(back, name), getattr(local, name), err_msg=name)
    # each scanner sat inside its sphere: normals facing it point in, so H < 0 on both scans
    for scan in (0, 1):
        ok = (back.status == 0) & (back.attributes["scan"] == scan)
        assert np.mean(back.mean[ok] < 0) > 0.99, scan


def test_las_is_offered_by_accept_header(client, e57_job):
    job, _ = e57_job
    response = client.get(f"/v1/jobs/{job['id']}/result",
                          headers={"Accept": "application/vnd.laszip"})
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/vnd.laszip"
    assert response.content[:4] == b"LASF"


def test_corrupt_e57_upload_is_a_clear_problem(client):
    response = client.post("/v1/jobs", files={"file": ("bad.e57", b"ASTM-E57" + b"\0" * 60)})
    if response.status_code == 202:
        job = wait_for_job(client, response.json()["id"])
        assert job["status"] == "failed" and "bad.e57" in job["error"]["detail"], job
    else:
        assert response.status_code == 422, response.text
        assert "bad.e57" in response.json()["detail"]
