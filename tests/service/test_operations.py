"""GET /v1/methods, probes, metrics, and the synchronous endpoint."""

from __future__ import annotations

import io
import json
import re

import numpy as np
from service_helpers import sphere

import curvature


def test_methods_lists_every_core_method_with_bounds(client):
    doc = client.get("/v1/methods").json()
    names = [m["name"] for m in doc["methods"]]
    assert names == ["auto", *sorted(curvature.FINDERS)]
    assert doc["default_method"] == curvature.DEFAULT_METHOD == "auto"
    for method in doc["methods"]:
        params = (curvature.AUTO_PARAMS if method["name"] == "auto"
                  else curvature.FINDERS[method["name"]].PARAMS)
        specs = {s.name: s for s in params}
        assert [p["name"] for p in method["parameters"]] == list(specs)
        for param in method["parameters"]:
            spec = specs[param["name"]]
            assert param["default"] == spec.default
            assert param["minimum"] == spec.minimum and param["maximum"] == spec.maximum
            assert param["type"] == spec.kind.__name__
    knn = next(m for m in doc["methods"] if m["name"] == "knn")
    assert knn["parameters"][0] | {"help": ""} == {
        "name": "k", "type": "int", "default": 24, "minimum": 5, "maximum": 1024,
        "choices": None, "help": "", "applies_to_fit": None}
    fits = {f["name"]: f for f in doc["fits"]}
    assert set(fits) == set(curvature.FITS)
    solver = next(p for p in fits["implicit"]["parameters"] if p["name"] == "solver")
    assert solver["choices"] == ["taubin", "algebraic"]
    assert not any(p["name"] == "solver" for p in fits["monge"]["parameters"])
    assert doc["orientations"] == list(curvature.ORIENTATIONS)
    assert doc["result_formats"] == ["json", "ply", "csv", "npz", "las", "laz"]
    assert "ply" in doc["input_formats"]


def test_every_method_runs_through_the_api(client):
    for name in sorted(curvature.FINDERS):
        params = {"method": name}
        if name == "knn":
            params["k"] = 8
        response = client.post("/v1/curvature", json={"points": sphere(150).tolist(),
                                                      "params": params})
        assert response.status_code == 200, (name, response.text)
        assert response.json()["n"] == 150


def test_health_and_readiness(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {"status": "ready",
                            "checks": {"store": True, "data_dir": True, "pool": True}}


def test_metrics_are_prometheus_text(client):
    client.get("/v1/methods")
    client.get("/v1/jobs/not-a-job")
    response = client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"] == "text/plain; version=0.0.4; charset=utf-8"
    text = response.text
    sample = re.compile(r'^[a-z_]+(\{[a-z_]+="[^"]*"(,[a-z_]+="[^"]*")*\})? -?[0-9.e+-]+$')
    for line in text.splitlines():
        assert line.startswith("# ") or sample.match(line), line
    assert 'curvature_http_requests_total{method="GET",route="/v1/methods",status="200"}' in text
    assert 'curvature_problems_total{type="job-not-found"}' in text
    assert re.search(r'^curvature_jobs\{status="queued"\} \d', text, re.M)
    assert "curvature_pool_workers 2" in text
    assert "curvature_ready 1" in text


def test_sync_curvature_json_default_and_formats(client, mesh_ply, tmp_path):
    pts = sphere(200)
    response = client.post("/v1/curvature", json={"points": pts.tolist(),
                                                  "params": {"method": "knn", "k": 10}})
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/json"
    doc = response.json()
    assert np.allclose(np.median(np.array(doc["fields"]["k1"], float)), 0.5, rtol=0.05)
    with open(mesh_ply, "rb") as fh:
        response = client.post("/v1/curvature?format=ply", files={"file": ("m.ply", fh)},
                               data={"params": json.dumps({"method": "knn", "k": 8})})
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/x-ply"
    path = tmp_path / "sync.ply"
    path.write_bytes(response.content)
    assert np.array_equal(curvature.read(path).faces, curvature.read(mesh_ply).faces)
    response = client.post("/v1/curvature", json={"points": pts.tolist()},
                           headers={"Accept": "application/x-npz"})
    with np.load(io.BytesIO(response.content)) as data:
        assert data["k2"].shape == (200,)
    # Scratch files of synchronous requests are removed once answered.
    assert not any(client.app.state.settings.tmp_dir.iterdir())
