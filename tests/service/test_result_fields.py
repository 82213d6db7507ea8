"""A result one field at a time (GET /v1/jobs/{id}/result/fields[/{name}] and
/result/points/{index}): the same values as the JSON result, in float32 or exact, with errors
as problem documents, read from the stored archive in chunks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from service_helpers import KEY_B, bearer, wait_for_job

import curvature
from curvature.io import table_of
from service import result_fields
from service.result_files import save_canonical


def assert_problem(response, status: int, slug: str) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    doc = response.json()
    assert doc["type"] == f"/problems/{slug}" and doc["status"] == status
    return doc


@pytest.fixture(scope="module")
def scan_job(app_client, scans):
    """A thinned real scan in its sensor's frame (PCL table scene, every 40th point)."""
    points = curvature.read(scans / "table_scene_mug_stereo_textured.pcd").points[::40]
    response = app_client.post("/v1/jobs", json={
        "points": points.tolist(), "params": {"method": "knn", "k": 10, "fit": "monge"}})
    assert response.status_code == 202, response.text
    job = wait_for_job(app_client, response.json()["id"])
    assert job["status"] == "succeeded", job
    return job["id"], len(points)


@pytest.fixture(scope="module")
def json_result(app_client, scan_job):
    return app_client.get(f"/v1/jobs/{scan_job[0]}/result?format=json").json()


def test_listing_has_the_json_results_fields_in_order_with_units(client, scan_job,
                                                                  json_result):
    job_id, n = scan_job
    doc = client.get(f"/v1/jobs/{job_id}/result/fields").json()
    assert doc["n"] == n == json_result["n"]
    assert [f["name"] for f in doc["fields"]] == list(json_result["fields"])
    entries = {f["name"]: f for f in doc["fields"]}
    assert entries["points"]["components"] == 3 and entries["k1"]["components"] == 1
    assert entries["mean"]["unit"] == "1/length unit" and entries["mean"]["scale"] == "diverging"
    assert entries["gaussian"]["unit"] == "1/length unit²"
    assert entries["status"]["scale"] == "categorical"
    assert entries["status"]["categories"]["0"] == "ok"
    assert entries["shape_index"]["limits"] == [-1.0, 1.0]
    # the standard errors (issue 16), for the viewer's "color by the standard error"
    for name in ("k1_std", "k2_std", "mean_std"):
        assert entries[name]["unit"] == "1/length unit" and entries[name]["scale"] == "sequential"
    assert "uncertain" in entries
    # A scanner's camera frame: up is about -y (the table's normal, towards the sensor).
    assert np.dot(doc["up"], [0, -1, 0]) > 0.8 and np.isclose(np.linalg.norm(doc["up"]), 1)


def test_every_field_is_the_json_result_in_float32(client, scan_job, json_result):
    job_id, n = scan_job
    for name, values in json_result["fields"].items():
        response = client.get(f"/v1/jobs/{job_id}/result/fields/{name}")
        assert response.status_code == 200, (name, response.text)
        assert response.headers["content-type"] == "application/octet-stream"
        width = 3 if isinstance(values[0], list) else 1
        assert response.headers["x-points"] == str(n)
        assert response.headers["x-components"] == str(width)
        got = np.frombuffer(response.content, dtype="<f4")
        expected = np.array([np.nan if v is None else v for v in np.ravel(
            [[np.nan if c is None else c for c in v] if width == 3 else v for v in values])],
            dtype=np.float64).astype(np.float32)
        assert np.array_equal(got, expected, equal_nan=True), name


