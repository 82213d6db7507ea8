"""A small web page for people: the caller's jobs with status, progress and previews, a form
to upload a file, and a WebGL viewer of finished jobs. HTML, CSS and JavaScript from
``service/static``: ``app.js`` is written by hand, ``viewer.js`` is the three.js bundle built
from ``web/`` (committed, so nothing is fetched from elsewhere). The page talks to the same
JSON API as every other client. Left out of the OpenAPI document.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, RedirectResponse

from ..problems import HTTPProblem

router = APIRouter(include_in_schema=False)

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
# Only these files are served: no path from the request ever reaches the file system.
ASSETS = {"app.js": "text/javascript", "viewer.js": "text/javascript", "style.css": "text/css"}
SECURITY_HEADERS = {
    # Scripts and styles from this origin only; previews arrive as blob: URLs.
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                               "object-src 'none'; base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache",
}


@router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/ui", status_code=307)


@router.get("/ui")
def page() -> FileResponse:
    """The jobs page."""
    return FileResponse(STATIC_DIR / "index.html", media_type="text/html; charset=utf-8",
                        headers=SECURITY_HEADERS)


@router.get("/ui/{asset}")
def asset(asset: str) -> FileResponse:
    """The page's script and style sheet."""
    media = ASSETS.get(asset)
    if media is None:
        raise HTTPProblem("not-found", f"no such file: /ui/{asset}")
    return FileResponse(STATIC_DIR / asset, media_type=f"{media}; charset=utf-8",
                        headers=SECURITY_HEADERS)
