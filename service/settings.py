"""Service settings, read from ``CURVATURE_*`` environment variables."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

# forkserver forks workers from a small clean process that has already imported numpy/numba,
# so a fresh worker starts in a fraction of a second; spawn is the portable fallback.
DEFAULT_START_METHOD = "forkserver" if sys.platform.startswith("linux") else "spawn"


class Settings(BaseSettings):
    """Everything an operator can tune; each field ``name`` is read from ``CURVATURE_NAME``.

    Examples
    --------
    ``CURVATURE_PORT=9000 CURVATURE_DATA_DIR=/var/lib/curvature python -m service``
    """

    model_config = SettingsConfigDict(env_prefix="CURVATURE_", extra="ignore")

    host: str = Field("127.0.0.1", description="Interface to listen on.")
    port: int = Field(8000, ge=0, le=65535, description="TCP port.")
    data_dir: Path = Field(Path("data"), description="Job store, inputs and results live here.")
    log_level: Literal["debug", "info", "warning", "error"] = "info"

    api_keys: SecretStr | None = Field(
        None, description="Comma-separated API keys accepted as 'Authorization: Bearer <key>'. "
        "Without any key (here or in api_keys_file) the service is open and listens on "
        "loopback only.")
    api_keys_file: Path | None = Field(
        None, description="File with one API key a line ('#' comments and blank lines "
        "ignored); adds to api_keys.")
    allow_open: bool = Field(
        False, description="Allow listening on a non-loopback address without API keys.")

    executor: Literal["local", "dask"] = Field(
        "local", description="'local': jobs run in the process pool on this machine. 'dask': "
        "the pool still drives each job (reading, planning, orientation, writing), but its "
        "spatial tiles run as tasks on the Dask cluster at dask_address.")
    dask_address: str | None = Field(
        None, description="Scheduler address for executor 'dask', e.g. tcp://scheduler:8786.")
    dask_tile_points: int = Field(
        250_000, ge=1000, description="Points per tile sent to the Dask cluster.")
    dask_connect_seconds: float = Field(
        20, gt=0, description="How long a job waits to reach the Dask scheduler.")
    workers: int = Field(2, ge=1, le=256, description="Worker processes in the local pool.")
    start_method: Literal["spawn", "forkserver"] = Field(
        DEFAULT_START_METHOD, description="multiprocessing start method of the pool.")
    small_job_bytes: int = Field(
        4 << 20, ge=0, description="Jobs whose input is at most this many bytes are small: "
        "they never wait for a worker behind large ones.")
    small_job_workers: int = Field(
        1, ge=0, description="Workers large jobs leave free for small ones (at least one "
        "worker always takes large jobs).")
    worker_nice: int = Field(
        10, ge=0, le=19, description="Scheduling niceness of the worker processes, so the "
        "server keeps answering (polls, uploads) while they compute.")
    estimate_workers: int = Field(
        1, ge=0, le=256,
        description="Threads each job may use inside the library (0: the library's default).")
    warmup: bool = Field(
        True, description="Compile the numeric kernels in every worker at startup.")

    max_upload_bytes: int = Field(
        1 << 30, ge=1024, description="Largest accepted request body (file uploads).")
    max_json_bytes: int = Field(
        64 << 20, ge=1024, description="Largest accepted JSON body (parsed in memory).")
    upload_read_timeout_seconds: float = Field(
        30, gt=0, description="A request body pausing longer than this is answered 408.")
    min_upload_bytes_per_second: int = Field(
        1024, ge=0, description="Past the first read timeout, a body arriving slower than "
        "this on average is answered 408.")
    header_timeout_seconds: float = Field(
        10, gt=0, description="A request's line and headers must arrive within this many "
        "seconds of its first byte (or of the connection's opening); else 408 and closed.")
    max_header_bytes: int = Field(
        64 << 10, ge=4096, description="Largest request line plus headers (431 beyond).")
    max_pending_connections: int = Field(
        512, ge=1, description="Connections waiting for their request headers at once; a "
        "new one beyond this closes the one that waited longest (slowloris).")
    keep_alive_timeout_seconds: float = Field(
        5, gt=0, description="An idle keep-alive connection is closed after this long.")
    max_concurrent_uploads: int = Field(
        256, ge=1, description="Uploads in progress at once (503 beyond; also kept below what "
        "the file descriptor limit allows).")
    max_uploads_per_key: int = Field(
        100, ge=1, description="Uploads one API key may have in progress at once (429 "
        "beyond; with max_jobs_per_key it bounds the folders one key can hold).")
    sync_max_points: int = Field(
        50_000, ge=10, description="Largest cloud POST /v1/curvature answers synchronously.")
    sync_time_limit_seconds: float = Field(
        60, gt=0, description="A synchronous computation running longer than this (or than "
        "job_time_limit_seconds, if smaller) is killed and answered 422 'time-limit'.")
    sync_max_cost: float = Field(
        2e9, gt=0, description="Work units (points times a per-point cost of the method's "
        "parameters, see docs/reliability.md) a synchronous request may ask for; more is "
        "answered 413 'too-costly'.")
    sync_workers: int = Field(
        1, ge=1, le=64, description="Processes serving synchronous requests, apart from the "
        "job pool (each is killed on its own when its request runs too long or its client "
        "hangs up).")
    max_pending_sync: int = Field(
        8, ge=1, description="Synchronous requests allowed to wait for a worker at once.")
    max_points: int = Field(
        10_000_000, ge=10, description="Largest cloud a job accepts (points).")
    max_queued_jobs: int = Field(
        1000, ge=1, description="Unfinished jobs accepted before answering 503.")
    max_jobs_per_key: int = Field(
        100, ge=1, description="Unfinished jobs one API key may have before answering 429.")
    job_time_limit_seconds: float = Field(
        3600, gt=0, description="A run longer than this fails the job ('time-limit').")
    time_limit_grace_seconds: float = Field(
        10, ge=0, description="Past the time limit plus this, a run that did not stop by "
        "itself is ended by killing the worker pool.")
    store_busy_timeout_seconds: float = Field(
        30, gt=0, description="How long a store operation waits for a locked SQLite file.")
    max_attempts: int = Field(
        3, ge=1, description="Runs of one job that killed their worker process before the job "
        "is quarantined (failed with 'worker-crashed').")
    max_restarts: int = Field(
        25, ge=1, description="Server restarts one job may be interrupted by before it is "
        "marked failed (counted apart from max_attempts).")
    retry_after_seconds: int = Field(5, ge=1, description="Retry-After sent with 503.")

    result_ttl_seconds: float = Field(
        24 * 3600, gt=0, description="Finished jobs and their files are deleted after this.")
    cleanup_interval_seconds: float = Field(
        60, gt=0, description="How often expired jobs are looked for.")
    progress_interval_seconds: float = Field(
        0.5, gt=0, description="Minimum time between two progress writes of a job.")
    dispatch_poll_seconds: float = Field(
        1.0, gt=0, description="Dispatcher re-reads the queue at least this often.")

    @model_validator(mode="after")
    def _dask_needs_an_address(self) -> Settings:
        if self.executor == "dask" and not self.dask_address:
            raise ValueError("CURVATURE_EXECUTOR=dask needs CURVATURE_DASK_ADDRESS, the "
                             "scheduler's address (e.g. tcp://scheduler:8786)")
        return self

    @property
    def db_path(self) -> Path:
        """SQLite job store."""
        return self.data_dir / "jobs.sqlite3"

    @property
    def jobs_dir(self) -> Path:
        """One sub-folder per job: input, canonical result, rendered formats."""
        return self.data_dir / "jobs"

    @property
    def tmp_dir(self) -> Path:
        """Scratch space of synchronous requests and unfinished uploads."""
        return self.data_dir / "tmp"
