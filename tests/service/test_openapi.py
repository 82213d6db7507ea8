"""openapi/openapi.json stays equal to the app's spec (regenerate: scripts/export_openapi.py)."""

from __future__ import annotations

import json
import subprocess
import sys

from service_helpers import REPO

from service.app import create_app

SPEC = REPO / "openapi" / "openapi.json"
EXPORT = REPO / "scripts" / "export_openapi.py"


def test_committed_spec_equals_the_app_spec():
    expected = json.dumps(create_app().openapi(), indent=2, sort_keys=True) + "\n"
    assert SPEC.read_text(encoding="utf-8") == expected, (
        "openapi/openapi.json is stale: run python scripts/export_openapi.py")


def test_export_script_stdout_matches_the_file():
    out = subprocess.run([sys.executable, str(EXPORT), "--stdout"], capture_output=True,
                         text=True, check=True, cwd=REPO)
    assert out.stdout == SPEC.read_text(encoding="utf-8")


def test_export_script_writes_a_file(tmp_path):
    target = tmp_path / "spec.json"
    subprocess.run([sys.executable, str(EXPORT), "--output", str(target)], check=True,
                   capture_output=True, cwd=tmp_path)
    assert target.read_text(encoding="utf-8") == SPEC.read_text(encoding="utf-8")


def test_spec_documents_both_request_bodies_and_problems():
    spec = json.loads(SPEC.read_text(encoding="utf-8"))
    body = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]
    assert set(body) == {"multipart/form-data", "application/json"}
    schemas = spec["components"]["schemas"]
    assert {"CloudRequest", "MultipartCloudRequest", "Problem", "KnnParams"} <= set(schemas)
    k = schemas["KnnParams"]["properties"]["k"]
    assert (k["default"], k["minimum"], k["maximum"]) == (24, 5, 1024)
    for path, operations in spec["paths"].items():
        for operation in operations.values():
            for status, response in operation["responses"].items():
                if status.startswith(("4", "5")):
                    assert "application/problem+json" in response["content"], (path, status)
