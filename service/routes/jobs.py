"""Asynchronous jobs: submit, inspect, list, download the result, cancel or delete."""

from __future__ import annotations

import shutil
from typing import Annotated, Literal

import anyio.to_thread
from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import FileResponse

from ..cleanup import remove_job_files
from ..dependencies import get_executor, get_metrics, get_settings, get_store, owner_id
from ..executor import LocalPoolExecutor
from ..formats import RESULT_FORMATS, RESULT_MEDIA_TYPES
from ..metrics import ServiceMetrics
from ..problem_types import ProblemError
from ..problems import HTTPProblem, problem_responses
from ..result_files import ResultCorrupt
from ..results import content_disposition, media_type, negotiate
from ..schemas import Job, JobError, JobInput, JobPage, JobResult, timestamp
from ..settings import Settings
from ..store import (
    CANCELLED,
    FAILED,
    QUEUED,
    RUNNING,
    STATUSES,
    SUCCEEDED,
    JobStore,
    QueueLimitError,
    new_job_id,
)
from ..store import Job as JobRecord
from ..uploads import receive_cloud

router = APIRouter(prefix="/v1/jobs", tags=["jobs"],
                   responses=problem_responses("unauthorized", "not-ready", "store-busy"))

# The file part's name must end in a known extension; OpenAPI cannot constrain a part's file
# name, so the encoding shows one (fuzzers such as schemathesis send it).
CLOUD_BODY = {"requestBody": {"required": True, "content": {
    "multipart/form-data": {
        "schema": {"$ref": "#/components/schemas/MultipartCloudRequest"},
        "encoding": {"file": {"contentType": "application/octet-stream", "headers": {
            "Content-Disposition": {
                "description": "The file name's extension names the format.",
                "schema": {"type": "string",
                           "example": 'form-data; name="file"; filename="cloud.xyz"'}}}},
            "params": {"contentType": "application/json"}}},
    "application/json": {"schema": {"$ref": "#/components/schemas/CloudRequest"}},
}}}
RESULT_CONTENT = {RESULT_MEDIA_TYPES[f].split(";")[0]: {"schema": {
    "type": "string", "format": "binary"}} for f in RESULT_FORMATS}
# The JSON result is a document, not bytes: columnar fields, NaN written as null.
RESULT_CONTENT["application/json"] = {"schema": {
    "type": "object", "required": ["n", "fields"], "properties": {
        "n": {"type": "integer", "minimum": 0, "description": "Number of points."},
        "fields": {"type": "object", "description": "One array of n values per field "
                   "(scalars, or [x, y, z] for points, normals and directions); null where a "
                   "value is NaN (status != 0).",
                   "additionalProperties": {"type": "array"}},
        "faces": {"type": "array", "description": "Triangles of the input mesh, if any.",
                  "items": {"type": "array", "items": {"type": "integer"}}},
        "info": {"type": "object", "description": "Method, parameters and timings."}}}}

ResultFormat = Literal[RESULT_FORMATS]


def job_view(job: JobRecord) -> Job:
    """The API form of a stored job."""
    base = f"/v1/jobs/{job.id}"
    links = {"self": base}
    result = None
    if job.status == SUCCEEDED:
        links["result"] = f"{base}/result"
        summary = job.summary or {}
        result = JobResult(formats=list(RESULT_FORMATS),
                           status_counts=summary.get("status_counts", {}),
                           dropped_points=summary.get("dropped_points", 0),
                           compute_seconds=summary.get("compute_seconds"),
                           tiles=summary.get("tiles"))
    return Job(
        id=job.id, status=job.status, progress=min(max(job.progress, 0.0), 1.0),
        method=job.params.get("method", ""), params=job.params,
        input=JobInput(kind=job.input_kind, filename=job.input_name, format=job.input_format,
                       bytes=job.input_bytes),
        n_points=job.n_points, attempts=job.attempts, restarts=job.restarts,
        created_at=timestamp(job.created_at),
        started_at=timestamp(job.started_at), finished_at=timestamp(job.finished_at),
        expires_at=timestamp(job.expires_at),
        error=JobError(**job.error) if job.error else None, result=result, links=links)


async def load_owned_job(store: JobStore, job_id: str, owner: str) -> JobRecord:
    """The caller's job; another owner's job is answered exactly like a missing one."""
    job = await anyio.to_thread.run_sync(store.get, job_id)
    if job is None or job.owner != owner:
        raise HTTPProblem("job-not-found", f"no job with id {job_id!r}", job_id=job_id)
    return job


async def succeeded_job(store: JobStore, job_id: str, owner: str) -> JobRecord:
    """The caller's job, which must have succeeded: 409 while queued or running (with
    Retry-After), or when it failed or was cancelled."""
    job = await load_owned_job(store, job_id, owner)
    if job.status in (QUEUED, RUNNING):
        raise HTTPProblem("result-not-ready", f"job {job_id} is {job.status} "
                          f"({job.progress:.0%} done); retry later",
                          headers={"Retry-After": "1"}, job_id=job_id, job_status=job.status)
    if job.status == FAILED:
        detail = (job.error or {}).get("detail", "the job failed")
        raise HTTPProblem("job-failed", f"job {job_id} failed: {detail}", job_id=job_id)
    if job.status == CANCELLED:
        raise HTTPProblem("job-cancelled", f"job {job_id} was cancelled", job_id=job_id)
    return job


