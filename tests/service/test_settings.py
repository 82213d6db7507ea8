"""Settings come from CURVATURE_* environment variables."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from service.settings import Settings


def test_defaults(monkeypatch):
    for name in ("HOST", "PORT", "DATA_DIR", "WORKERS", "EXECUTOR"):
        monkeypatch.delenv(f"CURVATURE_{name}", raising=False)
    settings = Settings()
    assert (settings.host, settings.port, settings.data_dir) == ("127.0.0.1", 8000, Path("data"))
    assert settings.executor == "local"
    assert settings.db_path == Path("data") / "jobs.sqlite3"


def test_environment_overrides(monkeypatch, tmp_path):
    monkeypatch.setenv("CURVATURE_HOST", "0.0.0.0")
    monkeypatch.setenv("CURVATURE_PORT", "9123")
    monkeypatch.setenv("CURVATURE_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("CURVATURE_MAX_UPLOAD_BYTES", "123456")
    monkeypatch.setenv("CURVATURE_SYNC_MAX_POINTS", "77")
    monkeypatch.setenv("CURVATURE_WORKERS", "3")
    monkeypatch.setenv("CURVATURE_RESULT_TTL_SECONDS", "60")
    monkeypatch.setenv("CURVATURE_START_METHOD", "spawn")
    settings = Settings()
    assert settings.host == "0.0.0.0" and settings.port == 9123
    assert settings.data_dir == tmp_path and settings.jobs_dir == tmp_path / "jobs"
    assert settings.max_upload_bytes == 123456 and settings.sync_max_points == 77
    assert settings.workers == 3 and settings.result_ttl_seconds == 60
    assert settings.start_method == "spawn"


def test_bad_values_are_refused(monkeypatch):
    monkeypatch.setenv("CURVATURE_WORKERS", "0")
    with pytest.raises(ValidationError):
        Settings()
    monkeypatch.setenv("CURVATURE_WORKERS", "1")
    monkeypatch.setenv("CURVATURE_EXECUTOR", "kubernetes")
    with pytest.raises(ValidationError):
        Settings()


def test_dask_executor_needs_a_scheduler_address(tmp_path):
    with pytest.raises(ValidationError, match="CURVATURE_DASK_ADDRESS"):
        Settings(data_dir=tmp_path, executor="dask")
    settings = Settings(data_dir=tmp_path, executor="dask", dask_address="tcp://h:8786")
    assert settings.dask_tile_points == 250_000


def test_security_and_limit_settings_from_the_environment(monkeypatch, tmp_path):
    keys = tmp_path / "keys.txt"
    monkeypatch.setenv("CURVATURE_API_KEYS", "key-one-0123456789,key-two-0123456789")
    monkeypatch.setenv("CURVATURE_API_KEYS_FILE", str(keys))
    monkeypatch.setenv("CURVATURE_ALLOW_OPEN", "true")
    monkeypatch.setenv("CURVATURE_MAX_POINTS", "1000")
    monkeypatch.setenv("CURVATURE_MAX_JOBS_PER_KEY", "7")
    monkeypatch.setenv("CURVATURE_JOB_TIME_LIMIT_SECONDS", "90")
    monkeypatch.setenv("CURVATURE_TIME_LIMIT_GRACE_SECONDS", "2")
    monkeypatch.setenv("CURVATURE_STORE_BUSY_TIMEOUT_SECONDS", "5")
    settings = Settings()
    assert settings.api_keys.get_secret_value() == "key-one-0123456789,key-two-0123456789"
    assert "key-one" not in repr(settings)  # a secret: never printed in logs or reprs
    assert settings.api_keys_file == keys and settings.allow_open
    assert (settings.max_points, settings.max_jobs_per_key) == (1000, 7)
    assert settings.job_time_limit_seconds == 90 and settings.time_limit_grace_seconds == 2
    assert settings.store_busy_timeout_seconds == 5


def test_defaults_are_closed(monkeypatch):
    for name in ("API_KEYS", "API_KEYS_FILE", "ALLOW_OPEN"):
        monkeypatch.delenv(f"CURVATURE_{name}", raising=False)
    settings = Settings()
    assert settings.api_keys is None and settings.api_keys_file is None
    assert not settings.allow_open
