"""A real ``python -m service`` process for the client tests (the helper of the service
tests, from tests/service)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "service"))
from service_helpers import ServerProcess  # noqa: E402


@pytest.fixture(scope="session")
def server(tmp_path_factory):
    """An open service (no API keys) on a free loopback port."""
    root = tmp_path_factory.mktemp("client-server")
    proc = ServerProcess(root / "data", root / "server.log").start()
    yield proc
    proc.stop()
