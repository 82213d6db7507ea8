"""Frame rate of the jobs page's WebGL viewer in headless Chromium on SwiftShader (no GPU).

A noisy torus of ``--points`` points (1M by default) runs as a cheap job (10-NN, Monge fit)
on a service started here and the page opens it in the viewer. Then, ``--repeat`` times:
the camera turns for ``--seconds`` the way a dragging user turns it (one step per animation
frame), which gives the frames per second and the chunk the viewer adapts to (the points
each frame draws, a uniform sample, see web/src/scene.js), and the seconds until the still
picture holds every point; and ``--frames`` frames each waited for (a pixel read back) drawing
every point, then the adapted chunk, side by side. Also the time from clicking View to the
first colored frame (fetching positions and one field as float32).

Usage::

    python benchmarks/viewer_fps.py                      # 1M points
    python benchmarks/viewer_fps.py --points 200000 --frames 20 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The browser and server helpers of the tests; this folder's service.py must not shadow the
# service package.
sys.path[0] = str(REPO / "tests" / "service")

from browser import CHROMIUM, WEBGL_FLAGS, chromium  # noqa: E402
from service_helpers import ServerProcess, wait_for_job  # noqa: E402

import curvature  # noqa: E402


def submit(server: ServerProcess, n: int) -> dict:
    cloud = curvature.synthetic.torus(n, noise=0.1, seed=1)
    path = server.data_dir.parent / "torus.ply"
    curvature.write(path, cloud.points)
    with open(path, "rb") as fh:
        response = server.client.post("/v1/jobs", files={"file": ("torus.ply", fh)}, data={
            "params": json.dumps({"method": "knn", "k": 10, "fit": "monge"})})
    response.raise_for_status()
    return wait_for_job(server.client, response.json()["id"], timeout=1800)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=4.0, help="of each turning run")
    parser.add_argument("--width", type=int, default=1200)
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    args = parser.parse_args()
    if CHROMIUM is None:
        sys.exit("chromium is not installed (Debian: apt-get install chromium)")

    root = Path(tempfile.mkdtemp(prefix="viewer-fps-"))
    server = ServerProcess(root / "data", root / "server.log").start()
    try:
        t0 = time.perf_counter()
        job = submit(server, args.points)
        print(f"job of {job['n_points']:,} points computed in {time.perf_counter() - t0:.0f} s")
        with chromium(root / "profile", WEBGL_FLAGS) as page:
            page.call("Emulation.setDeviceMetricsOverride", width=args.width, height=900,
                      deviceScaleFactor=1, mobile=False)
            page.call("Page.navigate", url=f"{server.url}/ui")
            button = f"document.querySelector('tr[data-job-id=\"{job['id']}\"] button.view')"
            page.wait_for(f"!!{button}")
            renderer = page.evaluate("(() => { const c = document.createElement('canvas')"
                                     ".getContext('webgl2'); const e = c.getExtension("
                                     "'WEBGL_debug_renderer_info'); return e ? c.getParameter("
                                     "e.UNMASKED_RENDERER_WEBGL) : 'unknown'; })()")
            t0 = time.perf_counter()
            page.evaluate(f"{button}.click(); true")
            page.wait_for("window.curvatureViewer.a && !window.curvatureViewer.busy", 600)
            load = time.perf_counter() - t0
            canvas = page.evaluate("[document.querySelector('#viewer-canvas').clientWidth,"
                                   " document.querySelector('#viewer-canvas').clientHeight]")
            times = {"all": [], "chunk": []}
            spins = []
            for _ in range(args.repeat):
                spins.append(page.evaluate(f"curvatureViewer.scene.spin({args.seconds})"))
                chunk = spins[-1]["chunk"]
                times["all"] += page.evaluate(
                    f"curvatureViewer.scene.measure({args.frames}, {args.points})")
                times["chunk"] += page.evaluate(
                    f"curvatureViewer.scene.measure({args.frames}, {chunk})")
    finally:
        server.stop()

    chunk = int(statistics.median(s["chunk"] for s in spins))
    load_average = os.getloadavg()[0]
    print(f"renderer: {renderer}; canvas {canvas[0]} x {canvas[1]} px, point size 2 px; "
          f"load average {load_average:.1f} on {os.cpu_count()} cores")
    print(f"open (positions + mean as float32, upload, first frame): {load:.2f} s")
    print(f"turning the camera {args.seconds:g} s at a time ({args.repeat} runs): "
          f"{statistics.median(s['fps'] for s in spins):.1f} fps (median), each frame "
          f"drawing {chunk:,} points (the adapted chunk, {100 * chunk / args.points:.1f} %); "
          f"every point drawn {statistics.median(s['complete_s'] for s in spins):.2f} s "
          f"after the camera stops")
    print(f"{'frame drawing':>24} {'median ms':>10} {'fps':>7} {'p90 ms':>8}")
    report = {"points": args.points, "renderer": renderer, "canvas": canvas, "load_s": load,
              "load_average": load_average,
              "spins": spins, "frames": {}}
    for mode, count in (("all", args.points), ("chunk", chunk)):
        med = statistics.median(times[mode])
        p90 = sorted(times[mode])[int(0.9 * (len(times[mode]) - 1))]
        print(f"{f'{count:,} points':>24} {med:10.1f} {1000 / med:7.1f} {p90:8.1f}")
        report["frames"][mode] = {"drawn": count, "median_ms": med, "fps": 1000 / med,
                                  "p90_ms": p90, "samples": len(times[mode])}
    ratio = statistics.median(times["all"]) / statistics.median(times["chunk"])
    print(f"ratio every point / adapted chunk (same run): {ratio:.2f}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
