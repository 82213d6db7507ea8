"""Catalog of problem types (RFC 9457) and the exception that carries one.

Kept free of web imports: the worker processes raise :class:`ProblemError` too, and it must
cross the process boundary (it pickles through its ``args``).
"""

from __future__ import annotations

from dataclasses import dataclass

TYPE_PREFIX = "/problems/"


@dataclass(frozen=True)
class ProblemType:
    """One stable kind of error: its slug (the end of the ``type`` URI), status and title."""

    slug: str
    status: int
    title: str
    description: str

    @property
    def uri(self) -> str:
        """The ``type`` member of a problem document (relative to the service's base URL)."""
        return TYPE_PREFIX + self.slug


_TYPES = [
    ProblemType("malformed-request", 400, "Malformed request",
                "The body is not valid JSON or multipart/form-data."),
    ProblemType("invalid-request", 422, "Invalid request",
                "A field, query parameter or form part is missing or has the wrong type."),
    ProblemType("invalid-parameters", 422, "Invalid parameters",
                "A method or fit parameter is unknown, out of bounds or inconsistent."),
    ProblemType("malformed-file", 422, "Malformed file",
                "The uploaded file could not be parsed (bad header, truncated body, bad value)."),
    ProblemType("unknown-format", 415, "Unknown file format",
                "The file extension names no format the service reads."),
    ProblemType("unsupported-media-type", 415, "Unsupported media type",
                "The request Content-Type must be multipart/form-data or application/json."),
    ProblemType("non-finite-coordinates", 422, "Non-finite coordinates",
                "At least one point has a NaN or infinite coordinate."),
    ProblemType("too-few-points", 422, "Too few points",
                "The cloud has fewer points than a curvature estimate needs."),
    ProblemType("invalid-cloud", 422, "Invalid cloud",
                "Points, normals or faces have the wrong shape or refer to missing vertices."),
    ProblemType("unauthorized", 401, "Unauthorized",
                "The request has no API key, or one the service does not accept; send "
                "'Authorization: Bearer <key>'."),
    ProblemType("too-large", 413, "Request too large",
                "The request body is larger than the configured limit."),
    ProblemType("cloud-too-large", 413, "Cloud too large",
                "The cloud has more points than the service accepts (CURVATURE_MAX_POINTS)."),
    ProblemType("too-many-points", 413, "Too many points for a synchronous answer",
                "The cloud is larger than the synchronous limit; submit it as a job."),
    ProblemType("too-costly", 413, "Too costly for a synchronous answer",
                "The parameters ask for more work than a synchronous answer may take "
                "(CURVATURE_SYNC_MAX_COST); use cheaper parameters or submit it as a job."),
    ProblemType("job-not-found", 404, "Job not found",
                "No job has this id (it never existed, was deleted or has expired)."),
    ProblemType("field-not-found", 404, "Field not found",
                "The job's result has no field of this name; GET /v1/jobs/{id}/result/fields "
                "lists them."),
    ProblemType("point-not-found", 404, "Point not found",
                "The point index is outside the result (0 to n - 1)."),
    ProblemType("result-not-ready", 409, "Result not ready",
                "The job is still queued or running; poll the job and retry."),
    ProblemType("job-failed", 409, "Job failed",
                "The job ended with an error, so it has no result; see the job's error."),
    ProblemType("job-cancelled", 409, "Job cancelled", "The job was cancelled; it has no result."),
    ProblemType("not-acceptable", 406, "Not acceptable",
                "No result format matches the Accept header or the format parameter."),
    ProblemType("too-many-jobs", 429, "Too many jobs",
                "This API key has too many unfinished jobs; retry after Retry-After seconds, "
                "or cancel some."),
    ProblemType("too-many-uploads", 429, "Too many uploads",
                "This API key has too many uploads in progress at once; retry after "
                "Retry-After seconds."),
    ProblemType("request-timeout", 408, "Request timeout",
                "The request headers or body arrived too slowly (a read timeout or the "
                "minimum upload rate); send it again on a faster connection."),
    ProblemType("request-headers-too-large", 431, "Request header fields too large",
                "The request line and headers together exceed the server's limit "
                "(CURVATURE_MAX_HEADER_BYTES)."),
    ProblemType("queue-full", 503, "Queue full",
                "Too many unfinished jobs or waiting requests; retry after Retry-After seconds."),
    ProblemType("store-busy", 503, "Job store busy",
                "The job store stayed locked longer than its timeout; nothing was changed. "
                "Retry after Retry-After seconds."),
    ProblemType("store-read-only", 503, "Job store read-only",
                "The job store or the data folder cannot be written (read-only file system or "
                "file); nothing was changed. Retry after Retry-After seconds."),
    ProblemType("result-corrupt", 503, "Result corrupt",
                "A stored result file failed its checksum or is missing; the job is computed "
                "again from its kept input. Retry after Retry-After seconds."),
    ProblemType("insufficient-storage", 507, "Insufficient storage",
                "The server's disk is full; nothing was stored. Retry later."),
    ProblemType("time-limit", 422, "Time limit exceeded",
                "The job ran longer than the per-job time limit; use a smaller cloud or "
                "cheaper parameters."),
    ProblemType("not-ready", 503, "Service not ready",
                "The service is starting or its job store or worker pool is unavailable."),
    ProblemType("cluster-unavailable", 503, "Compute cluster unavailable",
                "The Dask cluster (CURVATURE_DASK_ADDRESS) could not be reached, or lost the "
                "job's tiles more often than it retries them."),
    ProblemType("worker-crashed", 500, "Worker crashed",
                "The worker process running the job died repeatedly (e.g. out of memory)."),
    ProblemType("not-found", 404, "Not found", "No such path."),
    ProblemType("method-not-allowed", 405, "Method not allowed",
                "The path exists but not with this HTTP method."),
    ProblemType("internal-error", 500, "Internal error",
                "An unexpected error; it has been logged on the server."),
]

PROBLEM_TYPES: dict[str, ProblemType] = {t.slug: t for t in _TYPES}


class ProblemError(Exception):
    """An error that becomes a problem document with a known ``type``.

    Parameters
    ----------
    slug : str
        Key of :data:`PROBLEM_TYPES`.
    detail : str
        Human-readable explanation of this occurrence (never a traceback).
    """

    def __init__(self, slug: str, detail: str):
        if slug not in PROBLEM_TYPES:
            raise KeyError(f"unknown problem type {slug!r}")
        super().__init__(slug, detail)
        self.slug = slug
        self.detail = detail

    @property
    def kind(self) -> ProblemType:
        """The catalog entry."""
        return PROBLEM_TYPES[self.slug]

    def to_dict(self) -> dict:
        """``type``, ``title``, ``status`` and ``detail`` as stored in a job's ``error``."""
        kind = self.kind
        return {"type": kind.uri, "title": kind.title, "status": kind.status,
                "detail": self.detail}

    def __str__(self) -> str:
        return f"{self.slug}: {self.detail}"