def _queue_problem(settings: Settings, scope: str, count: int, limit: int) -> HTTPProblem:
    retry = {"Retry-After": str(settings.retry_after_seconds)}
    if scope == "owner":
        return HTTPProblem("too-many-jobs", f"this API key has {count} unfinished jobs; the "
                           f"limit is {limit} per key (CURVATURE_MAX_JOBS_PER_KEY)",
                           headers=retry)
    return HTTPProblem("queue-full", f"{count} jobs are queued or running; the limit is "
                       f"{limit} (CURVATURE_MAX_QUEUED_JOBS)", headers=retry)


@router.post(
    "", status_code=202, response_model=Job, openapi_extra=CLOUD_BODY,
    summary="Submit a cloud for curvature estimation",
    responses={202: {"description": "Accepted and queued; Location gives the job's URL."},
               **problem_responses("malformed-request", "invalid-request", "invalid-parameters",
                                   "malformed-file", "store-read-only",
                                   "too-many-uploads", "request-timeout",
                                   "non-finite-coordinates", "too-large", "cloud-too-large",
                                   "unknown-format", "too-many-jobs", "queue-full",
                                   "insufficient-storage")},
)
async def submit_job(
    request: Request, response: Response, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    executor: Annotated[LocalPoolExecutor, Depends(get_executor)],
    metrics: Annotated[ServiceMetrics, Depends(get_metrics)],
) -> Job:
    """Upload a file (multipart: ``file`` + optional ``params`` JSON) or send JSON arrays.

    The input and a ``queued`` job are stored before anything runs; the answer is 202 with
    ``Location: /v1/jobs/{id}``. Problems in the file itself (malformed, too few points,
    more than the point limit) show up as a ``failed`` job with an ``error`` once a worker has
    read it. 429 when the key has too many unfinished jobs, 503 when the whole queue is full
    (both with ``Retry-After``), 507 when the disk is full.
    """
    # Cheap checks first, so a refused client does not upload a big file for nothing; the
    # insert checks again, atomically, against concurrent submissions.
    mine, everyone = await anyio.to_thread.run_sync(
        lambda: (store.count_unfinished(owner), store.count_unfinished()))
    if mine >= settings.max_jobs_per_key:
        raise _queue_problem(settings, "owner", mine, settings.max_jobs_per_key)
    if everyone >= settings.max_queued_jobs:
        raise _queue_problem(settings, "total", everyone, settings.max_queued_jobs)
    job_id = new_job_id()
    folder = settings.jobs_dir / job_id
    try:
        with request.app.state.busy_folders.hold(job_id):
            folder.mkdir(parents=True)
            received = await receive_cloud(request, folder, settings, owner)
            if received.n_points is not None and received.n_points > settings.max_points:
                raise HTTPProblem("cloud-too-large", (
                    f"the cloud has {received.n_points} points; this service accepts at "
                    f"most {settings.max_points} (CURVATURE_MAX_POINTS)"))
            job = await anyio.to_thread.run_sync(lambda: store.insert(
                job_id=job_id, owner=owner, params=received.params, input_kind=received.kind,
                input_file=received.input_file, input_name=received.filename,
                input_format=received.format, input_bytes=received.size,
                n_points=received.n_points, max_unfinished=settings.max_queued_jobs,
                max_owner_unfinished=settings.max_jobs_per_key))
    except QueueLimitError as exc:
        shutil.rmtree(folder, ignore_errors=True)
        raise _queue_problem(settings, exc.scope, exc.count, exc.limit) from None
    except BaseException:
        # Nothing was accepted: no row, and no files left to fill the disk.
        shutil.rmtree(folder, ignore_errors=True)
        raise
    metrics.jobs_submitted.inc(input=received.kind)
    metrics.upload_bytes.inc(received.size)
    executor.wake()
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    return job_view(job)


@router.get("", response_model=JobPage, summary="List the caller's jobs, newest first",
            responses=problem_responses("invalid-request"))
def list_jobs(
    response: Response, owner: Annotated[str, Depends(owner_id)],
    store: Annotated[JobStore, Depends(get_store)],
    limit: Annotated[int, Query(ge=1, le=200, description="Page size.")] = 20,
    cursor: Annotated[str | None, Query(pattern=r"^[0-9]{1,18}$",
                                        description="next_cursor of the previous page.")] = None,
    status: Annotated[Literal[STATUSES] | None, Query(description="Only this status.")] = None,
) -> JobPage:
    """Jobs submitted with the caller's API key (all jobs when the service runs without keys),
    keyset-paginated."""
    before = int(cursor) if cursor else None
    rows = store.list_jobs(owner, limit=limit + 1, before_seq=before, status=status)
    page, more = rows[:limit], len(rows) > limit
    next_cursor = str(page[-1].seq) if more and page else None
    if next_cursor:
        query = f"limit={limit}&cursor={next_cursor}" + (f"&status={status}" if status else "")
        response.headers["Link"] = f'</v1/jobs?{query}>; rel="next"'
    return JobPage(items=[job_view(j) for j in page], next_cursor=next_cursor)


