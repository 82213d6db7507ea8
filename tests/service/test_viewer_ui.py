"""The jobs page's WebGL viewer, end to end in headless Chromium on SwiftShader: upload a
thinned real scan from the page, follow its progress until the viewer opens, turn the cloud,
pick a point and compare its values with the JSON result, switch fields, drag the color
limits on the histogram, change the up axis, and compare two jobs side by side and as a
difference. Screenshots are checked for content, not for exact pixels."""

from __future__ import annotations

import json

import numpy as np
import pytest
from browser import WEBGL_FLAGS, chromium, click, drag, needs_chromium, screenshot
from service_helpers import KEY_A, KEYS, ServerProcess, wait_for_job

import curvature

pytestmark = needs_chromium

VIEWER = "window.curvatureViewer"
IDLE = (f"{VIEWER} && {VIEWER}.a && !{VIEWER}.busy && {VIEWER}.scene"
        f" && {VIEWER}.scene.views.every(v => v.drawn >= v.n) && !{VIEWER}.scene.frameRequested")


@pytest.fixture(scope="module")
def live_server(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer-server")
    proc = ServerProcess(root / "data", root / "server.log", api_key=KEY_A,
                         api_keys=KEYS).start()
    yield proc
    proc.stop()


@pytest.fixture(scope="module")
def bunny_file(tmp_path_factory, scans):
    """The Stanford bunny (y up) thinned to every 5th vertex, as an XYZ file."""
    path = tmp_path_factory.mktemp("bunny") / "bunny_thin.xyz"
    np.savetxt(path, curvature.read(scans / "bun_zipper.ply").points[::5])
    return path


def canvas_box(page) -> dict:
    return page.evaluate("(() => { const r = document.querySelector('#viewer-canvas')"
                         ".getBoundingClientRect(); return {x: r.left, y: r.top,"
                         " width: r.width, height: r.height}; })()")


def canvas_pixels(page, save=None) -> np.ndarray:
    """The finished picture of the canvas (every point drawn); also saved as PNG to ``save``."""
    page.wait_for(IDLE)
    box = canvas_box(page)  # a screenshot's clip is in page coordinates, not the viewport's
    scroll = page.evaluate("[window.scrollX, window.scrollY]")
    pixels = screenshot(page, {**box, "x": box["x"] + scroll[0], "y": box["y"] + scroll[1]})
    if save is not None:
        from PIL import Image

        Image.fromarray(pixels.astype(np.uint8)).save(save)
    return pixels


def assert_cloud_drawn(pixels: np.ndarray, reds=True, blues=True) -> None:
    """Not blank: many colors, and (for curvature) both ends of the diverging map."""
    flat = pixels.reshape(-1, 3)
    assert len(np.unique(flat, axis=0)) > 100
    not_white = np.any(flat < 235, axis=1)
    assert not_white.mean() > 0.03
    r, g, b = flat[:, 0], flat[:, 1], flat[:, 2]
    if reds:
        assert np.sum((r > 150) & (b < 120) & (g < 140)) > 50
    if blues:
        assert np.sum((b > 150) & (r < 120)) > 50


def open_page(page, server) -> None:
    page.call("Page.enable")
    page.call("Page.navigate", url=f"{server.url}/ui")
    page.wait_for("document.readyState === 'complete' && !!window.CurvatureViewer")
    page.evaluate(f"document.querySelector('#api-key').value = '{KEY_A}';"
                  "document.querySelector('#key-form').requestSubmit(); true")
    page.wait_for("document.querySelectorAll('#method option').length > 0")


def pick_centre(page) -> dict:
    """Click the canvas where the first view's cloud is; wait for the pick's values."""
    box = canvas_box(page)
    views = page.evaluate(f"{VIEWER}.scene.views.length")
    # The point nearest the middle of the first view: click exactly on it.
    target = page.evaluate(
        f"(() => {{ const s = {VIEWER}.scene; const w = s.canvas.clientWidth / {views};"
        " const h = s.canvas.clientHeight; let best = null, d = Infinity;"
        " for (let i = 0; i < s.views[0].n; i += 7) { const p = s.screenPosition(0, i);"
        " if (!p) continue; const e = Math.hypot(p.x - w / 2, p.y - h / 2);"
        " if (e < d) { d = e; best = p; } } return best; })()")
    page.evaluate(f"{VIEWER}.lastPick = null; true")
    click(page, box["x"] + target["x"], box["y"] + target["y"])
    return page.wait_for(f"{VIEWER}.lastPick && !{VIEWER}.busy && {VIEWER}.lastPick")


def pick_table(page) -> dict:
    """The pick table: field -> [value of A, value of B ...] from the cells' data."""
    rows = page.evaluate("[...document.querySelectorAll('#viewer-pick tr[data-field]')].map("
                         "r => [r.dataset.field, [...r.querySelectorAll('td')].map("
                         "td => JSON.parse(td.dataset.value))])")
    return dict(rows)


def test_upload_view_turn_pick_switch_limits_up_and_compare(live_server, bunny_file, tmp_path):
    api = live_server.client
    with chromium(tmp_path / "profile", WEBGL_FLAGS) as page:
        open_page(page, live_server)
        # Upload from the page: file, method, fit and a parameter; progress, then the viewer.
        document = page.call("DOM.getDocument")["root"]["nodeId"]
        file_input = page.call("DOM.querySelector", nodeId=document, selector="#file")["nodeId"]
        page.call("DOM.setFileInputFiles", nodeId=file_input, files=[str(bunny_file)])
        page.evaluate("document.querySelector('#method').value = 'knn';"
                      "document.querySelector('#fit').value = 'monge';"
                      "document.querySelector('#extra-params').value = '{\"k\": 16}';"
                      "document.querySelector('#submit-form').requestSubmit(); true")
        progress = page.wait_for("(() => { const t = document.querySelector("
                                 "'#job-progress-text').innerText; return t.startsWith('Job')"
                                 " ? t : ''; })()")
        job_a = progress.split()[1].rstrip(":")
        assert page.wait_for(f"{VIEWER}.a && {VIEWER}.a.job.id === '{job_a}'", timeout=180)
        assert "succeeded, 100 %" in page.evaluate(
            "document.querySelector('#job-progress-text').innerText")
        job = api.get(f"/v1/jobs/{job_a}").json()
        assert job["params"]["k"] == 16 and job["input"]["filename"] == "bunny_thin.xyz"
        result = api.get(f"/v1/jobs/{job_a}/result?format=json").json()

        # The bunny comes up y up (auto, from its principal axes), colored by mean curvature.
        assert page.evaluate("document.querySelector('#viewer-up').selectedOptions[0]"
                             ".textContent") == "auto (y)"
        assert page.evaluate("document.querySelector('#viewer-field').value") == "mean"
        fields = page.evaluate("[...document.querySelectorAll('#viewer-field option')]"
                               ".map(o => o.value)")
        scalars = [k for k, v in result["fields"].items() if not isinstance(v[0], list)]
        assert fields == scalars  # listed from the result, not hard-coded
        assert "mean curvature H [1/length unit]" in page.evaluate(
            "document.querySelector('#viewer-legend').innerText")
        first = canvas_pixels(page, tmp_path / "first.png")
        assert_cloud_drawn(first)

        # Turn the cloud with the mouse: the picture changes and is still a cloud.
        box = canvas_box(page)
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        drag(page, (cx, cy), (cx + 160, cy + 40))
        turned = canvas_pixels(page)
        assert_cloud_drawn(turned)
        assert np.mean(np.any(turned != first, axis=2)) > 0.02

        # Pick: every field of the point, as in the JSON result (exact, not float32).
        pick = pick_centre(page)
        index = pick["index"]
        table = pick_table(page)
        assert list(table) == list(result["fields"])
        for name, values in result["fields"].items():
            assert table[name] == [values[index]], name

        # Switch the field: the legend, the colors and the values follow (float32 of JSON).
        page.evaluate("(() => { const s = document.querySelector('#viewer-field');"
                      " s.value = 'gaussian'; s.dispatchEvent(new Event('change')); })(); true")
        page.wait_for(f"{VIEWER}.fieldName === 'gaussian' && !{VIEWER}.busy")
        assert "Gaussian curvature K [1/length unit²]" in page.evaluate(
            "document.querySelector('#viewer-legend').innerText")
        shown = page.evaluate(f"(async () => Array.from(await {VIEWER}.a.field('gaussian'))"
                              ".map(v => Number.isNaN(v) ? null : v))()")
        expected = np.array([np.nan if v is None else v for v in result["fields"]["gaussian"]])
        got = np.array([np.nan if v is None else v for v in shown])
        assert np.array_equal(got, expected.astype(np.float32), equal_nan=True)
        gaussian = canvas_pixels(page, tmp_path / "gaussian.png")
        assert_cloud_drawn(gaussian, blues=False)
        assert np.mean(np.any(gaussian != turned, axis=2)) > 0.01

        # Drag the upper color limit on the histogram to a quarter: more points saturate.
        limits = page.evaluate(f"{VIEWER}.limits")
        hist = page.evaluate("(() => { const r = document.querySelector('#viewer-histogram')"
                             ".getBoundingClientRect(); return {x: r.left, y: r.top,"
                             " width: r.width, height: r.height}; })()")
        x_of = page.evaluate(f"[{VIEWER}.histogram.xOf({limits['vmax']}),"
                             f" {VIEWER}.histogram.xOf({limits['vmax']} / 4),"
                             f" {VIEWER}.histogram.canvas.width]")
        scale = hist["width"] / x_of[2]
        y = hist["y"] + hist["height"] / 2
        drag(page, (hist["x"] + x_of[0] * scale, y), (hist["x"] + x_of[1] * scale, y))
        dragged = page.evaluate(f"{VIEWER}.limits")
        assert dragged["vmin"] == limits["vmin"]
        assert dragged["vmax"] == pytest.approx(limits["vmax"] / 4, rel=0.05)
        assert float(page.evaluate("document.querySelector('#viewer-vmax').value")) == \
            pytest.approx(dragged["vmax"], rel=1e-4)
        saturated = canvas_pixels(page)
        red = lambda p: np.sum((p[..., 0] > 90) & (p[..., 2] < 60) & (p[..., 1] < 40))  # noqa: E731
        assert red(saturated) > red(gaussian)
        page.evaluate("document.querySelector('#viewer-reset-limits').click(); true")
        assert page.evaluate(f"{VIEWER}.limits.vmax") == limits["vmax"]

        # Another up axis: the camera starts again from the iso preset around it.
        page.evaluate("(() => { const s = document.querySelector('#viewer-up');"
                      " s.value = 'z'; s.dispatchEvent(new Event('change')); })(); true")
        assert np.mean(np.any(canvas_pixels(page) != gaussian, axis=2)) > 0.02

        # Compare with a second job of the same file (another method), side by side ...
        with open(bunny_file, "rb") as fh:
            second = api.post("/v1/jobs", files={"file": ("bunny_thin.xyz", fh)}, data={
                "params": json.dumps({"method": "knn", "k": 30, "fit": "monge"})})
        job_b = wait_for_job(api, second.json()["id"])["id"]
        page.evaluate("document.querySelector('#refresh').click(); true")
        page.wait_for(f"!!document.querySelector('#viewer-compare option[value=\"{job_b}\"]')")
        page.evaluate("(() => { const s = document.querySelector('#viewer-field');"
                      " s.value = 'mean'; s.dispatchEvent(new Event('change')); })(); true")
        page.wait_for(f"{VIEWER}.fieldName === 'mean' && !{VIEWER}.busy")
        page.evaluate(f"(() => {{ const s = document.querySelector('#viewer-compare');"
                      f" s.value = '{job_b}'; s.dispatchEvent(new Event('change')); }})(); true")
        page.wait_for(f"{VIEWER}.b && {VIEWER}.scene.views.length === 2 && !{VIEWER}.busy")
        assert page.evaluate(f"{VIEWER}.b.same")  # the same points in the same order
        pair = canvas_pixels(page, tmp_path / "pair.png")
        half = pair.shape[1] // 2
        assert_cloud_drawn(pair[:, :half])
        assert_cloud_drawn(pair[:, half:])
        result_b = api.get(f"/v1/jobs/{job_b}/result?format=json").json()
        pick = pick_centre(page)
        table = pick_table(page)
        assert table["mean"] == [result["fields"]["mean"][pick["index"]],
                                 result_b["fields"]["mean"][pick["index"]]]

        # ... and as the difference A - B of the field, in one view centred on 0.
        page.evaluate("(() => { const s = document.querySelector('#viewer-compare-mode');"
                      " s.value = 'difference'; s.dispatchEvent(new Event('change')); })();"
                      " true")
        page.wait_for(f"{VIEWER}.mode === 'difference' && {VIEWER}.scene.views.length === 1"
                      f" && !{VIEWER}.busy")
        assert "A − B" in page.evaluate("document.querySelector('#viewer-legend').innerText")
        limits = page.evaluate(f"{VIEWER}.limits")
        assert limits["mode"] == "diverging" and limits["vmin"] == -limits["vmax"]
        diff = np.array([np.nan if a is None or b is None else a - b for a, b in zip(
            result["fields"]["mean"], result_b["fields"]["mean"], strict=True)])
        shown = np.array([np.nan if v is None else v for v in page.evaluate(
            f"(async () => Array.from((await {VIEWER}.displayed())[0])"
            ".map(v => Number.isNaN(v) ? null : v))()")])
        assert np.allclose(shown, diff, rtol=1e-5, atol=1e-3 * np.nanmax(np.abs(diff)),
                           equal_nan=True)
        assert_cloud_drawn(canvas_pixels(page, tmp_path / "difference.png"))
        message = page.evaluate("document.querySelector('#message').innerText")
        assert "Viewer:" not in message, message
