"""The HTTP client of the curvature service (httpx, synchronous)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import secrets
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from .errors import (
    CurvatureAPIError,
    CurvatureConnectionError,
    JobCancelledError,
    JobFailedError,
    JobTimeoutError,
)
from .models import Job, RemoteResult, job_id_of
from .progress import JobProgressBar

DEFAULT_URL = "http://127.0.0.1:8000"
RESULT_FORMATS = ("json", "ply", "csv", "npz")
PREVIEW_FIELDS = ("mean", "gaussian", "k1", "k2", "k1_std", "k2_std", "mean_std")
PREVIEW_VIEWS = ("iso", "front", "side", "top")
PREVIEW_UP_CHOICES = ("auto", "x", "-x", "y", "-y", "z", "-z")
# While waiting, a service that is briefly unreachable or not ready (restart) is retried for
# this long before the error is raised.
TRANSIENT_WINDOW = 30.0


def api_error(response: httpx.Response) -> CurvatureAPIError:
    """The exception for an error answer, carrying its problem document."""
    try:
        doc = json.loads(response.content)
    except ValueError:
        doc = None
    if not isinstance(doc, dict):
        text = response.content[:500].decode("utf-8", "replace").strip()
        doc = {"title": response.reason_phrase, "status": response.status_code,
               "detail": text}
    retry_after = response.headers.get("retry-after")
    try:
        seconds = float(retry_after) if retry_after is not None else None
    except ValueError:
        seconds = None
    return CurvatureAPIError(response.status_code, doc, seconds)


def format_from_path(path) -> str:
    """Result format named by a file's extension (``.ply``, ``.csv``, ``.npz``, ``.json``)."""
    ext = Path(path).suffix.lower().lstrip(".")
    if ext not in RESULT_FORMATS:
        raise ValueError(f"cannot tell the result format from {os.fspath(path)!r}; use an "
                         f"extension among {', '.join(RESULT_FORMATS)} or pass format=")
    return ext


def parse_npz(data: bytes) -> RemoteResult:
    """The arrays of an NPZ result (no pickled objects are loaded)."""
    with np.load(io.BytesIO(data), allow_pickle=False) as archive:
        return RemoteResult({name: archive[name] for name in archive.files})


