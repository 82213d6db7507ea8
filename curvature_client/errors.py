"""Exceptions of the client: every one carries what the service said, if it said anything."""

from __future__ import annotations


class CurvatureClientError(Exception):
    """Base class of every error the client raises."""


class CurvatureConnectionError(CurvatureClientError):
    """The service could not be reached, or the connection broke (no HTTP answer)."""


class CurvatureAPIError(CurvatureClientError):
    """The service answered with an error (an ``application/problem+json`` document).

    Parameters
    ----------
    status : int
        HTTP status of the answer.
    problem : dict
        The problem document (``type``, ``title``, ``status``, ``detail``, ``instance`` and
        any extension members); for a non-problem answer, ``title`` and ``detail`` are made up
        from the status line and the start of the body.
    retry_after : float, optional
        Seconds from the ``Retry-After`` header (503 queue full, 409 not ready).

    Attributes
    ----------
    status, problem, retry_after
        As given.
    type, title, detail : str
        Shortcuts into ``problem``.
    """

    def __init__(self, status: int, problem: dict, retry_after: float | None = None):
        self.status = status
        self.problem = dict(problem)
        self.retry_after = retry_after
        super().__init__(self._message())

    @property
    def type(self) -> str:
        return str(self.problem.get("type") or "about:blank")

    @property
    def title(self) -> str:
        return str(self.problem.get("title") or "")

    @property
    def detail(self) -> str:
        return str(self.problem.get("detail") or "")

    def _message(self) -> str:
        text = f"{self.status} {self.title}".strip()
        if self.detail:
            text += f": {self.detail}"
        return f"{text} ({self.type})"


class JobFailedError(CurvatureAPIError):
    """A job ended ``failed`` (or ``cancelled``: :class:`JobCancelledError`).

    ``problem`` is the job's ``error`` document (for a cancelled job, one made up here), and
    ``job`` the final state of the job.
    """

    def __init__(self, job, problem: dict):
        self.job = job
        super().__init__(int(problem.get("status") or 409), problem)


class JobTimeoutError(CurvatureClientError, TimeoutError):
    """A job did not finish within the time :meth:`CurvatureClient.wait` was given.

    ``job`` is its last known state; it keeps running on the service.
    """

    def __init__(self, job, timeout: float):
        self.job = job
        self.timeout = timeout
        super().__init__(f"job {job.id} is still {job.status} ({job.progress:.0%} done) after "
                         f"{timeout:g} s; it keeps running on the service")


class JobCancelledError(JobFailedError):
    """A job ended ``cancelled``; ``problem`` says so (type ``/problems/job-cancelled``)."""
