"""FastAPI dependencies: the app's shared objects and the caller's identity."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .auth import ANONYMOUS, KeyRing
from .executor import LocalPoolExecutor
from .metrics import ServiceMetrics
from .problems import HTTPProblem
from .settings import Settings
from .store import JobStore

REALM = 'Bearer realm="curvature"'

_bearer = HTTPBearer(
    auto_error=False, scheme_name="ApiKey",
    description="An API key from CURVATURE_API_KEYS / CURVATURE_API_KEYS_FILE, sent as "
    "'Authorization: Bearer <key>'. Each job belongs to the key that submitted it. A service "
    "started without keys (loopback only) ignores the header.")


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


def owner_id(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> str:
    """The caller's owner id: the digest of a valid API key, or ``anonymous`` when the
    service runs without keys.

    Raises
    ------
    HTTPProblem
        401 ``unauthorized`` (with ``WWW-Authenticate: Bearer``) when keys are configured and
        the request has none, or one that matches no key.
    """
    keyring: KeyRing | None = getattr(request.app.state, "keyring", None)
    if keyring is None:
        raise HTTPProblem("not-ready", "the service is starting (API keys not loaded yet)")
    if not keyring.enabled:
        return ANONYMOUS
    if credentials is None:
        raise HTTPProblem("unauthorized", "this service needs an API key: send "
                          "'Authorization: Bearer <key>'", headers={"WWW-Authenticate": REALM})
    owner = keyring.owner_of(credentials.credentials)
    if owner is None:
        raise HTTPProblem("unauthorized", "the API key is not valid for this service",
                          headers={"WWW-Authenticate": f'{REALM}, error="invalid_token"'})
    return owner
