"""Preview pictures of jobs (GET /v1/jobs/{id}/preview.png) and the jobs web page, the latter
driven end to end in headless Chromium over the DevTools protocol."""

from __future__ import annotations

import base64
import io
import json

import numpy as np
import pytest
from browser import chromium, needs_chromium
from PIL import Image
from service_helpers import KEY_A, KEY_B, KEYS, ServerProcess, bearer, sphere, wait_for_job

import curvature

FIELDS = ("mean", "gaussian", "k1", "k2")
VIEWS = ("iso", "front", "side", "top")


def png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return Image.open(io.BytesIO(data)).size


def torus_points(n=3000, seed=2) -> np.ndarray:
    """A fat torus (minor radius > major / 2): mean curvature positive outside, negative on
    the inner side, so its pictures hold both ends of the color map."""
    return curvature.synthetic.torus(n, major=2.0, minor=1.2, seed=seed).points


@pytest.fixture(scope="module")
def done_job(app_client):
    response = app_client.post("/v1/jobs", json={
        "points": torus_points().tolist(), "params": {"method": "knn", "k": 12, "fit": "monge"}})
    assert response.status_code == 202, response.text
    job = wait_for_job(app_client, response.json()["id"])
    assert job["status"] == "succeeded", job
    return job["id"]


def assert_problem(response, status: int, slug: str) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    doc = response.json()
    assert doc["type"] == f"/problems/{slug}" and doc["status"] == status
    return doc


# -- the preview endpoint ------------------------------------------------------------------

def test_preview_is_rendered_once_and_cached_with_the_job(client, done_job, monkeypatch):
    response = client.get(f"/v1/jobs/{done_job}/preview.png")
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    assert png_size(response.content) == (800, 600)
    cached = client.app.state.settings.jobs_dir / done_job / "preview-mean-iso-upauto.png"
    assert cached.read_bytes() == response.content

    def no_render(*args, **kwargs):
        raise AssertionError("rendered again instead of using the cached picture")

    monkeypatch.setattr("service.routes.preview.curvature.render_preview", no_render)
    again = client.get(f"/v1/jobs/{done_job}/preview.png?field=mean&view=iso")
    assert again.status_code == 200 and again.content == response.content


def test_every_field_and_view(client, done_job):
    pictures = set()
    for field, view in [(f, "iso") for f in FIELDS] + [("k1", v) for v in VIEWS[1:]]:
        response = client.get(f"/v1/jobs/{done_job}/preview.png",
                              params={"field": field, "view": view})
        assert response.status_code == 200, (field, view, response.text)
        assert png_size(response.content) == (800, 600)
        pictures.add(response.content)
    assert len(pictures) == 7  # each field and each camera gives its own picture


def test_bad_field_or_view_is_a_422_problem(client, done_job):
    doc = assert_problem(client.get(f"/v1/jobs/{done_job}/preview.png?field=curvedness"),
                         422, "invalid-request")
    assert "field" in doc["detail"]
    assert_problem(client.get(f"/v1/jobs/{done_job}/preview.png?view=back"),
                   422, "invalid-request")


def test_unknown_job_is_404(client):
    assert_problem(client.get("/v1/jobs/nope/preview.png"), 404, "job-not-found")


def test_another_keys_job_is_404_and_no_key_is_401(client, done_job):
    url = f"/v1/jobs/{done_job}/preview.png"
    doc = assert_problem(client.get(url, headers=bearer(KEY_B)), 404, "job-not-found")
    assert doc["detail"] == "no job with id " + repr(done_job)  # same as a missing job
    assert_problem(client.get(url, headers={"Authorization": ""}), 401, "unauthorized")


def test_job_whose_result_is_gone_is_computed_again(client):
    # A succeeded job exists: a lost result is not 'job-not-found' (issue 18, finding 5).
    response = client.post("/v1/jobs", json={"points": sphere(200).tolist()})
    job_id = wait_for_job(client, response.json()["id"])["id"]
    (client.app.state.settings.jobs_dir / job_id / "result.npz").unlink()
    assert_problem(client.get(f"/v1/jobs/{job_id}/preview.png"), 503, "result-corrupt")
    assert wait_for_job(client, job_id)["status"] == "succeeded"
    assert client.get(f"/v1/jobs/{job_id}/preview.png").status_code == 200


