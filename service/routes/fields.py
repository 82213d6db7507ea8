"""A finished job's result one field at a time, for viewers: the field listing, each field as
little-endian float32, and every field of one point."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import anyio
import anyio.to_thread
from fastapi import APIRouter, Depends, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse

from .. import result_fields
from ..dependencies import get_settings, get_store, owner_id
from ..problems import HTTPProblem, problem_responses
from ..result_files import CANONICAL_RESULT, ResultCorrupt
from ..settings import Settings
from ..store import JobStore
from .jobs import recompute, succeeded_job

router = APIRouter(prefix="/v1/jobs", tags=["jobs"],
                   responses=problem_responses("unauthorized", "job-not-found",
                                               "result-not-ready", "job-failed",
                                               "job-cancelled", "result-corrupt"))

# Conversions at once per process: each reads a result's file and holds one chunk.
MAX_CONCURRENT_CONVERSIONS = 2
FIELD_NAME = PathParam(description="A name from the field listing, e.g. k1, points, status.",
                       pattern=r"^[A-Za-z0-9_.-]{1,100}$")

FIELD_ENTRY = {"type": "object", "required": ["name", "components", "label", "unit", "scale"],
               "properties": {
                   "name": {"type": "string"},
                   "components": {"type": "integer", "description": "1 for scalars, 3 for "
                                  "points, normals and directions."},
                   "dtype": {"type": "string", "description": "How the result stores it."},
                   "label": {"type": "string"},
                   "unit": {"type": "string", "description": "Empty when dimensionless."},
                   "scale": {"type": "string", "enum": ["diverging", "sequential",
                                                         "categorical", "auto"],
                             "description": "How to color it: diverging (centred on 0), "
                                            "sequential, categorical codes, or auto "
                                            "(diverging when the values have both signs)."},
                   "limits": {"type": "array", "items": {"type": "number"}},
                   "categories": {"type": "object",
                                  "additionalProperties": {"type": "string"}}}}
LISTING = {"type": "object", "required": ["n", "up", "fields"], "properties": {
    "n": {"type": "integer", "description": "Number of points."},
    "up": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
           "description": "Up direction chosen from the cloud's principal axes "
                          "(preview.png's up=auto)."},
    "fields": {"type": "array", "items": FIELD_ENTRY}}}


def _limiter(request: Request) -> anyio.CapacityLimiter:
    limiter = getattr(request.app.state, "fields_limiter", None)
    if limiter is None:
        limiter = request.app.state.fields_limiter = anyio.CapacityLimiter(
            MAX_CONCURRENT_CONVERSIONS)
    return limiter


async def _run(request: Request, store: JobStore, settings: Settings, job_id: str,
               owner: str, work, *args):
    """``work(job_dir, *args, canonical_sha256)`` in a thread, for a succeeded job; a lost or
    corrupt result queues the job again (503 result-corrupt)."""
    job = await succeeded_job(store, job_id, owner)
    job_dir: Path = settings.jobs_dir / job_id
    try:
        return await anyio.to_thread.run_sync(work, job_dir, *args, job.result_sha256,
                                              limiter=_limiter(request))
    except FileNotFoundError as exc:  # deleted or expired while we looked, or lost
        raise await recompute(store, request.app.state.executor, settings, job,
                              f"{CANONICAL_RESULT} is missing ({exc.strerror})") from None
    except ResultCorrupt as exc:
        raise await recompute(store, request.app.state.executor, settings, job,
                              str(exc)) from None


@router.get("/{job_id}/result/fields", summary="List the per-point fields of a result",
            responses={200: {"description": "Number of points, the automatic up direction "
                             "and each field with its unit and color scale.",
                             "content": {"application/json": {"schema": LISTING}}}})
async def list_fields(
    job_id: str, request: Request, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
) -> dict:
    """The fields of the JSON result, in its order (positions, curvature and every other
    array of the result, shape index, curvedness, index, input attributes), each fetchable
    as float32 from ``/result/fields/{name}``."""
    doc = await _run(request, store, settings, job_id, owner, result_fields.manifest)
    return {"n": doc["n"], "up": doc["up"], "fields": doc["fields"]}


@router.get(
    "/{job_id}/result/fields/{name}", summary="One field of a result as float32",
    response_class=FileResponse,
    responses={200: {"description": "n x components little-endian float32 values, row-major "
                     "(x y z x y z ... for points); NaN where the result has no value. "
                     "X-Points and X-Components give the shape.",
                     "content": {"application/octet-stream": {"schema": {
                         "type": "string", "format": "binary"}}}},
               **problem_responses("field-not-found", "invalid-request")})
async def get_field(
    job_id: str, request: Request, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    name: Annotated[str, FIELD_NAME],
) -> FileResponse:
    """Compact and fast to load in a browser (a Float32Array over the body): 4 bytes per value
    instead of about 20 in JSON. Converted from the result on first request and kept with the
    job; integer fields (status, neighbor_count) are exact in float32 below 2^24."""
    try:
        path, entry = await _run(request, store, settings, job_id, owner,
                                 result_fields.field_file, name)
    except KeyError:
        raise HTTPProblem("field-not-found", f"the result of job {job_id} has no field "
                          f"{name!r}; GET /v1/jobs/{job_id}/result/fields lists them",
                          job_id=job_id) from None
    n = path.stat().st_size // (4 * entry["components"])
    return FileResponse(path, media_type="application/octet-stream", headers={
        "Content-Disposition": f'attachment; filename="{job_id}-{name}.f32"',
        "X-Points": str(n), "X-Components": str(entry["components"]),
        "Cache-Control": "private, no-cache"})


@router.get(
    "/{job_id}/result/points/{index}", summary="Every field of one point of a result",
    responses={200: {"description": "The point's values, float64 as stored, null where NaN.",
                     "content": {"application/json": {"schema": {
                         "type": "object", "required": ["index", "fields"], "properties": {
                             "index": {"type": "integer"},
                             "fields": {"type": "object", "additionalProperties": True}}}}}},
               **problem_responses("point-not-found", "invalid-request")})
async def get_point(
    job_id: str, request: Request, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    index: Annotated[int, PathParam(ge=0, le=2**40, description="Row of the result "
                                    "(0 to n - 1), as in the field arrays.")],
) -> dict:
    """What a viewer shows for a picked point: the same values as row ``index`` of the JSON
    result, read from the stored result without loading it."""
    try:
        values = await _run(request, store, settings, job_id, owner,
                            result_fields.point_values, index)
    except IndexError as exc:
        raise HTTPProblem("point-not-found", f"job {job_id}: {exc}", job_id=job_id) from None
    return {"index": index, "fields": values}