@router.get("/{job_id}", response_model=Job, summary="Status, progress and error of a job",
            responses=problem_responses("job-not-found"))
async def get_job(job_id: str, owner: Annotated[str, Depends(owner_id)],
                  store: Annotated[JobStore, Depends(get_store)]) -> Job:
    """Another key's job is answered 404, like a job that does not exist."""
    return job_view(await load_owned_job(store, job_id, owner))


@router.get(
    "/{job_id}/result", summary="Download a finished job's result",
    response_class=FileResponse,
    responses={200: {"description": "The result in the negotiated format: "
                     + ", ".join(f"{f} as {RESULT_MEDIA_TYPES[f]}" for f in RESULT_FORMATS),
                     "content": RESULT_CONTENT},
               **problem_responses("job-not-found", "result-not-ready", "job-failed",
                                   "not-acceptable", "invalid-request",
                                   "insufficient-storage", "result-corrupt")},
)
async def get_result(
    job_id: str, request: Request, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    executor: Annotated[LocalPoolExecutor, Depends(get_executor)],
    format: Annotated[ResultFormat | None, Query(
        description="Result format; wins over the Accept header.")] = None,
) -> FileResponse:
    """The format comes from ``?format=``, else from Accept (``application/json``,
    ``application/x-ply`` / ``model/ply`` / ``application/octet-stream``, ``text/csv``,
    ``application/x-npz``), else JSON. JSON is columnar with NaN as null; PLY is binary with
    the input faces; 409 while the job is queued or running."""
    fmt = negotiate(format, request.headers.get("accept"))
    job = await succeeded_job(store, job_id, owner)
    expected = (job.checksums or {}).get(fmt)
    try:
        path, digest = await executor.render(settings.jobs_dir / job_id, fmt,
                                             job.result_sha256, expected)
    except ResultCorrupt as exc:
        raise await recompute(store, executor, settings, job, str(exc)) from None
    if digest != expected and fmt != "npz":
        await anyio.to_thread.run_sync(store.set_checksum, job_id, fmt, digest)
    return FileResponse(path, media_type=media_type(fmt), headers={
        "Content-Disposition": content_disposition(job_id, fmt), "Vary": "Accept"})


async def recompute(store: JobStore, executor: LocalPoolExecutor, settings: Settings,
                     job: JobRecord, why: str) -> HTTPProblem:
    """A succeeded job's stored result is lost: queue it again from its kept input, or fail
    it when the input is gone too; the problem to answer either way."""
    folder = settings.jobs_dir / job.id
    retry = {"Retry-After": str(settings.retry_after_seconds)}
    if await anyio.to_thread.run_sync(store.get, job.id) is None:  # deleted meanwhile
        return HTTPProblem("job-not-found", f"no job with id {job.id!r}", job_id=job.id)
    if (folder / job.input_file).is_file():
        if await anyio.to_thread.run_sync(store.requeue_for_recompute, job.id):
            for stale in folder.glob("result.*"):
                stale.unlink(missing_ok=True)
            executor.wake()
        return HTTPProblem("result-corrupt", f"the stored result of job {job.id} is lost "
                           f"({why}); the job has been queued to compute it again from its "
                           "input: poll the job and retry", headers=retry, job_id=job.id)
    error = ProblemError("result-corrupt", f"the stored result is lost ({why}) and the input "
                         "is gone too; submit the cloud again").to_dict()
    await anyio.to_thread.run_sync(lambda: store.fail_lost(job.id, error))
    return HTTPProblem("result-corrupt", f"job {job.id}: {error['detail']}", headers=retry,
                       job_id=job.id)


@router.delete(
    "/{job_id}", response_model=Job, summary="Cancel a job, or delete a finished one",
    responses={204: {"description": "The finished job and its files were deleted."},
               **problem_responses("job-not-found")},
)
async def delete_job(
    job_id: str, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    executor: Annotated[LocalPoolExecutor, Depends(get_executor)],
) -> Job | Response:
    """A queued or running job is cancelled (200 with the job, status ``cancelled``; a running
    computation stops at its next progress report). A finished job is deleted with its files
    (204)."""
    job = await load_owned_job(store, job_id, owner)
    if not job.is_final:
        cancelled = await anyio.to_thread.run_sync(store.cancel, job_id,
                                                   settings.result_ttl_seconds)
        if cancelled is not None:
            executor.cancel(job_id)
            return job_view(cancelled)
        job = await load_owned_job(store, job_id, owner)  # it finished meanwhile: delete it below
    await anyio.to_thread.run_sync(store.delete, job_id)
    await anyio.to_thread.run_sync(remove_job_files, settings, job_id)
    return Response(status_code=204)
