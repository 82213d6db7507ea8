"""Every error leaves the service as application/problem+json (RFC 9457).

Handlers turn :class:`ProblemError`, request validation errors and Starlette HTTP errors into
problem documents; :class:`CatchAllMiddleware` turns anything else into a bare
``internal-error`` problem (no traceback, no internals) and logs the exception once.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Receive, Scope, Send

from .problem_types import PROBLEM_TYPES, ProblemError
from .storage_errors import storage_problem

log = logging.getLogger("service")

PROBLEM_MEDIA_TYPE = "application/problem+json"

_HTTP_SLUGS = {404: "not-found", 405: "method-not-allowed", 406: "not-acceptable",
               413: "too-large", 415: "unsupported-media-type", 422: "invalid-request"}


class HTTPProblem(ProblemError):
    """A :class:`ProblemError` with extra response headers and problem members.

    Parameters
    ----------
    slug, detail : str
        As for :class:`ProblemError`.
    headers : dict, optional
        E.g. ``{"Retry-After": "5"}``.
    **extensions
        Extra members of the problem document (e.g. ``errors``, ``job_id``).
    """

    def __init__(self, slug: str, detail: str, *, headers: dict[str, str] | None = None,
                 **extensions: Any):
        super().__init__(slug, detail)
        self.headers = headers or {}
        self.extensions = extensions


def problem_response(request: Request | None, slug: str, detail: str, *,
                     headers: dict[str, str] | None = None, **extensions: Any) -> JSONResponse:
    """Build the problem document of ``slug`` for ``request``."""
    kind = PROBLEM_TYPES[slug]
    body = {"type": kind.uri, "title": kind.title, "status": kind.status, "detail": detail,
            "instance": request.url.path if request is not None else None}
    body.update(extensions)
    if request is not None:
        metrics = getattr(request.app.state, "metrics", None)
        if metrics is not None:
            metrics.problems.inc(type=slug)
    return JSONResponse(body, status_code=kind.status, headers=headers,
                        media_type=PROBLEM_MEDIA_TYPE)


def validation_errors(errors: list[dict], prefix: tuple = ()) -> list[dict]:
    """Pydantic errors reduced to location and message (no echoed input, no URLs)."""
    out = []
    for err in errors:
        loc = [str(p) for p in (*prefix, *err.get("loc", ()))]
        out.append({"loc": loc, "msg": err.get("msg", ""), "type": err.get("type", "")})
    return out


async def _problem_error(request: Request, exc: ProblemError) -> JSONResponse:
    headers = getattr(exc, "headers", None) or _retry_after(request, exc.slug)
    extensions = getattr(exc, "extensions", {})
    return problem_response(request, exc.slug, exc.detail, headers=headers, **extensions)


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    errors = validation_errors(exc.errors())
    first = errors[0] if errors else {"loc": [], "msg": "invalid request"}
    detail = f"{'.'.join(first['loc']) or 'request'}: {first['msg']}"
    return problem_response(request, "invalid-request", detail, errors=errors)


async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    slug = _HTTP_SLUGS.get(exc.status_code)
    if slug is None:  # statuses without their own type: plain RFC 9457 "about:blank"
        body = {"type": "about:blank", "title": str(exc.detail), "status": exc.status_code,
                "detail": str(exc.detail), "instance": request.url.path}
        return JSONResponse(body, status_code=exc.status_code, headers=exc.headers,
                            media_type=PROBLEM_MEDIA_TYPE)
    detail = str(exc.detail) if exc.detail else PROBLEM_TYPES[slug].description
    if slug == "not-found" and exc.detail == "Not Found":
        detail = f"no route for {request.method} {request.url.path}"
    return problem_response(request, slug, detail, headers=exc.headers)


class CatchAllMiddleware:
    """Last line of defence: an unexpected exception becomes a 500 problem, logged once.

    Pure ASGI (not ``BaseHTTPMiddleware``) so streaming responses are untouched. When the
    response had already started, the connection is simply closed.
    """

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracking_send(message):
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception as exc:
            # A full disk or a locked store is the operator's problem, not a bug: the client
            # gets a 507/503 it can act on. Both leave the store and files consistent.
            known = storage_problem(exc, f"answering {scope.get('method')} {scope.get('path')}")
            if known is None:
                log.exception("unhandled error on %s %s", scope.get("method"),
                              scope.get("path"))
            else:
                log.error("%s on %s %s: %s", known.slug, scope.get("method"),
                          scope.get("path"), exc)
            if started:
                return
            request = Request(scope)
            if known is None:
                response = problem_response(request, "internal-error",
                                            PROBLEM_TYPES["internal-error"].description)
            else:
                response = problem_response(request, known.slug, known.detail,
                                            headers=_retry_after(request, known.slug))
            await response(scope, receive, send)


def _retry_after(request: Request, slug: str) -> dict[str, str] | None:
    if PROBLEM_TYPES[slug].status != 503:
        return None
    settings = getattr(request.app.state, "settings", None)
    return {"Retry-After": str(getattr(settings, "retry_after_seconds", 5))}


def install(app: FastAPI) -> None:
    """Register the problem handlers and the catch-all middleware on ``app``."""
    app.add_exception_handler(ProblemError, _problem_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_middleware(CatchAllMiddleware)


def problem_responses(*slugs: str) -> dict[int | str, dict]:
    """OpenAPI ``responses`` entries for the given problem types."""
    out: dict[int | str, dict] = {}
    for slug in slugs:
        kind = PROBLEM_TYPES[slug]
        entry = out.setdefault(kind.status, {
            "description": "", "content": {PROBLEM_MEDIA_TYPE: {
                "schema": {"$ref": "#/components/schemas/Problem"}}}})
        entry["description"] = "; ".join(filter(None, [entry["description"],
                                                       f"{kind.uri}: {kind.title}"]))
    return out