def test_a_point_has_every_field_exactly_as_the_json_result(client, scan_job, json_result):
    job_id, n = scan_job
    for index in (0, n // 2, n - 1):
        doc = client.get(f"/v1/jobs/{job_id}/result/points/{index}").json()
        assert doc["index"] == index
        assert doc["fields"] == {k: v[index] for k, v in json_result["fields"].items()}


def test_colors_and_nan_come_through(tmp_path):
    """A result with packed colors, NaN curvature and an input index, saved as the service
    saves it: the fields and one point equal the library's table (the JSON result's source),
    also when converted in many small chunks."""
    rng = np.random.default_rng(0)
    n = 500
    k1 = rng.normal(size=n)
    k2 = k1 - np.abs(rng.normal(size=n))
    k1[7] = k2[7] = np.nan
    status = np.zeros(n, np.int8)
    status[7] = 2
    result = curvature.CurvatureResult(
        points=rng.normal(size=(n, 3)), k1=k1, k2=k2, mean=(k1 + k2) / 2, gaussian=k1 * k2,
        normals=rng.normal(size=(n, 3)), dir1=rng.normal(size=(n, 3)),
        dir2=rng.normal(size=(n, 3)), neighbor_count=np.full(n, 12, np.int32), status=status,
        residual=rng.random(n), attributes={
            "rgba": rng.integers(0, 2**32, n, dtype=np.uint32),
            "intensity": rng.random(n).astype(np.float32), "index": np.arange(n)[::-1].copy()})
    digest = save_canonical(result, tmp_path / "result.npz")
    table = table_of(result)
    doc = result_fields.manifest(tmp_path, digest)
    assert [f["name"] for f in doc["fields"]] == list(table.fields)
    assert {"red", "green", "blue", "alpha", "intensity"} <= set(table.fields)
    values = result_fields.point_values(tmp_path, 7, digest)
    assert values["k1"] is None and values["shape_index"] is None and values["status"] == 2
    assert values["index"] == n - 1 - 7 and values["red"] == int(table.fields["red"][7])
    old_chunk = result_fields.CHUNK_ROWS
    result_fields.CHUNK_ROWS = 64
    try:
        for name, array in table.fields.items():
            path, entry = result_fields.field_file(tmp_path, name, digest)
            got = np.fromfile(path, dtype="<f4")
            assert np.array_equal(got, np.asarray(array, np.float32).ravel(), equal_nan=True)
    finally:
        result_fields.CHUNK_ROWS = old_chunk


def test_conversions_are_kept_and_dropped_with_a_new_result(tmp_path, monkeypatch):
    result = curvature.estimate(curvature.synthetic.sphere(300, seed=2).points, "knn", k=12,
                                fit="monge")
    digest = save_canonical(result, tmp_path / "result.npz")
    first, _ = result_fields.field_file(tmp_path, "k1", digest)
    calls = []
    original = result_fields.catalog
    monkeypatch.setattr(result_fields, "catalog", lambda path: calls.append(path) or
                        original(path))
    again, _ = result_fields.field_file(tmp_path, "k1", digest)
    assert again == first and calls == []  # neither the archive nor the checksum read again
    # A recomputed result (another archive) makes the listing and the conversions anew.
    scaled = curvature.CurvatureResult(**{**result.fields(), "points": result.points * 2,
                                          "k1": result.k1 / 2})
    digest2 = save_canonical(scaled, tmp_path / "result.npz")
    path, _ = result_fields.field_file(tmp_path, "k1", digest2)
    assert np.allclose(np.fromfile(path, "<f4"), result.k1 / 2, rtol=1e-6)
    with pytest.raises(result_fields.ResultCorrupt):
        result_fields.manifest(tmp_path, digest)  # the old digest no longer matches


def test_unknown_field_and_bad_names_and_indices_are_problems(client, scan_job):
    job_id, n = scan_job
    doc = assert_problem(client.get(f"/v1/jobs/{job_id}/result/fields/curliness"), 404,
                         "field-not-found")
    assert "curliness" in doc["detail"] and "/result/fields" in doc["detail"]
    assert_problem(client.get(f"/v1/jobs/{job_id}/result/fields/a%20b"), 422, "invalid-request")
    doc = assert_problem(client.get(f"/v1/jobs/{job_id}/result/points/{n}"), 404,
                         "point-not-found")
    assert f"0 to {n - 1}" in doc["detail"]
    assert_problem(client.get(f"/v1/jobs/{job_id}/result/points/-1"), 422, "invalid-request")
    assert_problem(client.get(f"/v1/jobs/{job_id}/result/points/x"), 422, "invalid-request")


def test_other_keys_missing_keys_and_missing_jobs(client, scan_job):
    job_id = scan_job[0]
    for path in ("fields", "fields/k1", "points/0"):
        url = f"/v1/jobs/{job_id}/result/{path}"
        assert_problem(client.get(url, headers=bearer(KEY_B)), 404, "job-not-found")
        assert_problem(client.get(url, headers={"Authorization": ""}), 401, "unauthorized")
        assert_problem(client.get(f"/v1/jobs/nope/result/{path}"), 404, "job-not-found")


def test_unfinished_failed_and_lost_results(client):
    buffer = __import__("io").BytesIO()
    np.save(buffer, np.random.default_rng(5).normal(size=(400_000, 3)))
    response = client.post("/v1/jobs", files={"file": ("big.npy", buffer.getvalue())},
                           data={"params": json.dumps({"method": "knn", "k": 30})})
    job_id = response.json()["id"]
    try:
        assert_problem(client.get(f"/v1/jobs/{job_id}/result/fields"), 409, "result-not-ready")
    finally:
        client.delete(f"/v1/jobs/{job_id}")
    assert_problem(client.get(f"/v1/jobs/{job_id}/result/fields/k1"), 409, "job-cancelled")
    failed = client.post("/v1/jobs", files={"file": ("bad.xyz", b"1 2 3\n4 5\n")})
    job = wait_for_job(client, failed.json()["id"])
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result/points/0"), 409, "job-failed")
    # A lost result is computed again from the kept input (503 with Retry-After meanwhile).
    done = client.post("/v1/jobs", json={"points": curvature.synthetic.sphere(
        200, seed=1).points.tolist()})
    job_id = wait_for_job(client, done.json()["id"])["id"]
    (client.app.state.settings.jobs_dir / job_id / "result.npz").write_bytes(b"garbage")
    doc = assert_problem(client.get(f"/v1/jobs/{job_id}/result/fields"), 503, "result-corrupt")
    assert "computed again" in doc["detail"] or "queued" in doc["detail"]
    assert wait_for_job(client, job_id)["status"] == "succeeded"
    assert client.get(f"/v1/jobs/{job_id}/result/fields/k1").status_code == 200
