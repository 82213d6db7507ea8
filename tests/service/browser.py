"""Headless Chromium driven over the DevTools protocol, for the web page's tests and the
viewer benchmark: no browser download, no Playwright; the Debian chromium package."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

CHROMIUM = next((path for path in (shutil.which("chromium"), "/usr/bin/chromium")
                 if path and os.path.exists(path)), None)
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (Debian: apt-get install chromium; "
                             ".ci/run installs it); the browser test needs it")


class DevTools:
    """A minimal Chrome DevTools Protocol session over one page's websocket."""

    def __init__(self, ws):
        self.ws = ws
        self.next_id = 0

    def call(self, method: str, **params) -> dict:
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.ws.recv(timeout=60))
            if message.get("id") == self.next_id:  # anything else is an event: ignored
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                           awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float = 90.0):
        """Evaluate until the value is truthy; errors count as not yet (the page may still
        be loading)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                value, problem = self.evaluate(expression), None
            except RuntimeError as exc:
                value, problem = None, exc
            if value:
                return value
            if time.monotonic() > deadline:
                page = self.evaluate("document.body ? document.body.innerText : ''")
                pytest.fail(f"timed out waiting for {expression} ({problem}); the page "
                            f"shows:\n{page}")
            time.sleep(0.2)


@contextlib.contextmanager
def chromium(profile: Path, flags: tuple[str, ...] = ()):
    """Headless Chromium with remote debugging (and ``flags``); yields a DevTools session on
    its page."""
    from websockets.sync.client import connect

    process = subprocess.Popen(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--disable-dev-shm-usage", "--hide-scrollbars", "--lang=en-US",
         "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0",
         f"--user-data-dir={profile}", "--window-size=1200,800", *flags, "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 60
        while not (port_file.exists() and len(port_file.read_text().split()) >= 2):
            if process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"chromium did not open its debugging port (exit {process.poll()})")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        targets = httpx.get(f"http://127.0.0.1:{port}/json/list", timeout=30).json()
        page = next(t for t in targets if t["type"] == "page")
        with connect(page["webSocketDebuggerUrl"], max_size=None, open_timeout=30) as ws:
            session = DevTools(ws)
            session.call("Emulation.setDeviceMetricsOverride", width=1200, height=800,
                         deviceScaleFactor=1, mobile=False)
            yield session
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGTERM)  # chromium and its helper processes
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()



# WebGL in headless Chromium without a GPU: ANGLE on SwiftShader (software rendering).
WEBGL_FLAGS = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist")


def screenshot(session: DevTools, clip: dict | None = None) -> np.ndarray:
    """The page (or a clip {x, y, width, height} in CSS pixels) as an RGB array (h, w, 3)."""
    from PIL import Image

    params = {"format": "png"}
    if clip is not None:
        params["clip"] = {**clip, "scale": 1}
    data = base64.b64decode(session.call("Page.captureScreenshot", **params)["data"])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(int)


def mouse(session: DevTools, kind: str, x: float, y: float, buttons: int = 0,
          button: str = "none") -> None:
    """One mouse event at page coordinates (CSS pixels)."""
    session.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button=button,
                 buttons=buttons, clickCount=1 if kind != "mouseMoved" else 0,
                 pointerType="mouse")


def drag(session: DevTools, start: tuple[float, float], end: tuple[float, float],
         steps: int = 8) -> None:
    """Press the left button at ``start``, move to ``end`` in steps, release."""
    mouse(session, "mouseMoved", *start)
    mouse(session, "mousePressed", *start, buttons=1, button="left")
    for k in range(1, steps + 1):
        t = k / steps
        mouse(session, "mouseMoved", start[0] + t * (end[0] - start[0]),
              start[1] + t * (end[1] - start[1]), buttons=1, button="left")
    mouse(session, "mouseReleased", *end, buttons=0, button="left")


def click(session: DevTools, x: float, y: float) -> None:
    mouse(session, "mouseMoved", x, y)
    mouse(session, "mousePressed", x, y, buttons=1, button="left")
    mouse(session, "mouseReleased", x, y, buttons=0, button="left")
