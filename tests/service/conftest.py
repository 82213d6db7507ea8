"""Fixtures of the service tests: one in-process app (TestClient) for the whole session, so
the worker pool starts and compiles the kernels once."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from service_helpers import KEY_A, SCANS, bearer, grid_mesh, make_settings, sphere, wait_ready

import curvature

# Starlette suggests httpx2 for its TestClient; httpx still works and is what we depend on.
warnings.filterwarnings("ignore", message="Using `httpx` with `starlette.testclient`")
from fastapi.testclient import TestClient  # noqa: E402

from service.app import create_app  # noqa: E402


@pytest.fixture(scope="session")
def app_client(tmp_path_factory):
    """One app with its pool for all in-process tests; the client sends API key A."""
    app = create_app(make_settings(tmp_path_factory.mktemp("service-data")))
    with TestClient(app, raise_server_exceptions=False, headers=bearer(KEY_A)) as client:
        wait_ready(client)
        yield client


@pytest.fixture
def client(app_client):
    """The session client; settings changed by a test are restored afterwards."""
    original = app_client.app.state.settings
    yield app_client
    app_client.app.state.settings = original


@pytest.fixture
def sphere_points():
    return sphere()


@pytest.fixture
def mesh_ply(tmp_path) -> Path:
    """A small binary PLY mesh (120 vertices) written by the library."""
    pts, faces = grid_mesh()
    path = tmp_path / "bump.ply"
    curvature.write(path, curvature.PointCloud(points=pts, faces=faces))
    return path


@pytest.fixture(scope="session")
def scans() -> Path:
    if not (SCANS / "bun_zipper.ply").exists():
        pytest.skip(f"real scans not found in {SCANS}")
    return SCANS
