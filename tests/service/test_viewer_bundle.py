"""The viewer's bundle (service/static/viewer.js, built from web/ by esbuild) is committed:
it must be the build of the sources and lock file in the repository, and the page must load
nothing from elsewhere."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
WEB = REPO / "web"
BUNDLE = REPO / "service" / "static" / "viewer.js"


def source_digest() -> str:
    """The digest web/build.mjs writes into the bundle's first line (same files, order)."""
    digest = hashlib.sha256()
    files = ["package-lock.json"] + [f"src/{p.name}" for p in sorted((WEB / "src").glob("*.js"))]
    for name in files:
        digest.update((name + "\n").encode())
        digest.update((WEB / name).read_bytes())
    return digest.hexdigest()


def test_bundle_is_built_from_the_committed_sources():
    first = BUNDLE.read_text().splitlines()[0]
    found = re.search(r"sources sha256 ([0-9a-f]{64})", first)
    assert found, f"{BUNDLE} has no source digest on its first line: {first[:120]}"
    assert found.group(1) == source_digest(), (
        "service/static/viewer.js is stale: run `npm ci && npm run build` in web/ and commit it")


def test_lock_file_pins_what_package_json_asks_for():
    package = json.loads((WEB / "package.json").read_text())
    lock = json.loads((WEB / "package-lock.json").read_text())["packages"]
    for name, version in package["devDependencies"].items():
        assert lock[f"node_modules/{name}"]["version"] == version, name


def test_the_page_loads_only_its_own_files(client):
    page = client.get("/ui")
    sources = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert sources and all(s.startswith("/ui/") for s in sources), sources
    assert "default-src 'self'" in page.headers["content-security-policy"]
    bundle = client.get("/ui/viewer.js")
    assert bundle.status_code == 200
    assert bundle.headers["content-type"].startswith("text/javascript")
    assert bundle.content == BUNDLE.read_bytes()
    assert "CurvatureViewer" in bundle.text and "/result/" in bundle.text
