"""Response hygiene for every answer: security headers, a complete ``Allow``, and access
logs without secrets.

- ``X-Content-Type-Options: nosniff`` everywhere, and ``Cache-Control: no-store`` unless a
  route chose its own caching (results and job states are private and change).
- ``OPTIONS`` on a known path answers 204 with every method the path takes, and a 405 names
  them all too (Starlette's own 405 lists only the first matching route's methods).
- Query strings in uvicorn's access log lose their values: a key sent as ``?api_key=...`` is
  refused by the service but must not end up in a log either.
"""

from __future__ import annotations

import logging
import re
from urllib.parse import parse_qsl, urlencode

from starlette.types import ASGIApp, Receive, Scope, Send

# Query parameters of the API whose values are harmless and help reading a log.
_PLAIN_QUERY = {"format", "limit", "cursor", "status", "field", "view"}
REDACTED = "REDACTED"


def redact_query(path_with_query: str) -> str:
    """``path?a=1&api_key=secret`` -> ``path?a=REDACTED&api_key=REDACTED`` except the
    API's own harmless parameters, which are kept."""
    path, sep, query = path_with_query.partition("?")
    if not sep:
        return path_with_query
    pairs = parse_qsl(query, keep_blank_values=True)
    if not pairs:
        return f"{path}?{REDACTED}"
    return path + "?" + urlencode([(k, v if k in _PLAIN_QUERY else REDACTED)
                                   for k, v in pairs])


class RedactQueryFilter(logging.Filter):
    """Rewrites uvicorn access-log records (args: client, method, path, version, status)."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and len(args) >= 3 and isinstance(args[2], str):
            record.args = (*args[:2], redact_query(args[2]), *args[3:])
        return True


def install_log_redaction() -> None:
    """Add the filter to uvicorn's access logger once (idempotent)."""
    access = logging.getLogger("uvicorn.access")
    if not any(isinstance(f, RedactQueryFilter) for f in access.filters):
        access.addFilter(RedactQueryFilter())


def _method_table(app) -> list[tuple[re.Pattern, set[str]]]:
    """Path patterns of the app's OpenAPI document and the methods of each (cached)."""
    table = getattr(app.state, "allow_table", None)
    if table is None:
        table = []
        for template, operations in app.openapi().get("paths", {}).items():
            pattern = re.escape(template)
            pattern = re.sub(r"\\\{[^/]+?\\\}", "[^/]+", pattern)
            table.append((re.compile(f"^{pattern}$"),
                          {m.upper() for m in operations if m.upper() in _HTTP_METHODS}))
        app.state.allow_table = table
    return table


_HTTP_METHODS = {"GET", "PUT", "POST", "DELETE", "PATCH", "HEAD"}


def allowed_methods(app, scope: Scope) -> list[str]:
    """Every method the API takes on the scope's path (with OPTIONS); empty for a path it
    does not document."""
    methods: set[str] = set()
    for pattern, route_methods in _method_table(app):
        if pattern.match(scope["path"]):
            methods |= route_methods
    if not methods:
        return []
    return sorted(methods | {"OPTIONS"})


class HygieneMiddleware:
    """Pure ASGI middleware applying the rules of this module. ``router`` is the app whose
    routes decide ``Allow``."""

    def __init__(self, app: ASGIApp, router):
        self.app = app
        self.router = router

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] == "OPTIONS":
            allow = allowed_methods(self.router, scope)
            if allow:
                await send({"type": "http.response.start", "status": 204,
                            "headers": _headers([(b"allow", ", ".join(allow).encode())])})
                await send({"type": "http.response.body", "body": b""})
                return

        async def hygienic_send(message):
            if message["type"] == "http.response.start":
                headers = [(k, v) for k, v in message.get("headers", [])]
                if message["status"] == 405:
                    allow = allowed_methods(self.router, scope)
                    if allow:
                        headers = [(k, v) for k, v in headers if k.lower() != b"allow"]
                        headers.append((b"allow", ", ".join(allow).encode()))
                message = {**message, "headers": _headers(headers)}
            await send(message)

        await self.app(scope, receive, hygienic_send)


def _headers(headers: list[tuple[bytes, bytes]]) -> list[tuple[bytes, bytes]]:
    names = {k.lower() for k, _ in headers}
    out = list(headers)
    if b"x-content-type-options" not in names:
        out.append((b"x-content-type-options", b"nosniff"))
    if b"cache-control" not in names:
        out.append((b"cache-control", b"no-store"))
    return out
