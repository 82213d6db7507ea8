"""Swagger UI (``/docs``) and ReDoc (``/redoc``) from files installed with the service.

FastAPI's own pages load their scripts from a CDN, so without internet they stay blank. The
``fastapi-offline`` package ships the same Swagger UI and ReDoc bundles (MIT licensed, like
Swagger UI and ReDoc themselves); only its files are used here, under ``/docs/assets/``.
Left out of the OpenAPI document.
"""

from __future__ import annotations

from importlib.resources import files

from fastapi import APIRouter, Request
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import FileResponse, HTMLResponse

from ..problems import HTTPProblem

router = APIRouter(include_in_schema=False)

ASSET_DIR = files("fastapi_offline") / "static"
# Only these files are served: no path from the request reaches the file system.
ASSETS = {"swagger-ui-bundle.js": "text/javascript", "swagger-ui.css": "text/css",
          "redoc.standalone.js": "text/javascript", "favicon.png": "image/png"}
ASSET_URL = "/docs/assets"


def _root(request: Request) -> str:
    return request.scope.get("root_path", "")


@router.get("/docs")
def swagger_ui(request: Request) -> HTMLResponse:
    app, root = request.app, _root(request)
    return get_swagger_ui_html(
        openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - Swagger UI",
        oauth2_redirect_url=f"{root}{app.swagger_ui_oauth2_redirect_url}",
        swagger_js_url=f"{root}{ASSET_URL}/swagger-ui-bundle.js",
        swagger_css_url=f"{root}{ASSET_URL}/swagger-ui.css",
        swagger_favicon_url=f"{root}{ASSET_URL}/favicon.png")


@router.get("/docs/oauth2-redirect")
def swagger_ui_redirect() -> HTMLResponse:
    return get_swagger_ui_oauth2_redirect_html()


@router.get("/redoc")
def redoc(request: Request) -> HTMLResponse:
    app, root = request.app, _root(request)
    return get_redoc_html(
        openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - ReDoc",
        redoc_js_url=f"{root}{ASSET_URL}/redoc.standalone.js",
        redoc_favicon_url=f"{root}{ASSET_URL}/favicon.png", with_google_fonts=False)


@router.get(f"{ASSET_URL}/{{asset}}")
def asset(asset: str) -> FileResponse:
    """A file of the Swagger UI or ReDoc bundle."""
    media = ASSETS.get(asset)
    if media is None:
        raise HTTPProblem("not-found", f"no such file: {ASSET_URL}/{asset}")
    return FileResponse(str(ASSET_DIR / asset), media_type=media,
                        headers={"Cache-Control": "public, max-age=86400"})
