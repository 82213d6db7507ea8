"""FastAPI dependencies: the app's shared objects and the caller's identity."""

from __future__ import annotations

from typing import Annotated

from fastapi import Header, Request

from .executor import LocalPoolExecutor
from .metrics import ServiceMetrics
from .problems import HTTPProblem
from .settings import Settings
from .store import JobStore

CLIENT_HEADER = "X-Client-Id"
ANONYMOUS = "anonymous"


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_metrics(request: Request) -> ServiceMetrics:
    return request.app.state.metrics


def get_store(request: Request) -> JobStore:
    store = getattr(request.app.state, "store", None)
    if store is None:
        raise HTTPProblem("not-ready", "the job store is not open yet")
    return store


def get_executor(request: Request) -> LocalPoolExecutor:
    executor = getattr(request.app.state, "executor", None)
    if executor is None:
        raise HTTPProblem("not-ready", "the worker pool is not running")
    return executor


def client_id(
    x_client_id: Annotated[str | None, Header(
        alias=CLIENT_HEADER, pattern=r"^[A-Za-z0-9._:@-]{1,128}$",
        description="Who the caller is, to list their own jobs (not authentication: any "
        "caller may claim any id; put an authenticating proxy in front for that).")] = None,
) -> str:
    """The caller's id from ``X-Client-Id``, or ``anonymous``."""
    return x_client_id or ANONYMOUS
