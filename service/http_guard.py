"""Connections that never finish their request headers (slowloris) are bounded.

uvicorn arms no timer on a connection until its first response is sent, keeps every header
line of a request in memory, and its ``limit_concurrency`` counts stalled connections too,
so it would answer 503 to everyone once enough sockets hang. This protocol, uvicorn's
httptools one plus three guards, keeps them from costing more than a bounded share:

- a request's headers must be complete within ``header_timeout`` seconds of its first byte
  (or of the connection's opening): otherwise 408 and the connection is closed;
- headers (request line included) may hold at most ``max_header_bytes``: otherwise 431;
- at most ``max_pending`` connections may be waiting for their headers at once; a new one
  beyond that closes the one that has waited longest, so stalled sockets cannot pile up
  to the descriptor limit and a normal client (whose headers arrive at once) always gets in.

Idle keep-alive connections are closed by uvicorn's own ``timeout_keep_alive``.
"""

from __future__ import annotations

import asyncio
import json
from collections import OrderedDict

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from .problem_types import PROBLEM_TYPES
from .problems import PROBLEM_MEDIA_TYPE

# The stalled-connection metrics (read by /metrics).
STATS = {"header_timeouts": 0, "headers_too_large": 0, "evicted": 0}


def _problem_bytes(status: int, slug: str, detail: str) -> bytes:
    """A complete HTTP/1.1 response carrying a problem document, closing the connection."""
    kind = PROBLEM_TYPES[slug]
    body = json.dumps({"type": kind.uri, "title": kind.title, "status": status,
                       "detail": detail}).encode()
    head = (f"HTTP/1.1 {status} {kind.title}\r\ncontent-type: {PROBLEM_MEDIA_TYPE}\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n"
            "x-content-type-options: nosniff\r\ncache-control: no-store\r\n\r\n")
    return head.encode("ascii") + body


def guarded_protocol(header_timeout: float, max_header_bytes: int,
                     max_pending: int) -> type[asyncio.Protocol]:
    """An ``http=`` protocol class for ``uvicorn.Config`` with these bounds."""
    pending: OrderedDict[GuardedProtocol, None] = OrderedDict()  # oldest first

    class GuardedProtocol(HttpToolsProtocol):
        _timer: asyncio.TimerHandle | None = None
        _header_bytes = 0

        def connection_made(self, transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._wait_for_headers()

        def connection_lost(self, exc) -> None:
            self._headers_done()
            super().connection_lost(exc)

        def data_received(self, data: bytes) -> None:
            if self._timer is None and self.parser is not None and (
                    self.cycle is None or self.cycle.response_complete):
                self._wait_for_headers()  # the first bytes of a next request
            if self._timer is not None:
                self._header_bytes += len(data)
            super().data_received(data)
            # Still inside the headers after this chunk (a chunk that completes them may
            # carry body bytes too: those are not counted against the header limit).
            if self._timer is not None and self._header_bytes > max_header_bytes:
                STATS["headers_too_large"] += 1
                self._refuse(431, "request-headers-too-large",
                             f"the request line and headers exceed {max_header_bytes} bytes")

        def on_headers_complete(self) -> None:
            self._headers_done()
            super().on_headers_complete()

        def _wait_for_headers(self) -> None:
            self._header_bytes = 0
            self._timer = self.loop.call_later(header_timeout, self._too_slow)
            pending[self] = None
            while len(pending) > max_pending:
                oldest, _ = pending.popitem(last=False)
                STATS["evicted"] += 1
                oldest._refuse(408, "request-timeout", "too many connections are waiting "
                               "for their request headers; this one waited longest")

        def _headers_done(self) -> None:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            pending.pop(self, None)

        def _too_slow(self) -> None:
            self._timer = None
            STATS["header_timeouts"] += 1
            self._refuse(408, "request-timeout",
                         f"the request headers did not arrive within {header_timeout:g} s")

        def _refuse(self, status: int, slug: str, detail: str) -> None:
            self._headers_done()
            if not self.transport.is_closing():
                self.transport.write(_problem_bytes(status, slug, detail))
                self.transport.close()

    return GuardedProtocol
