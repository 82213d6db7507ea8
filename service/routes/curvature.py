"""Synchronous curvature of small clouds."""

from __future__ import annotations

import shutil
import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from ..dependencies import get_executor, get_metrics, get_settings, owner_id
from ..executor import LocalPoolExecutor
from ..formats import RESULT_MEDIA_TYPES
from ..metrics import ServiceMetrics
from ..problems import HTTPProblem, problem_responses
from ..results import content_disposition, media_type, negotiate
from ..settings import Settings
from ..sync_cost import sync_cost_problem
from ..sync_lane import SyncAborted
from ..uploads import receive_cloud
from .jobs import CLOUD_BODY, RESULT_CONTENT, ResultFormat

# Computing costs the operator: only holders of a key may ask (when keys are configured).
router = APIRouter(prefix="/v1", tags=["curvature"], dependencies=[Depends(owner_id)],
                   responses=problem_responses("unauthorized"))


async def client_gone(request: Request) -> None:
    """Return once the client has closed the connection (the body is already read, so the
    next ASGI message can only be the disconnect)."""
    while True:
        message = await request.receive()
        if message["type"] == "http.disconnect":
            return


@router.post(
    "/curvature", summary="Curvature of a small cloud, answered right away",
    response_class=FileResponse, openapi_extra=CLOUD_BODY,
    responses={200: {"description": "The result in the negotiated format ("
                     + ", ".join(f"{f}: {m}" for f, m in RESULT_MEDIA_TYPES.items()) + ")",
                     "content": RESULT_CONTENT},
               **problem_responses("malformed-request", "invalid-request", "invalid-parameters",
                                   "malformed-file", "non-finite-coordinates", "too-few-points",
                                   "too-large", "too-many-points", "unknown-format",
                                   "not-acceptable", "queue-full", "insufficient-storage",
                                   "too-costly", "time-limit", "cloud-too-large",
                                   "too-many-uploads", "request-timeout")},
)
async def curvature_now(
    request: Request,
    owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    executor: Annotated[LocalPoolExecutor, Depends(get_executor)],
    metrics: Annotated[ServiceMetrics, Depends(get_metrics)],
    format: Annotated[ResultFormat | None, Query(
        description="Result format; wins over the Accept header.")] = None,
) -> FileResponse:
    """Same input as ``POST /v1/jobs``; the answer is the result itself (JSON by default, or
    as negotiated like a job result). Clouds above the synchronous point limit get 413
    ``too-many-points``, and parameters whose work explodes (EGG/TC candidates,
    ``min_neighbors``) 413 ``too-costly``: submit those as jobs. The computation runs in a
    process of its own, killed after the synchronous time limit (422 ``time-limit``) or as
    soon as the client disconnects."""
    fmt = negotiate(format, request.headers.get("accept"))
    if executor.sync_waiting >= settings.max_pending_sync:
        raise HTTPProblem(
            "queue-full", f"{executor.sync_waiting} synchronous requests are already waiting",
            headers={"Retry-After": str(settings.retry_after_seconds)})
    name = uuid.uuid4().hex
    folder = settings.tmp_dir / name
    try:
        with request.app.state.busy_folders.hold(name):
            folder.mkdir(parents=True)
            received = await receive_cloud(request, folder, settings, owner)
            if received.n_points is not None and received.n_points > settings.sync_max_points:
                raise HTTPProblem("too-many-points", (
                    f"the cloud has {received.n_points} points; synchronous answers are "
                    f"limited to {settings.sync_max_points}; submit it to POST /v1/jobs"))
            if received.n_points is not None:
                too_costly = sync_cost_problem(received.params, received.n_points,
                                               settings.sync_max_cost)
                if too_costly is not None:
                    raise HTTPProblem("too-costly", too_costly)
            path = await executor.run_sync(
                str(folder / received.input_file), received.kind, received.filename,
                received.params, fmt, str(folder), settings.sync_max_points,
                settings.estimate_workers, settings.sync_max_cost,
                disconnected=client_gone(request))
    except SyncAborted:
        shutil.rmtree(folder, ignore_errors=True)
        # Nobody is listening; the client closed the connection before the answer.
        return Response(status_code=499)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    metrics.sync_requests.inc(format=fmt)
    metrics.upload_bytes.inc(received.size)
    return FileResponse(path, media_type=media_type(fmt),
                        headers={"Content-Disposition": content_disposition("curvature", fmt),
                                 "Vary": "Accept"},
                        background=BackgroundTask(shutil.rmtree, folder, ignore_errors=True))
