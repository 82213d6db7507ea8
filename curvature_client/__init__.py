"""Python client of the curvature service: submit clouds, follow jobs, fetch results.

::

    from curvature_client import CurvatureClient

    with CurvatureClient("http://127.0.0.1:8000", api_key="...") as client:
        job = client.submit("scan.ply", method="knn", k=24, fit="monge")
        client.wait(job)                       # progress bar on stderr
        res = client.result(job)               # numpy arrays: res.k1, res.mean, ...

Needs only httpx and numpy (``pip install 'curvature[client]'``). The module
``curvature_client.cli`` adds ``curvature remote ...`` to the command line.
"""

from .client import DEFAULT_URL, RESULT_FORMATS, CurvatureClient
from .errors import (
    CurvatureAPIError,
    CurvatureClientError,
    CurvatureConnectionError,
    JobCancelledError,
    JobFailedError,
    JobTimeoutError,
)
from .models import Job, RemoteResult

__all__ = [
    "DEFAULT_URL",
    "RESULT_FORMATS",
    "CurvatureAPIError",
    "CurvatureClient",
    "CurvatureClientError",
    "CurvatureConnectionError",
    "Job",
    "JobCancelledError",
    "JobFailedError",
    "JobTimeoutError",
    "RemoteResult",
]
