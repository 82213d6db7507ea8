"""Slowloris: connections that never finish their request headers are bounded (issue 18).

A few hundred sockets that send part of a request line and headers and then stall must not
keep a normal client out, must not hold the server's descriptors, and must be closed with
a 408 problem once the header timeout passes; oversized headers get 431.
"""

from __future__ import annotations

import json
import os
import socket
import time

import httpx
import pytest
from service_helpers import KEY_A, ServerProcess

STALLED = 300
MAX_PENDING = 100
HEADER_TIMEOUT = 3.0


def _fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def _answer(sock: socket.socket, timeout: float = 5.0) -> bytes:
    """Everything the server sends until it closes the connection."""
    sock.settimeout(timeout)
    chunks = []
    while True:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            break
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


def _problem(raw: bytes) -> tuple[int, dict]:
    head, _, body = raw.partition(b"\r\n\r\n")
    return int(head.split(b" ", 2)[1]), json.loads(body)


@pytest.fixture
def server(tmp_path):
    proc = ServerProcess(tmp_path / "data", tmp_path / "server.log", api_key=KEY_A,
                         api_keys=KEY_A, warmup="false", workers=1,
                         header_timeout_seconds=HEADER_TIMEOUT,
                         max_pending_connections=MAX_PENDING).start()
    yield proc
    proc.stop()


def test_stalled_headers_neither_lock_out_clients_nor_hold_descriptors(server):
    pid = server.process.pid
    baseline = _fds(pid)
    stalled = []
    try:
        for _ in range(STALLED):
            sock = socket.create_connection(("127.0.0.1", server.port))
            sock.sendall(b"GET /v1/jobs HTTP/1.1\r\nHost: x\r\nX-Slow: 1")  # never ends
            stalled.append(sock)
        time.sleep(0.5)
        # A normal client gets its answer at once, and the server holds at most the
        # allowed number of stalled sockets (the oldest were closed to make room).
        started = time.monotonic()
        answer = server.client.get("/v1/jobs")
        assert answer.status_code == 200, answer.text
        assert time.monotonic() - started < 2.0
        assert _fds(pid) <= baseline + MAX_PENDING + 10, (_fds(pid), baseline)
        status, problem = _problem(_answer(stalled[0], 2.0))
        assert status == 408 and problem["type"] == "/problems/request-timeout"
        assert "waited longest" in problem["detail"]
        # Past the header timeout every stalled socket has been answered and closed.
        time.sleep(HEADER_TIMEOUT + 1.0)
        status, problem = _problem(_answer(stalled[-1], 2.0))
        assert status == 408 and f"within {HEADER_TIMEOUT:g} s" in problem["detail"]
        assert _fds(pid) <= baseline + 5, (_fds(pid), baseline)
    finally:
        for sock in stalled:
            sock.close()
    metrics = server.client.get("/metrics").text
    evicted = [line for line in metrics.splitlines()
               if line.startswith('curvature_connections_closed_total{reason="evicted"}')]
    assert evicted and float(evicted[0].rsplit(" ", 1)[1]) >= STALLED - MAX_PENDING


def test_oversized_headers_get_431_and_keep_alive_requests_still_work(server):
    with socket.create_connection(("127.0.0.1", server.port)) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n" + b"X-Big: " + b"a" * 70_000)
        status, problem = _problem(_answer(sock))
    assert status == 431 and problem["type"] == "/problems/request-headers-too-large"
    # Several requests on one kept-alive connection, each with its headers in time.
    with httpx.Client(base_url=server.url, headers=server.headers) as client:
        for _ in range(3):
            assert client.get("/healthz").status_code == 200
            time.sleep(0.2)


def test_headers_and_a_large_body_in_one_write_are_not_taken_for_big_headers(server):
    points = [[i * 1e-3, (i % 97) * 1e-2, 1.0 + (i % 13) * 1e-3] for i in range(6000)]
    body = json.dumps({"points": points}).encode()
    assert len(body) > 2 * (64 << 10)
    head = (f"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {KEY_A}\r\n"
            "Content-Type: application/json\r\nConnection: close\r\n"
            f"Content-Length: {len(body)}\r\n\r\n").encode()
    with socket.create_connection(("127.0.0.1", server.port)) as sock:
        sock.sendall(head + body)
        raw = _answer(sock, 30.0)
    assert raw.startswith(b"HTTP/1.1 202"), raw[:300]


def test_a_slow_but_steady_client_within_the_timeout_is_served(server):
    with socket.create_connection(("127.0.0.1", server.port)) as sock:
        for part in (b"GET /healthz HTTP/1.1\r\n", b"Host: x\r\n", b"Connection: close\r\n",
                     b"\r\n"):
            sock.sendall(part)
            time.sleep(HEADER_TIMEOUT / 6)
        raw = _answer(sock)
    assert raw.startswith(b"HTTP/1.1 200"), raw[:200]