def test_unfinished_and_cancelled_jobs_are_409(client):
    buffer = io.BytesIO()
    np.save(buffer, np.random.default_rng(5).normal(size=(400_000, 3)))
    response = client.post("/v1/jobs", files={"file": ("big.npy", buffer.getvalue())},
                           data={"params": json.dumps({"method": "knn", "k": 30})})
    job_id = response.json()["id"]
    try:
        early = client.get(f"/v1/jobs/{job_id}/preview.png")
        doc = assert_problem(early, 409, "result-not-ready")
        assert early.headers["retry-after"] == "1" and doc["job_status"] in ("queued", "running")
    finally:
        assert client.delete(f"/v1/jobs/{job_id}").json()["status"] == "cancelled"
    assert_problem(client.get(f"/v1/jobs/{job_id}/preview.png"), 409, "job-cancelled")


def test_failed_job_is_409_with_its_error(client):
    response = client.post("/v1/jobs", files={"file": ("bad.xyz", b"1 2 3\n4 5\n")})
    job = wait_for_job(client, response.json()["id"])
    assert job["status"] == "failed"
    doc = assert_problem(client.get(f"/v1/jobs/{job['id']}/preview.png"), 409, "job-failed")
    assert "bad.xyz" in doc["detail"]


def test_openapi_documents_the_preview_but_not_the_page(client):
    spec = client.get("/openapi.json").json()
    operation = spec["paths"]["/v1/jobs/{job_id}/preview.png"]["get"]
    assert "image/png" in operation["responses"]["200"]["content"]
    assert {p["name"] for p in operation["parameters"]} >= {"job_id", "field", "view"}
    assert not [path for path in spec["paths"] if path == "/" or path.startswith("/ui")]


# -- the page's files ----------------------------------------------------------------------

def test_root_redirects_to_the_page(client):
    response = client.get("/", follow_redirects=False)
    assert response.status_code == 307 and response.headers["location"] == "/ui"


def test_page_and_assets_are_served_with_a_strict_policy(client):
    page = client.get("/ui")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    for marker in ('id="submit-form"', 'id="method"', 'id="jobs-body"', 'src="/ui/app.js"',
                   'id="api-key"'):
        assert marker in page.text
    script = client.get("/ui/app.js")
    assert script.status_code == 200
    assert script.headers["content-type"].startswith("text/javascript")
    assert "/v1/methods" in script.text and "Bearer" in script.text
    assert client.get("/ui/style.css").headers["content-type"].startswith("text/css")
    assert_problem(client.get("/ui/index.html"), 404, "not-found")
    assert_problem(client.get("/ui/..%2Fapp.py"), 404, "not-found")


# -- the page in a real browser ------------------------------------------------------------

@pytest.fixture(scope="module")
def live_server(tmp_path_factory):
    """A service requiring API keys; its ``client`` sends key A."""
    root = tmp_path_factory.mktemp("ui-server")
    proc = ServerProcess(root / "data", root / "server.log", api_key=KEY_A,
                         api_keys=KEYS).start()
    yield proc
    proc.stop()


def row_state(job_id: str) -> str:
    """JS: the row of a job as 'status|progress text|thumbnail width', or '' while absent."""
    return (f"(() => {{ const row = document.querySelector('tr[data-job-id=\"{job_id}\"]');"
            " if (!row) return '';"
            " const img = row.querySelector('img.thumb');"
            " const width = img && img.complete ? img.naturalWidth : 0;"
            " return [row.dataset.status, row.querySelector('td.progress').innerText.trim(),"
            " width].join('|'); })()")


