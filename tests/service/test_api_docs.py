"""Swagger UI and ReDoc work without internet: their files come from the installed package."""

from __future__ import annotations

import base64
import io
import re

import numpy as np
import pytest
from PIL import Image
from service_helpers import ServerProcess
from test_preview_ui import chromium, needs_chromium

from service.routes.api_docs import ASSETS

# Every host name but the loopback address fails to resolve: a page that needs a CDN breaks.
OFFLINE = ("--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",)


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_pages_refer_to_local_files_only(client, page):
    response = client.get(page)
    assert response.status_code == 200
    urls = re.findall(r'(?:src|href)="([^"]+)"|url: \'([^\']+)\'', response.text)
    urls = [a or b for a, b in urls]
    assert urls and all(u.startswith("/") for u in urls), urls
    for url in urls:
        assert client.get(url).status_code == 200, url


def test_every_asset_is_served_and_nothing_else(client):
    for name, media in ASSETS.items():
        response = client.get(f"/docs/assets/{name}")
        assert response.status_code == 200 and len(response.content) > 1000
        assert response.headers["content-type"].startswith(media)
    assert client.get("/docs/assets/..%2Fcore.py").status_code == 404
    assert client.get("/docs/assets/LICENSE").status_code == 404


@pytest.fixture(scope="module")
def docs_server(tmp_path_factory):
    """A service without API keys on loopback (the pages need no pool: no warm-up)."""
    root = tmp_path_factory.mktemp("docs-server")
    proc = ServerProcess(root / "data", root / "server.log", workers=1, warmup="false").start()
    yield proc
    proc.stop()


def operations(server) -> list[tuple[str, str]]:
    spec = server.client.get("/openapi.json").json()
    return [(method.upper(), path) for path, ops in spec["paths"].items() for method in ops]


@needs_chromium
def test_swagger_ui_shows_every_operation_offline(docs_server, tmp_path):
    expected = operations(docs_server)
    with chromium(tmp_path / "profile", OFFLINE) as page:
        page.call("Page.navigate", url=f"{docs_server.url}/docs")
        count = page.wait_for(f"(() => {{ const n = document.querySelectorAll('.opblock')"
                              f".length; return n >= {len(expected)} ? n : 0; }})()")
        assert count == len(expected)
        shown = page.evaluate(
            "[...document.querySelectorAll('.opblock-summary')].map(s => "
            "s.querySelector('.opblock-summary-method').innerText + ' ' + "
            "s.querySelector('.opblock-summary-path').innerText.replace(/\\u200b/g, ''))")
        assert sorted(tuple(s.split(" ", 1)) for s in shown) == sorted(expected)
        shot = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
    (tmp_path / "swagger.png").write_bytes(shot)
    pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    # Swagger UI draws GET operations blue (#61affe) and POST ones green (#49cc90).
    assert np.sum((abs(r - 97) < 12) & (abs(g - 175) < 12) & (abs(b - 254) < 12)) > 500
    assert np.sum((abs(r - 73) < 12) & (abs(g - 204) < 12) & (abs(b - 144) < 12)) > 500


@needs_chromium
def test_redoc_shows_every_operation_offline(docs_server, tmp_path):
    spec = docs_server.client.get("/openapi.json").json()
    summaries = {op["summary"] for ops in spec["paths"].values() for op in ops.values()}
    with chromium(tmp_path / "profile", OFFLINE) as page:
        page.call("Page.navigate", url=f"{docs_server.url}/redoc")
        text = page.wait_for("(() => { const t = document.body.innerText; "
                             "return t.includes('Curvature service') && "
                             "document.querySelectorAll('[data-section-id^=\"operation/\"]')"
                             ".length > 0 ? t : ''; })()")
        missing = [s for s in summaries if s not in text]
        assert not missing, missing
        shot = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
    (tmp_path / "redoc.png").write_bytes(shot)
    pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 200  # text and menus drawn
