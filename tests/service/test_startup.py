"""Process start-up: one server per data folder, the port bound before anything is opened,
and readiness that says when kernels are being compiled."""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import warnings

import pytest
from service_helpers import REPO, make_settings, start_limit, wait_ready

import service.executor
from service.datalock import LOCK_NAME, DataDirBusy, DataDirLock

warnings.filterwarnings("ignore", message="Using `httpx` with `starlette.testclient`")
from fastapi.testclient import TestClient  # noqa: E402

from service.app import create_app  # noqa: E402


def run_service(data_dir, port: int, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
    env.update({"CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
                "CURVATURE_DATA_DIR": str(data_dir), "CURVATURE_WORKERS": "1"})
    return subprocess.run([sys.executable, "-m", "service"], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_the_lock_is_exclusive_and_names_its_holder(tmp_path):
    first = DataDirLock.acquire(tmp_path / "data")
    with pytest.raises(DataDirBusy) as busy:
        DataDirLock.acquire(tmp_path / "data")
    assert busy.value.holder == os.getpid()
    assert str((tmp_path / "data").resolve()) in str(busy.value)
    first.release()
    DataDirLock.acquire(tmp_path / "data").release()  # free again


def test_a_second_server_on_a_held_data_folder_refuses(tmp_path):
    data_dir = tmp_path / "data"
    holder = DataDirLock.acquire(data_dir)  # stands for a running server: same lock
    try:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        out = run_service(data_dir, port)
    finally:
        holder.release()
    assert out.returncode == 75, out.stderr
    assert f"data folder {data_dir.resolve()} is in use by process {os.getpid()}" in out.stderr
    assert sorted(p.name for p in data_dir.iterdir()) == [LOCK_NAME]  # no store opened


def test_a_taken_port_stops_the_start_before_the_data_folder_is_touched(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        out = run_service(tmp_path / "data", taken.getsockname()[1])
    assert out.returncode == 71, out.stderr
    assert "cannot listen on 127.0.0.1 port" in out.stderr
    assert not (tmp_path / "data").exists()


def test_an_app_cannot_serve_a_folder_another_server_holds(tmp_path):
    settings = make_settings(tmp_path / "data", warmup=False)
    holder = DataDirLock.acquire(settings.data_dir)
    try:
        with pytest.raises(DataDirBusy), TestClient(create_app(settings)):
            pass
    finally:
        holder.release()
    assert not settings.db_path.exists()


def test_readiness_says_kernels_are_compiling_on_a_cold_cache(tmp_path, monkeypatch, caplog):
    # A cold cache as the pool sees it: one worker runs the full warm-up (here it loads
    # the kernels from the cache, which takes long enough to be seen), then the rest.
    monkeypatch.setattr(service.executor, "cache_is_warm", lambda: False)
    caplog.set_level(logging.INFO, logger="service")
    app = create_app(make_settings(tmp_path / "data", workers=1))
    with TestClient(app, raise_server_exceptions=False) as client:
        first = client.get("/readyz")
        assert first.status_code == 503
        assert "compiling kernels" in first.json()["detail"]
        checks = first.json()["checks"]
        assert checks["store"] and not checks["pool"]
        wait_ready(client, start_limit())
    assert "compiling the numeric kernels" in caplog.text
