"""``params`` without a method are the default method's; errors name method and parameter."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from service_helpers import sphere, wait_for_job

import curvature


@pytest.mark.parametrize("params", [{}, {"k": 24}, {"k": 96}, {"orientation": "auto"}])
def test_params_without_a_method_are_the_default_methods(client, params):
    response = client.post("/v1/jobs", json={"points": sphere(200).tolist(), "params": params})
    assert response.status_code == 202, response.text
    job = wait_for_job(client, response.json()["id"])
    assert job["status"] == "succeeded", job
    assert job["method"] == curvature.DEFAULT_METHOD == "auto"
    assert job["params"]["k"] == params.get("k", 1536)


def test_an_upload_without_a_method_is_the_default_method(client):
    text = "\n".join(" ".join(map(str, p)) for p in sphere(150).tolist())
    response = client.post("/v1/jobs", files={"file": ("s.xyz", text.encode())},
                           data={"params": json.dumps({"normal_k": 20})})
    assert response.status_code == 202, response.text
    assert response.json()["method"] == "auto"


@pytest.mark.parametrize("params, detail", [
    ({"k": 10}, "params.k: method 'auto': parameter 'k' must be >= 24, got 10; allowed: 24 to "
                "4096"),
    ({"k": 5000}, "params.k: method 'auto': parameter 'k' must be <= 4096, got 5000; allowed: "
                  "24 to 4096"),
    ({"method": "knn", "k": 0}, "params.k: method 'knn': parameter 'k' must be >= 5, got 0"),
    ({"method": "knn", "k": 5.5},
     "params.k: method 'knn': parameter 'k' must be a whole number, got 5.5"),
    ({"method": "knn", "k": "many"}, "params.k: method 'knn': parameter 'k' must be int, "
                                     "got 'many'"),
    ({"method": "tc", "k": 5}, "params.k: method 'tc': unknown parameter(s) ['k']; accepted: "),
    ({"method": "auto", "fit": "monge"},
     "params.fit: method 'auto' chooses its own fit; fit 'monge' needs a neighborhood method"),
    ({"method": "knn", "fit": "cubic"}, "params.fit: method 'knn': unknown fit 'cubic'; "
                                        "choose one of ['adaptive', 'implicit', 'monge', 'nfr']"),
    ({"method": "knn", "solver": "qr"}, "params.solver: method 'knn': parameter 'solver' "
                                        "must be one of ['taubin', 'algebraic'], got 'qr'"),
    ({"method": "egg", "orientation": "up"},
     "params.orientation: method 'egg': unknown orientation 'up'; choose one of"),
    ({"method": "knn", "viewpoint": [1]},
     "params.viewpoint.1: method 'knn': parameter 'viewpoint': field required"),
    ({"method": "paper"}, "params: unknown method 'paper'; choose one of ['auto', "),
    ([1, 2], "params: params must be a JSON object, got list"),
])
def test_every_parameter_error_names_the_method_and_the_parameter(client, params, detail):
    response = client.post("/v1/curvature", json={"points": sphere(50).tolist(),
                                                  "params": params})
    assert response.status_code == 422
    problem = response.json()
    assert problem["type"].endswith("/invalid-parameters")
    assert problem["detail"].startswith(detail), problem["detail"]


def test_the_library_says_the_same_for_a_bound(client):
    with pytest.raises(curvature.ParameterError) as raised:
        curvature.estimate(sphere(50), "knn", k=0)
    response = client.post("/v1/curvature", json={"points": sphere(50).tolist(),
                                                  "params": {"method": "knn", "k": 0}})
    assert response.json()["detail"] == f"params.k: {raised.value}"


def test_the_job_pages_placeholder_is_valid_for_every_method_with_that_parameter(client):
    # what a user who types the hint as it stands gets: a job, not a 422
    page = client.get("/ui").text
    hint = json.loads(re.search(r"id=\"extra-params\"[^>]*placeholder='([^']*)'", page)[1])
    methods = {m["name"]: {p["name"] for p in m["parameters"]}
               for m in client.get("/v1/methods").json()["methods"]}
    takers = [name for name, names in methods.items() if set(hint) <= names]
    assert "auto" in takers and "knn" in takers, takers
    # noisy, so that auto takes its noisy branch, the one k sizes
    points = sphere(400) + np.random.default_rng(5).normal(scale=0.02, size=(400, 3))
    for params in [hint] + [{"method": name, **hint} for name in takers]:
        response = client.post("/v1/curvature", json={"points": points.tolist(),
                                                      "params": params})
        assert response.status_code == 200, (params, response.text)
        # honoured as given: no fit uses more neighbors than k
        assert max(response.json()["fields"]["neighbor_count"]) <= hint["k"], params
