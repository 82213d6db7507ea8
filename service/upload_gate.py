"""Slow and piled-up uploads: a read timeout, a minimum rate, and caps on concurrent uploads.

Every upload holds a socket and a file while it lasts, so stalled clients used to exhaust the
process's file descriptors (and then the store and every other request failed with "Too many
open files"). Uploads are now counted while they run, globally and per API key, and refused
beyond the caps with a problem document; the global cap is also kept below what the
descriptor limit allows, with headroom for the store, the pool and the log.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections import Counter
from collections.abc import AsyncIterator, Iterator

import anyio
from fastapi import Request

from .problems import HTTPProblem
from .settings import Settings

log = logging.getLogger("service.uploads")

# Descriptors kept free for everything but uploads (store connections, pool pipes, logs),
# and descriptors one upload holds (socket, upload file, one spare for a worker thread).
FD_HEADROOM = 256
FDS_PER_UPLOAD = 3


def raise_fd_limit() -> int:
    """Raise the soft descriptor limit to the hard one; return the soft limit now."""
    try:
        import resource
    except ImportError:  # not POSIX
        return 1 << 16
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = hard if hard != resource.RLIM_INFINITY else max(soft, 1 << 16)
    if want > soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
            soft = want
        except (ValueError, OSError):
            pass
    return soft


class UploadGate:
    """Counts uploads in progress and refuses those beyond the caps.

    Parameters
    ----------
    max_total, max_per_key : int
        ``CURVATURE_MAX_CONCURRENT_UPLOADS`` and ``CURVATURE_MAX_UPLOADS_PER_KEY``; the
        total is lowered to what the descriptor limit leaves room for.
    """

    def __init__(self, max_total: int, max_per_key: int):
        fd_limit = raise_fd_limit()
        fd_cap = max(1, (fd_limit - FD_HEADROOM) // FDS_PER_UPLOAD)
        if fd_cap < max_total:
            log.warning("at most %d concurrent uploads (file descriptor limit %d)", fd_cap,
                        fd_limit)
        self.max_total = min(max_total, fd_cap)
        self.max_per_key = max_per_key
        self.total = 0
        self.per_key: Counter[str] = Counter()

    @contextlib.contextmanager
    def hold(self, owner: str, retry_after: int) -> Iterator[None]:
        """Count one upload of ``owner`` while the block runs (event-loop only: no lock)."""
        headers = {"Retry-After": str(retry_after)}
        if self.per_key[owner] >= self.max_per_key:
            raise HTTPProblem("too-many-uploads", f"this API key already has "
                              f"{self.per_key[owner]} uploads in progress; the limit is "
                              f"{self.max_per_key} (CURVATURE_MAX_UPLOADS_PER_KEY)",
                              headers=headers)
        if self.total >= self.max_total:
            raise HTTPProblem("queue-full", f"{self.total} uploads are in progress; the limit "
                              f"is {self.max_total} (CURVATURE_MAX_CONCURRENT_UPLOADS)",
                              headers=headers)
        self.total += 1
        self.per_key[owner] += 1
        try:
            yield
        finally:
            self.total -= 1
            self.per_key[owner] -= 1
            if not self.per_key[owner]:
                del self.per_key[owner]


def gate_of(request: Request) -> UploadGate:
    """The app's gate, made on first use from its settings."""
    state = request.app.state
    gate = getattr(state, "upload_gate", None)
    if gate is None:
        s: Settings = state.settings
        gate = state.upload_gate = UploadGate(s.max_concurrent_uploads, s.max_uploads_per_key)
    return gate


async def timed_stream(request: Request, settings: Settings) -> AsyncIterator[bytes]:
    """The request body, failing with 408 when the next chunk takes longer than
    ``upload_read_timeout_seconds`` or the average rate falls below
    ``min_upload_bytes_per_second`` once the first read timeout has passed."""
    timeout = settings.upload_read_timeout_seconds
    min_rate = settings.min_upload_bytes_per_second
    chunks = request.stream().__aiter__()
    started = time.monotonic()
    received = 0
    while True:
        try:
            with anyio.fail_after(timeout):
                chunk = await chunks.__anext__()
        except StopAsyncIteration:
            return
        except TimeoutError:
            raise HTTPProblem("request-timeout", f"no body data for {timeout:g} s "
                              "(CURVATURE_UPLOAD_READ_TIMEOUT_SECONDS)") from None
        received += len(chunk)
        elapsed = time.monotonic() - started
        if elapsed > timeout and received < min_rate * elapsed:
            raise HTTPProblem("request-timeout", (
                f"the body arrives at {received / elapsed:.0f} bytes/s, below the minimum of "
                f"{min_rate} (CURVATURE_MIN_UPLOAD_BYTES_PER_SECOND)"))
        yield chunk
