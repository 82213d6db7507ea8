"""A minimal Prometheus registry rendered in the text exposition format (version 0.0.4).

Hand-written to avoid a dependency for a few counters; label values are escaped as the format
requires. Gauges that reflect the job store are filled in at scrape time.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


def _escape(value: str) -> str:
    return str(value).replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


def _labels(key: tuple) -> str:
    if not key:
        return ""
    return "{" + ",".join(f'{k}="{_escape(v)}"' for k, v in key) + "}"


def _number(value: float) -> str:
    return repr(float(value)) if isinstance(value, float) else str(value)


class Metric:
    """A counter or gauge family: one value per label set."""

    def __init__(self, name: str, kind: str, help_text: str):
        self.name, self.kind, self.help = name, kind, help_text
        self._values: dict[tuple, float] = defaultdict(float)
        self._lock = threading.Lock()

    def inc(self, amount: float = 1.0, **labels: str) -> None:
        with self._lock:
            self._values[tuple(sorted(labels.items()))] += amount

    def set(self, value: float, **labels: str) -> None:
        with self._lock:
            self._values[tuple(sorted(labels.items()))] = value

    def render(self) -> list[str]:
        lines = [f"# HELP {self.name} {self.help}", f"# TYPE {self.name} {self.kind}"]
        with self._lock:
            items = sorted(self._values.items())
        lines += [f"{self.name}{_labels(k)} {_number(v)}" for k, v in items]
        return lines


class Summary:
    """Sum and count of observations per label set (a Prometheus summary without quantiles)."""

    def __init__(self, name: str, help_text: str):
        self.name, self.help = name, help_text
        self._sum: dict[tuple, float] = defaultdict(float)
        self._count: dict[tuple, int] = defaultdict(int)
        self._lock = threading.Lock()

    def observe(self, value: float, **labels: str) -> None:
        key = tuple(sorted(labels.items()))
        with self._lock:
            self._sum[key] += value
            self._count[key] += 1

    def render(self) -> list[str]:
        lines = [f"# HELP {self.name} {self.help}", f"# TYPE {self.name} summary"]
        with self._lock:
            keys = sorted(self._count)
            for k in keys:
                lines.append(f"{self.name}_sum{_labels(k)} {_number(self._sum[k])}")
                lines.append(f"{self.name}_count{_labels(k)} {self._count[k]}")
        return lines


class ServiceMetrics:
    """The service's metric families."""

    def __init__(self):
        self.requests = Metric("curvature_http_requests_total", "counter",
                               "HTTP requests by method, route template and status code.")
        self.request_seconds = Summary("curvature_http_request_duration_seconds",
                                       "Time to answer HTTP requests, by route template.")
        self.jobs_submitted = Metric("curvature_jobs_submitted_total", "counter",
                                     "Jobs accepted, by input kind.")
        self.jobs_finished = Metric("curvature_jobs_finished_total", "counter",
                                    "Job runs that ended in this process, by outcome.")
        self.job_seconds = Summary("curvature_job_run_seconds",
                                   "Wall time of job runs in the pool, by outcome.")
        self.upload_bytes = Metric("curvature_upload_bytes_total", "counter",
                                   "Bytes of accepted request bodies.")
        self.sync_requests = Metric("curvature_sync_requests_total", "counter",
                                    "Synchronous curvature requests answered, by format.")
        self.sync_stopped = Metric("curvature_sync_stopped_total", "counter",
                                   "Synchronous runs ended by killing their process, by reason "
                                   "(time-limit, disconnect, crashed).")
        self.problems = Metric("curvature_problems_total", "counter",
                               "Problem responses sent, by problem type.")
        self.jobs = Metric("curvature_jobs", "gauge", "Jobs in the store, by status.")
        self.pool_workers = Metric("curvature_pool_workers", "gauge",
                                   "Worker processes of the local pool.")
        self.pool_busy = Metric("curvature_pool_jobs_in_flight", "gauge",
                                "Jobs handed to the pool and not yet finished.")
        self.ready = Metric("curvature_ready", "gauge", "1 when the service accepts work.")
        self.connections_closed = Metric(
            "curvature_connections_closed_total", "counter", "Connections closed before their "
            "request headers were complete, by reason (header_timeouts, headers_too_large, "
            "evicted).")

    def render(self) -> str:
        from .http_guard import STATS

        for reason, count in STATS.items():
            self.connections_closed.set(count, reason=reason)
        families = [self.requests, self.request_seconds, self.jobs_submitted, self.jobs_finished,
                    self.job_seconds, self.upload_bytes, self.sync_requests, self.sync_stopped,
                    self.problems,
                    self.jobs, self.pool_workers, self.pool_busy, self.ready,
                    self.connections_closed]
        lines: list[str] = []
        for family in families:
            lines += family.render()
        return "\n".join(lines) + "\n"


class RequestMetricsMiddleware:
    """Counts requests by route template (not raw path, to keep label cardinality bounded)."""

    def __init__(self, app, metrics: ServiceMetrics):
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = {"code": 500}

        async def recording_send(message):
            if message["type"] == "http.response.start":
                status["code"] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, recording_send)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            self.metrics.requests.inc(method=scope.get("method", ""), route=template,
                                      status=str(status["code"]))
            self.metrics.request_seconds.observe(time.perf_counter() - start, route=template)
