"""Probes and metrics for operators."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Annotated

import anyio.to_thread
from fastapi import APIRouter, Depends, Request
from fastapi.responses import PlainTextResponse
from pydantic import BaseModel

from .. import metrics as metrics_module
from ..dependencies import get_metrics
from ..metrics import ServiceMetrics
from ..problems import HTTPProblem, problem_responses

router = APIRouter(tags=["operations"])


class Health(BaseModel):
    status: str


class Readiness(BaseModel):
    status: str
    checks: dict[str, bool]


def _folder_writable(folder: Path) -> bool:
    """True when a file can be created in ``folder`` (uploads and results go there)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".ready-"):
            return True
    except OSError:
        return False


def _checks(request: Request) -> dict[str, bool]:
    store = getattr(request.app.state, "store", None)
    executor = getattr(request.app.state, "executor", None)
    settings = request.app.state.settings
    return {"store": store is not None and store.ping() and store.writable(),
            "data_dir": _folder_writable(settings.jobs_dir) and _folder_writable(settings.tmp_dir),
            "pool": executor is not None and executor.ready}


@router.get("/healthz", response_model=Health, summary="Liveness: the process answers")
def healthz() -> Health:
    return Health(status="ok")


@router.get("/readyz", response_model=Readiness, responses=problem_responses("not-ready"),
            summary="Readiness: job store open and writable, data folder writable, worker "
            "pool started and warmed up")
async def readyz(request: Request) -> Readiness:
    checks = await anyio.to_thread.run_sync(_checks, request)
    if not all(checks.values()):
        failing = ", ".join(k for k, ok in checks.items() if not ok)
        raise HTTPProblem("not-ready", f"not ready: {failing}{_warming(request)}",
                          checks=checks)
    return Readiness(status="ready", checks=checks)


def _warming(request: Request) -> str:
    """What the pool is doing before it is ready, for the not-ready message."""
    executor = getattr(request.app.state, "executor", None)
    if executor is None or executor.ready or executor.warmed_up:
        return ""
    if executor.compiling:
        seconds = time.monotonic() - executor.compile_started
        return (f" (compiling kernels, {seconds:.0f} s so far: numba's cache was missing or "
                "stale; progress in the log)")
    return " (warming up the workers)"


@router.get("/metrics", response_class=PlainTextResponse,
            summary="Prometheus metrics (text exposition format 0.0.4)",
            responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}})
async def metrics(request: Request,
                  registry: Annotated[ServiceMetrics, Depends(get_metrics)]) -> PlainTextResponse:
    checks = await anyio.to_thread.run_sync(_checks, request)
    store = getattr(request.app.state, "store", None)
    if store is not None and checks["store"]:
        counts = await anyio.to_thread.run_sync(store.count_by_status)
        for status, count in counts.items():
            registry.jobs.set(count, status=status)
    registry.ready.set(1 if all(checks.values()) else 0)
    return PlainTextResponse(registry.render(), media_type=metrics_module.CONTENT_TYPE)
