"""Helpers shared by the service tests: clouds, polling, settings, a real server process.

(A plain module rather than a package: ``tests/service`` must not shadow the ``service``
package on ``sys.path``.)
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from curvature.warmup import cache_is_warm
from service.settings import Settings

REPO = Path(__file__).resolve().parents[2]
SCANS = REPO.parent / "shared" / "data"
FINAL = ("succeeded", "failed", "cancelled")
# API keys of the test apps: the in-process client sends KEY_A unless a test says otherwise.
KEY_A = "test-key-alpha-0123456789"
KEY_B = "test-key-bravo-0123456789"
KEYS = f"{KEY_A},{KEY_B}"


def bearer(key: str) -> dict[str, str]:
    """The Authorization header for ``key``."""
    return {"Authorization": f"Bearer {key}"}


def sphere(n: int = 300, radius: float = 2.0, seed: int = 0) -> np.ndarray:
    """Points on a sphere (Fibonacci lattice, slightly jittered): k1 = k2 = 1/radius."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    pts = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    pts += np.random.default_rng(seed).normal(scale=1e-4, size=pts.shape)
    return radius * pts / np.linalg.norm(pts, axis=1, keepdims=True)


def grid_mesh(nx: int = 12, ny: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy height field and its triangles."""
    x, y = np.meshgrid(np.linspace(-1, 1, nx), np.linspace(-1, 1, ny), indexing="ij")
    pts = np.column_stack([x.ravel(), y.ravel(), 0.2 * (x * x + 0.5 * y * y).ravel()])
    faces = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
            faces += [(a, b, c), (a, c, d)]
    return pts, np.array(faces, dtype=np.int64)


def wait_for_job(client, job_id: str, timeout: float = 120.0, until=FINAL,
                 headers: dict | None = None) -> dict:
    """Poll a job until its status is in ``until``; fail the test on timeout."""
    deadline = time.monotonic() + timeout
    while True:
        response = client.get(f"/v1/jobs/{job_id}", headers=headers or {})
        assert response.status_code == 200, response.text
        job = response.json()
        if job["status"] in until:
            return job
        if time.monotonic() > deadline:
            pytest.fail(f"job {job_id} still {job['status']} after {timeout} s")
        time.sleep(0.05)


def make_settings(data_dir: Path, **changes) -> Settings:
    """Small, fast settings for tests (pool of 2, API keys KEY_A and KEY_B)."""
    values = {"data_dir": data_dir, "workers": 2, "cleanup_interval_seconds": 3600,
              "progress_interval_seconds": 0.05, "dispatch_poll_seconds": 0.2,
              "api_keys": KEYS}
    values.update(changes)
    return Settings(**values)


@contextlib.contextmanager
def changed_executor(client, **changes):
    """Temporarily change the settings the running app's executor reads at each dispatch."""
    executor = client.app.state.executor
    original = executor.settings
    executor.settings = original.model_copy(update=changes)
    try:
        yield executor
    finally:
        executor.settings = original


@contextlib.contextmanager
def changed_settings(client, **changes):
    """Temporarily change settings of the running app (no validation: edge values allowed)."""
    original = client.app.state.settings
    client.app.state.settings = original.model_copy(update=changes)
    try:
        yield
    finally:
        client.app.state.settings = original


def start_limit() -> float:
    """Seconds a service may take to become ready: with numba's cache warm (the install step
    fills it) the workers load the kernels in seconds; on a cold cache one worker compiles
    them first, which took up to 16 minutes on a loaded 2-core machine."""
    return 300.0 if cache_is_warm() else 2400.0


def wait_ready(client, timeout: float | None = None) -> None:
    timeout = start_limit() if timeout is None else timeout
    deadline = time.monotonic() + timeout
    while (answer := client.get("/readyz")).status_code != 200:
        if time.monotonic() > deadline:
            pytest.fail(f"service not ready in {timeout:.0f} s: {answer.text}")
        time.sleep(0.1)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def processes_with_env(marker: str) -> list[int]:
    """Pids of our processes whose environment contains ``marker`` (Linux /proc)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if marker.encode() in (entry / "environ").read_bytes():
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def stop_group(process: subprocess.Popen, grace: float = 30.0) -> None:
    """End ``process`` (started with ``start_new_session=True``) and its process group."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)  # workers that outlived their server


class ServerProcess:
    """``python -m service`` in a subprocess on a random free port of 127.0.0.1.

    Parameters
    ----------
    data_dir : Path
        CURVATURE_DATA_DIR.
    log_path : Path
        Where its output goes (shown when a test fails).
    api_key : str, optional
        Sent by :attr:`client` with every request.
    **env
        More CURVATURE_* variables (names without the prefix).
    """

    def __init__(self, data_dir: Path, log_path: Path, api_key: str | None = None, **env):
        self.data_dir = data_dir
        self.log_path = log_path
        self.port = free_port()
        self.env = {**os.environ, "CURVATURE_HOST": "127.0.0.1",
                    "CURVATURE_PORT": str(self.port), "CURVATURE_DATA_DIR": str(data_dir),
                    "CURVATURE_WORKERS": "2", "CURVATURE_DISPATCH_POLL_SECONDS": "0.2",
                    "CURVATURE_PROGRESS_INTERVAL_SECONDS": "0.05"}
        self.env.update({f"CURVATURE_{k.upper()}": str(v) for k, v in env.items()})
        self.headers = bearer(api_key) if api_key else {}
        self.process: subprocess.Popen | None = None
        self.client: httpx.Client | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float | None = None, wait: bool = True) -> ServerProcess:
        """Start the process and wait until ``/readyz`` answers 200 (``wait``); a server
        that exits or is not ready in ``timeout`` seconds (default :func:`start_limit`) is
        stopped, its log shown, and the test failed."""
        with open(self.log_path, "ab") as log:
            self.process = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO,
                                            env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                            start_new_session=True)
        self.client = httpx.Client(base_url=self.url, timeout=60.0, headers=self.headers)
        if wait:
            try:
                self.wait_ready(timeout)
            except BaseException:
                self.stop()
                raise
        return self

    def wait_ready(self, timeout: float | None = None) -> None:
        timeout = start_limit() if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                pytest.fail(f"server exited early (status {self.process.returncode}):\n"
                            f"{self.log()}")
            try:
                if self.client.get("/readyz").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"server not ready in {timeout:.0f} s:\n{self.log()}")
            time.sleep(0.2)

    def kill(self) -> None:
        """SIGKILL the server process alone (its workers must go down with it)."""
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=30)
        self.client.close()

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 30 s, for the server and anything left in its
        process group (workers of a server that never got ready)."""
        if self.process is not None:
            stop_group(self.process)
        if self.client is not None:
            self.client.close()

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")[-5000:]
