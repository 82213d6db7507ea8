"""Preview pictures of a finished job: its cloud colored by a curvature field (PNG)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import anyio
import anyio.to_thread
import numpy as np
from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import FileResponse

import curvature

from ..dependencies import get_settings, get_store, owner_id
from ..problems import problem_responses
from ..result_files import CANONICAL_RESULT, ResultCorrupt, matches
from ..settings import Settings
from ..store import JobStore
from .jobs import recompute, succeeded_job

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

PreviewField = Literal[tuple(curvature.PREVIEW_FIELDS)]
PreviewView = Literal[tuple(curvature.PREVIEW_VIEWS)]
PreviewUp = Literal[tuple(curvature.PREVIEW_UP_CHOICES)]
# Renders at once per process: each holds a result's points in memory and a CPU core.
MAX_CONCURRENT_RENDERS = 2


def preview_path(job_dir: Path, field: str, view: str, up: str = "auto") -> Path:
    """Where the PNG of ``field`` seen from ``view`` with ``up`` is cached in the job's
    folder."""
    return job_dir / f"preview-{field}-{view}-up{up}.png"


def render_cached(job_dir: Path, field: str, view: str, up: str = "auto",
                  canonical_sha256: str | None = None) -> Path:
    """The cached PNG, rendered from the canonical result on first request.

    Only the two arrays the picture needs are read from the (uncompressed) result archive,
    not the whole result: a 1M-point result is then about 32 MB in memory, not 150.

    Raises
    ------
    FileNotFoundError
        The job's files are gone (deleted or expired).
    ResultCorrupt
        The canonical result fails its checksum ``canonical_sha256``, or was computed by a
        version that did not have ``field`` (the job is then computed again).
    """
    target = preview_path(job_dir, field, view, up)
    if not target.exists():
        if (job_dir / CANONICAL_RESULT).exists() and not matches(job_dir / CANONICAL_RESULT,
                                                                 canonical_sha256):
            raise ResultCorrupt(f"{CANONICAL_RESULT} fails its checksum")
        with np.load(job_dir / CANONICAL_RESULT, allow_pickle=False) as archive:
            if field not in archive.files:  # computed by a version without that field
                raise ResultCorrupt(f"{CANONICAL_RESULT} predates the field {field!r}")
            arrays = {"points": archive["points"], field: archive[field]}
        curvature.render_preview(arrays, field, view=view, up=up, path=target)  # atomic
    return target


def _limiter(request: Request) -> anyio.CapacityLimiter:
    limiter = getattr(request.app.state, "preview_limiter", None)
    if limiter is None:
        limiter = request.app.state.preview_limiter = anyio.CapacityLimiter(
            MAX_CONCURRENT_RENDERS)
    return limiter


@router.get(
    "/{job_id}/preview.png", summary="Picture of a finished job colored by curvature",
    response_class=FileResponse,
    responses={200: {"description": "PNG (800 x 600): the cloud seen from a fixed camera, "
                                    "colored by the field, with a color bar.",
                     "content": {"image/png": {"schema": {"type": "string",
                                                          "format": "binary"}}}},
               **problem_responses("job-not-found", "result-not-ready", "job-failed",
                                   "job-cancelled", "invalid-request", "unauthorized",
                                   "result-corrupt")},
)
async def get_preview(
    job_id: str, request: Request, owner: Annotated[str, Depends(owner_id)],
    settings: Annotated[Settings, Depends(get_settings)],
    store: Annotated[JobStore, Depends(get_store)],
    field: Annotated[PreviewField, Query(description="Field that gives the colors.")] = "mean",
    view: Annotated[PreviewView, Query(
        description="Camera preset around the up axis; with z up: iso (from +x, -y, +z), "
                    "front (from -y), side (from +x) or top (from +z).")] = "iso",
    up: Annotated[PreviewUp, Query(
        description="The world's up axis; auto chooses it from the cloud's principal axes "
                    "(a flat scene's normal, towards the origin's side; else the axis along "
                    "which the cloud sits off the origin; else z).")] = "auto",
) -> FileResponse:
    """The cloud of a succeeded job, orthographic from a camera preset, colored by ``field``
    between its 2nd and 98th percentile (symmetric around 0 with a diverging map for mean and
    Gaussian curvature); points without a value are grey. Large clouds are drawn from a
    fixed subsample of 400,000 points. Rendered on first request and kept with the job."""
    job = await succeeded_job(store, job_id, owner)
    try:
        path = await anyio.to_thread.run_sync(render_cached, settings.jobs_dir / job_id, field,
                                              view, up, job.result_sha256,
                                              limiter=_limiter(request))
    except FileNotFoundError as exc:  # deleted or expired while we looked, or lost
        raise await recompute(store, request.app.state.executor, settings, job,
                              f"{CANONICAL_RESULT} is missing ({exc.strerror})") from None
    except ResultCorrupt as exc:
        raise await recompute(store, request.app.state.executor, settings, job,
                              str(exc)) from None
    return FileResponse(path, media_type="image/png", headers={
        "Content-Disposition": f'inline; filename="{job_id}-{field}-{view}-up{up}.png"',
        "Cache-Control": "private, max-age=86400"})
