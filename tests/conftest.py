"""Shared pytest fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

# tests/conftest.py -> tests -> project root (/work/main) -> its parent (/work)
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Directory of the real scans (bunny PLYs, PCL PCDs); never modified by tests."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real scan directory {SHARED_DATA} is missing")
    return SHARED_DATA