def _npz_upload(points, normals=None, faces=None) -> bytes:
    """Arrays packed as the NPZ the service reads (exact float64, far smaller than JSON)."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"points: not a numeric array ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points: expected shape (n, 3), got {pts.shape}")
    arrays = {"points": pts}
    if normals is not None:
        arrays["normals"] = np.asarray(normals, dtype=np.float64)
    if faces is not None:
        arrays["faces"] = np.asarray(faces, dtype=np.int64)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


class CurvatureClient:
    """Submit clouds to a curvature service, follow the jobs and fetch their results.

    Parameters
    ----------
    url : str
        Base URL of the service, e.g. ``http://127.0.0.1:8000``.
    api_key : str, optional
        Sent as ``Authorization: Bearer <api_key>``.
    client_id : str, optional
        Sent as ``X-Client-Id`` (groups jobs for listing on services without keys).
    timeout : float
        Seconds for each HTTP request (not for a whole job: see :meth:`wait`).
    transport : httpx.BaseTransport, optional
        E.g. ``httpx.MockTransport`` in tests.

    Examples
    --------
    >>> with CurvatureClient("http://127.0.0.1:8000", api_key="...") as client:
    ...     job = client.submit("scan.ply", method="knn", k=24, fit="monge")
    ...     client.wait(job)
    ...     res = client.result(job)            # arrays: res.k1, res.mean, res.normals, ...
    ...     client.result(job, path="scan_curvature.ply")
    """

    def __init__(self, url: str = DEFAULT_URL, api_key: str | None = None, *,
                 client_id: str | None = None, timeout: float = 60.0,
                 transport: httpx.BaseTransport | None = None):
        headers = {"User-Agent": "curvature-client"}
        if api_key:
            headers["Authorization"] = f"Bearer {api_key}"
        if client_id:
            headers["X-Client-Id"] = client_id
        self.url = url.rstrip("/")
        self._http = httpx.Client(base_url=self.url, headers=headers, timeout=timeout,
                                  transport=transport)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> CurvatureClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- plumbing ---------------------------------------------------------------------------

    def _request(self, method: str, path: str, **kwargs) -> httpx.Response:
        try:
            response = self._http.request(method, path, **kwargs)
        except httpx.TransportError as exc:
            raise CurvatureConnectionError(f"{method} {self.url}{path}: {exc or type(exc)}") \
                from exc
        if response.status_code >= 400:
            raise api_error(response)
        return response

    @contextlib.contextmanager
    def _stream(self, path: str, **kwargs) -> Iterator[httpx.Response]:
        try:
            with self._http.stream("GET", path, **kwargs) as response:
                if response.status_code >= 400:
                    response.read()
                    raise api_error(response)
                yield response
        except httpx.TransportError as exc:
            raise CurvatureConnectionError(f"GET {self.url}{path}: {exc or type(exc)}") \
                from exc

    def _download(self, path: str, target, **kwargs) -> Path:
        """Stream an answer into ``target`` through a temporary file renamed into place."""
        target = Path(target)
        tmp = target.with_name(f".{target.name}.{secrets.token_hex(6)}.part")
        try:
            with self._stream(path, **kwargs) as response, open(tmp, "wb") as fh:
                for chunk in response.iter_bytes(1 << 20):
                    fh.write(chunk)
            os.replace(tmp, target)
        finally:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        return target

    # -- jobs -------------------------------------------------------------------------------

    def submit(self, cloud, method: str | None = None, *, normals=None, faces=None,
               filename: str | None = None, **params: Any) -> Job:
        """Queue a curvature job.

        Parameters
        ----------
        cloud : str, os.PathLike, array_like of shape (n, 3), or a PointCloud
            A file (uploaded as is; its format comes from its extension), an array of points,
            or any object with ``points`` (and optional ``normals``, ``faces``) attributes.
        method : str, optional
            Neighborhood method (``knn``, ``tc``, ``egg``, ``mesh``, ...; see
            :meth:`methods`). Default: the service's default method.
        normals : array_like, shape (n, 3), optional
            With array input: per-point normals (used for orientation).
        faces : array_like, shape (m, 3), optional
            With array input: triangles (for the ``mesh`` method and PLY results).
        filename : str, optional
            Name sent with the upload (its extension names the format).
        **params
            Method and fit parameters, e.g. ``k=24``, ``fit="monge"``,
            ``viewpoint=(0, 0, 10)``.

        Returns
        -------
        Job
            The queued job.

        Raises
        ------
        CurvatureAPIError
            The service refused the job (invalid parameters 422, too large 413, unknown
            format 415, queue full 503 with ``retry_after``, ...).
        FileNotFoundError
            ``cloud`` names a file that does not exist.
        ValueError
            Array input of the wrong shape.
        """
        form = {}
        if method is not None or params:
            if method is None:  # parameters must name their method: take the default one
                method = self.methods()["default_method"]
            form["params"] = json.dumps({"method": method, **params}, default=_json_default)
        if isinstance(cloud, str | os.PathLike):
            source = Path(cloud)
            if not source.is_file():
                raise FileNotFoundError(f"no such file: {os.fspath(source)!r}")
            with open(source, "rb") as fh:
                response = self._request("POST", "/v1/jobs", data=form,
                                         files={"file": (filename or source.name, fh)})
        else:
            if hasattr(cloud, "points"):
                normals = normals if normals is not None else getattr(cloud, "normals", None)
                faces = faces if faces is not None else getattr(cloud, "faces", None)
                cloud = cloud.points
            payload = _npz_upload(cloud, normals, faces)
            response = self._request("POST", "/v1/jobs", data=form,
                                     files={"file": (filename or "cloud.npz", payload)})
        return Job.from_json(response.json())

    def get(self, job) -> Job:
        """The job's current state."""
        return Job.from_json(self._request("GET", f"/v1/jobs/{job_id_of(job)}").json())

    def jobs(self, status: str | None = None, limit: int | None = None) -> list[Job]:
        """The caller's jobs, newest first (every page, up to ``limit`` jobs)."""
        found: list[Job] = []
        query: dict[str, Any] = {"limit": 200 if limit is None else min(max(limit, 1), 200)}
        if status:
            query["status"] = status
        while True:
            page = self._request("GET", "/v1/jobs", params=query).json()
            found.extend(Job.from_json(doc) for doc in page["items"])
            if not page.get("next_cursor") or (limit is not None and len(found) >= limit):
                return found[:limit] if limit is not None else found
            query["cursor"] = page["next_cursor"]

    def wait(self, job, *, progress: bool = True, timeout: float | None = 3600.0,
             poll_interval: float = 0.1, max_interval: float = 2.0, stream=None) -> Job:
        """Poll a job until it has finished; show a progress bar on stderr meanwhile.

        The polling interval starts at ``poll_interval`` and grows by half after every poll
        that saw no change, up to ``max_interval``. A service that is briefly unreachable or
        answers 503 (e.g. while it restarts) is polled again for up to 30 s.

        Parameters
        ----------
        job : Job or str
        progress : bool
            Draw a progress bar (on ``stream``, stderr by default).
        timeout : float or None
            Seconds to wait at most; ``None`` waits forever.
        poll_interval, max_interval : float
            Seconds between polls, first and largest.
        stream : file-like, optional

        Returns
        -------
        Job
            The succeeded job.

        Raises
        ------
        JobFailedError
            The job failed; ``problem`` is the job's error (e.g. a malformed file).
        JobCancelledError
            The job was cancelled.
        JobTimeoutError
            Still not finished after ``timeout`` seconds (the job keeps running).
        """
        job_id = job_id_of(job)
        deadline = None if timeout is None else time.monotonic() + timeout
        bar = JobProgressBar(job_id, stream) if progress else None
        interval, seen = poll_interval, None
        try:
            while True:
                current = self._poll(job_id, deadline)
                if bar is not None:
                    bar.update(current.status, current.progress)
                if current.is_final:
                    break
                if deadline is not None and time.monotonic() >= deadline:
                    raise JobTimeoutError(current, timeout)
                state = (current.status, current.progress)
                interval = poll_interval if state != seen else min(interval * 1.5,
                                                                   max_interval)
                seen = state
                pause = interval if deadline is None else min(interval,
                                                              deadline - time.monotonic())
                time.sleep(max(pause, 0.0))
        finally:
            if bar is not None:
                bar.close()
        if current.status == "failed":
            raise JobFailedError(current, current.error or {
                "title": "Job failed", "status": 409, "detail": f"job {job_id} failed"})
        if current.status == "cancelled":
            raise JobCancelledError(current, {
                "type": "/problems/job-cancelled", "title": "Job cancelled", "status": 409,
                "detail": f"job {job_id} was cancelled"})
        return current

    def _poll(self, job_id: str, deadline: float | None) -> Job:
        """:meth:`get`, retrying transient failures for a while."""
        give_up = time.monotonic() + TRANSIENT_WINDOW
        if deadline is not None:
            give_up = min(give_up, deadline)
        while True:
            try:
                return self.get(job_id)
            except CurvatureConnectionError:
                pause = 0.5
                if time.monotonic() >= give_up:
                    raise
            except CurvatureAPIError as exc:
                if exc.status != 503 or time.monotonic() >= give_up:
                    raise
                pause = min(exc.retry_after or 1.0, 5.0)
            time.sleep(max(min(pause, give_up - time.monotonic()), 0.0))

    def result(self, job, format: str | None = None, *, path=None):
        """A finished job's result: arrays, a parsed JSON document, bytes, or a file.

        Parameters
        ----------
        job : Job or str
        format : {"npz", "json", "ply", "csv"}, optional
            Default: from ``path``'s extension when a path is given, else ``npz``.
        path : str or os.PathLike, optional
            Write the result there (streamed to a temporary file, then renamed).

        Returns
        -------
        RemoteResult, dict, bytes or Path
            With ``path``: the path. Else ``npz`` gives a :class:`RemoteResult` of numpy
            arrays, ``json`` the parsed document, ``ply`` and ``csv`` the raw bytes.

        Raises
        ------
        CurvatureAPIError
            409 while the job is not finished (``result-not-ready``), or when it failed or
            was cancelled; 404 for an unknown job.
        """
        fmt = format or (format_from_path(path) if path is not None else "npz")
        if fmt not in RESULT_FORMATS:
            raise ValueError(f"format must be one of {', '.join(RESULT_FORMATS)}, got {fmt!r}")
        url = f"/v1/jobs/{job_id_of(job)}/result"
        if path is not None:
            return self._download(url, path, params={"format": fmt})
        response = self._request("GET", url, params={"format": fmt})
        if fmt == "npz":
            return parse_npz(response.content)
        if fmt == "json":
            return response.json()
        return response.content

    def preview(self, job, field: str = "mean", *, view: str = "iso", up: str = "auto",
                path=None):
        """PNG picture of a finished job's cloud colored by ``field`` (bytes, or a file);
        ``up`` is the world's up axis (``auto``: chosen from the cloud's principal axes)."""
        if field not in PREVIEW_FIELDS:
            raise ValueError(f"field must be one of {', '.join(PREVIEW_FIELDS)}, got {field!r}")
        if view not in PREVIEW_VIEWS:
            raise ValueError(f"view must be one of {', '.join(PREVIEW_VIEWS)}, got {view!r}")
        if up not in PREVIEW_UP_CHOICES:
            raise ValueError(f"up must be one of {', '.join(PREVIEW_UP_CHOICES)}, got {up!r}")
        url = f"/v1/jobs/{job_id_of(job)}/preview.png"
        query = {"field": field, "view": view, "up": up}
        if path is not None:
            return self._download(url, path, params=query)
        return self._request("GET", url, params=query).content

    def fields(self, job) -> dict:
        """The per-point fields of a finished job's result: ``n``, ``up`` and ``fields``
        (name, components, label, unit, scale of each)."""
        return self._request("GET", f"/v1/jobs/{job_id_of(job)}/result/fields").json()

    def field(self, job, name: str) -> np.ndarray:
        """One field of a finished job's result as float32, shape (n,) or (n, components):
        4 bytes a value, for when the whole result is not needed."""
        response = self._request("GET", f"/v1/jobs/{job_id_of(job)}/result/fields/{name}")
        values = np.frombuffer(response.content, dtype="<f4")
        width = int(response.headers.get("x-components", "1"))
        return values.reshape(-1, width) if width > 1 else values

    def point(self, job, index: int) -> dict:
        """Every field of one point of a finished job's result, as stored (``None``: NaN)."""
        return self._request("GET", f"/v1/jobs/{job_id_of(job)}/result/points/{int(index)}"
                             ).json()["fields"]

    def cancel(self, job) -> Job | None:
        """Cancel a queued or running job (returns it, now ``cancelled``); a job that has
        already finished is deleted with its files instead (returns ``None``)."""
        response = self._request("DELETE", f"/v1/jobs/{job_id_of(job)}")
        return None if response.status_code == 204 else Job.from_json(response.json())

    def methods(self) -> dict:
        """Methods, fit models and parameters with defaults and bounds (``/v1/methods``)."""
        return self._request("GET", "/v1/methods").json()


def _json_default(value):
    """Parameters given as numpy values or tuples (e.g. ``viewpoint``)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"parameter value {value!r} is not JSON serialisable")