@needs_chromium
def test_page_lists_jobs_with_previews_and_uploads_a_file(live_server, tmp_path):
    api = live_server.client
    submitted = api.post("/v1/jobs", json={"points": torus_points().tolist(),
                                           "params": {"method": "knn", "k": 12,
                                                      "fit": "monge"}})
    first = wait_for_job(api, submitted.json()["id"])
    assert first["status"] == "succeeded"
    catalog = api.get("/v1/methods").json()
    methods = [m["name"] for m in catalog["methods"]]
    upload = tmp_path / "torus_upload.xyz"
    np.savetxt(upload, torus_points(2000, seed=9))

    with chromium(tmp_path / "profile") as page:
        page.call("Page.enable")
        page.call("Page.navigate", url=f"{live_server.url}/ui")
        # Without a key the page says what is missing; with key A it shows A's jobs.
        assert "needs an API key" in page.wait_for(
            "document.querySelector('#message').innerText")
        page.evaluate(f"document.querySelector('#api-key').value = '{KEY_A}';"
                      "document.querySelector('#key-form').requestSubmit(); true")
        # The table lists the job as succeeded, 100 %, with its 800 x 600 preview loaded.
        assert page.wait_for(row_state(first["id"]) + " === 'succeeded|100 %|800'")
        options = page.evaluate("[...document.querySelectorAll('#method option')]"
                                ".map(o => o.value)")
        assert options == methods  # the select is filled from GET /v1/methods
        assert page.evaluate("document.querySelector('#method').value") == \
            catalog["default_method"]
        assert "3,000" in page.evaluate(f"document.querySelector('tr[data-job-id=\""
                                        f"{first['id']}\"]').innerText")

        # Upload through the form: pick the file, a method, a fit and a parameter; submit.
        document = page.call("DOM.getDocument")["root"]["nodeId"]
        file_input = page.call("DOM.querySelector", nodeId=document, selector="#file")["nodeId"]
        page.call("DOM.setFileInputFiles", nodeId=file_input, files=[str(upload)])
        page.evaluate("document.querySelector('#method').value = 'tc';"
                      "document.querySelector('#fit').value = 'monge';"
                      "document.querySelector('#extra-params').value = '{\"min_neighbors\": 12}';"
                      "document.querySelector('#submit-form').requestSubmit(); true")
        message = page.wait_for("(() => { const t = document.querySelector('#message')"
                                ".innerText; return t.includes('submitted') ? t : ''; })()")
        new_id = message.split()[1]
        job = api.get(f"/v1/jobs/{new_id}").json()
        assert job["method"] == "tc" and job["params"]["fit"] == "monge"
        assert job["params"]["min_neighbors"] == 12
        assert job["input"]["filename"] == "torus_upload.xyz"
        # The page follows the new job by itself (auto-refresh) until its preview shows.
        assert page.wait_for(row_state(new_id) + " === 'succeeded|100 %|800'", timeout=180)
        assert page.evaluate("document.querySelectorAll('#jobs-body tr').length") == 2

        shot = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
    (tmp_path / "page.png").write_bytes(shot)
    pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)
    assert pixels.shape == (800, 1200, 3)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 500  # not a blank page
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    assert np.sum((r > 150) & (b < 110) & (g < 130)) > 200  # the previews' reds (convex) ...
    assert np.sum((b > 150) & (r < 110)) > 200  # ... and blues (inner side of the tori)


def test_a_result_from_before_a_field_existed_is_computed_again(tmp_path):
    """A canonical result written before a field existed (k1_std came with issue 16) makes the
    preview of that field a ResultCorrupt, which the route answers with 503 result-corrupt
    and a recomputation, not a 500."""
    from service.result_files import CANONICAL_RESULT, ResultCorrupt
    from service.routes.preview import render_cached

    np.savez(tmp_path / CANONICAL_RESULT, points=sphere(50), mean=np.zeros(50))
    assert render_cached(tmp_path, "mean", "iso").exists()
    with pytest.raises(ResultCorrupt, match="predates the field 'k1_std'"):
        render_cached(tmp_path, "k1_std", "iso")
