"""The FastAPI application: wiring, lifespan (store, pool, cleanup) and the OpenAPI document."""

from __future__ import annotations

import asyncio
import logging
from contextlib import asynccontextmanager, suppress

import anyio.to_thread
from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

import curvature

from . import problems
from .auth import is_loopback, load_keyring
from .cleanup import BusyFolders, cleanup_loop, sweep
from .datalock import DataDirLock
from .executor import create_executor
from .metrics import RequestMetricsMiddleware, ServiceMetrics
from .middleware import HygieneMiddleware, install_log_redaction
from .problem_types import PROBLEM_TYPES, ProblemError
from .problems import PROBLEM_MEDIA_TYPE
from .routes import api_docs, fields, health, jobs, methods, preview, ui
from .routes import curvature as curvature_routes
from .routes import problems as problem_routes
from .schemas import CloudRequest, MultipartCloudRequest, Problem
from .settings import Settings
from .store import JobStore

log = logging.getLogger("service")

DESCRIPTION = """\
Per-point principal curvatures (k1 >= k2), mean and Gaussian curvature, normals and principal
directions of 3D point clouds and meshes, by local quadric fitting over a choice of
neighborhoods.

Submit a cloud as a job (`POST /v1/jobs`), poll it (`GET /v1/jobs/{id}`) and download the result
(`GET /v1/jobs/{id}/result`) as JSON, binary PLY, CSV or NPZ; small clouds can be answered right
away (`POST /v1/curvature`). Errors are `application/problem+json` documents whose `type` is
stable and documented under `/problems/{slug}`.
"""

INTERRUPTED = ProblemError(
    "worker-crashed", "the service was restarted while this job ran, too many times "
    "(CURVATURE_MAX_RESTARTS)").to_dict()


@asynccontextmanager
async def lifespan(app: FastAPI):
    """Load the API keys, open the store, re-queue interrupted jobs, remove what interrupted
    uploads left, start the pool and the cleanup task."""
    settings: Settings = app.state.settings
    if app.state.keyring is None:  # a second start of the same app keeps the first ring
        app.state.keyring = load_keyring(settings)
        # From here on only the keys' digests are kept.
        app.state.settings = settings = settings.model_copy(update={"api_keys": None})
    if not app.state.keyring.enabled:
        log.warning("no API keys configured: every caller shares one anonymous owner and "
                    "sees every job; %s (set CURVATURE_API_KEYS to require keys)",
                    f"listening on loopback ({settings.host}) only" if is_loopback(settings.host)
                    else f"OPEN to anyone reaching {settings.host} (CURVATURE_ALLOW_OPEN)")
    # `python -m service` takes the lock before binding; an embedding app takes it here.
    own_lock = app.state.data_lock is None
    if own_lock:
        app.state.data_lock = DataDirLock.acquire(settings.data_dir)
    for folder in (settings.data_dir, settings.jobs_dir, settings.tmp_dir):
        folder.mkdir(parents=True, exist_ok=True)
    store = JobStore(settings.db_path, settings.store_busy_timeout_seconds)
    await anyio.to_thread.run_sync(store.initialize)
    requeued, failed = await anyio.to_thread.run_sync(
        store.requeue_interrupted, settings.max_restarts, INTERRUPTED,
        settings.result_ttl_seconds)
    if requeued or failed:
        log.warning("recovered interrupted jobs: %d re-queued, %d failed", requeued, failed)
    # No request is in progress yet, so any folder without a job row is left over from an
    # upload the previous process never finished.
    await anyio.to_thread.run_sync(lambda: sweep(settings, store, orphan_age=0.0))
    executor = create_executor(settings, store, app.state.metrics)
    await executor.start()
    app.state.store = store
    app.state.executor = executor
    busy = app.state.busy_folders
    cleanup = asyncio.create_task(cleanup_loop(
        settings, store, lambda: executor.busy_ids() | busy()))
    log.info("curvature service ready on data dir %s with %d worker(s) (%s)",
             settings.data_dir.resolve(), settings.workers, settings.start_method)
    try:
        yield
    finally:
        cleanup.cancel()
        with suppress(asyncio.CancelledError):
            await cleanup
        await executor.stop()
        app.state.executor = None
        if own_lock:
            app.state.data_lock.release()
            app.state.data_lock = None


def build_openapi(app: FastAPI) -> dict:
    """The app's OpenAPI document, with the request and problem schemas the hand-parsed
    endpoints refer to."""
    if app.openapi_schema is not None:
        return app.openapi_schema
    spec = get_openapi(title=app.title, version=app.version, description=app.description,
                       routes=app.routes, tags=app.openapi_tags)
    schemas = spec.setdefault("components", {}).setdefault("schemas", {})
    for model in (CloudRequest, MultipartCloudRequest, Problem):
        schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
        schemas.update(schema.pop("$defs", {}))
        schemas[model.__name__] = schema
    _document_validation_problems(spec)
    app.openapi_schema = spec
    return spec


def _document_validation_problems(spec: dict) -> None:
    """FastAPI documents its own 422 body for every route with parameters; ours is a problem."""
    problem_422 = {"description": f"{PROBLEM_TYPES['invalid-request'].uri}: "
                                  f"{PROBLEM_TYPES['invalid-request'].title}",
                   "content": {PROBLEM_MEDIA_TYPE: {
                       "schema": {"$ref": "#/components/schemas/Problem"}}}}
    for operations in spec.get("paths", {}).values():
        for operation in operations.values():
            response = operation.get("responses", {}).get("422")
            if response and "application/json" in response.get("content", {}):
                operation["responses"]["422"] = problem_422
    for name in ("HTTPValidationError", "ValidationError"):
        spec["components"]["schemas"].pop(name, None)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app; nothing touches the disk or starts processes until its lifespan runs.

    Parameters
    ----------
    settings : Settings, optional
        Defaults to the ``CURVATURE_*`` environment.
    """
    app = FastAPI(
        title="Curvature service", version=curvature.__version__, description=DESCRIPTION,
        lifespan=lifespan, docs_url=None, redoc_url=None,  # served offline: routes/api_docs.py
        openapi_tags=[
            {"name": "jobs", "description": "Asynchronous curvature jobs."},
            {"name": "curvature", "description": "Synchronous answers for small clouds."},
            {"name": "methods", "description": "Methods, fit models and parameters."},
            {"name": "operations", "description": "Health, readiness and metrics."},
            {"name": "problems", "description": "Documentation of the error types."},
        ],
    )
    app.state.settings = settings if settings is not None else Settings()
    app.state.metrics = ServiceMetrics()
    app.state.store = None
    app.state.executor = None
    app.state.keyring = None
    app.state.data_lock = None  # DataDirLock of settings.data_dir while serving
    app.state.busy_folders = BusyFolders()
    problems.install(app)
    # Outside the catch-all, so its 500s get the headers too.
    app.add_middleware(HygieneMiddleware, router=app)
    install_log_redaction()
    # Added last = outermost: it also counts the 500s the catch-all produces.
    app.add_middleware(RequestMetricsMiddleware, metrics=app.state.metrics)
    for module in (jobs, fields, preview, curvature_routes, methods, health, problem_routes, ui,
                   api_docs):
        app.include_router(module.router)
    app.openapi = lambda: build_openapi(app)
    return app
