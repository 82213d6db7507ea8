"""Soak and abuse figures of issue 18: kill -9 cycles and memory per input byte.

Usage::

    python benchmarks/soak.py                 # 20 kill -9 cycles, memory of every format
    python benchmarks/soak.py --cycles 5 --skip-memory --json /tmp/soak.json

``kill`` phase: a real service on loopback; each cycle submits a mix of jobs (small JSON
clouds and 200k-point NPY uploads), waits a random 0.5 to 3 s, kills the server with SIGKILL
(its workers follow it) and starts it again on the same data folder. At the end every
accepted job is followed to its end; the report counts them by final status and error type
(none may fail because of the restarts: a restart is not an attempt).

``memory`` phase: for each input format, a 200,000-point cloud is written and loaded the way
a worker loads it (``service.inputs.load_input`` and the cloud checks; for JSON bodies the
server's ``_decode_cloud``) in a fresh process; the growth of its peak resident set over the
baseline, divided by the file's size, is the memory per input byte.

The fast, asserting versions of every finding live in ``tests/service/test_abuse.py``.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import random
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from load import free_port, process_tree, sphere, wait_ready  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
FINAL = ("succeeded", "failed", "cancelled")


def _start(data_dir: Path, port: int, key: str, log) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
    env.update({"CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
                "CURVATURE_DATA_DIR": str(data_dir), "CURVATURE_API_KEYS": key,
                "CURVATURE_LOG_LEVEL": "warning"})
    server = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO, env=env, stdout=log,
                              stderr=subprocess.STDOUT, start_new_session=True)
    wait_ready(f"http://127.0.0.1:{port}", server)
    return server


def kill_cycles(cycles: int, seed: int = 0) -> dict:
    """Kill -9 the service ``cycles`` times under a mix of jobs; count the outcomes."""
    import httpx

    rng = random.Random(seed)
    key = secrets.token_urlsafe(24)
    port = free_port()
    headers = {"Authorization": f"Bearer {key}"}
    accepted: list[str] = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="curvature-soak-") as tmp, \
            open(Path(tmp) / "server.log", "wb") as log:
        data_dir = Path(tmp) / "data"
        server = _start(data_dir, port, key, log)
        try:
            for cycle in range(cycles):
                with httpx.Client(base_url=f"http://127.0.0.1:{port}", headers=headers,
                                  timeout=30) as client:
                    for i in range(3):
                        body = {"points": sphere(300 + 10 * i, 1.0 + i, cycle).tolist()}
                        r = client.post("/v1/jobs", json=body)
                        if r.status_code == 202:
                            accepted.append(r.json()["id"])
                    buffer = io.BytesIO()
                    np.save(buffer, np.random.default_rng(cycle).normal(size=(200_000, 3)))
                    r = client.post("/v1/jobs", files={"file": ("c.npy", buffer.getvalue())},
                                    data={"params": json.dumps({"method": "knn", "k": 10})})
                    if r.status_code == 202:
                        accepted.append(r.json()["id"])
                time.sleep(rng.uniform(0.5, 3.0))
                os.killpg(server.pid, signal.SIGKILL)
                server.wait()
                deadline = time.monotonic() + 20  # its workers follow it
                while any(p != os.getpid() for p in process_tree(server.pid)
                          if Path(f"/proc/{p}").exists()) and time.monotonic() < deadline:
                    time.sleep(0.2)
                server = _start(data_dir, port, key, log)
            outcomes: dict[str, int] = {}
            restarts = attempts = 0
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", headers=headers,
                              timeout=30) as client:
                for job_id in accepted:
                    deadline = time.monotonic() + 600
                    while True:
                        job = client.get(f"/v1/jobs/{job_id}").json()
                        if job["status"] in FINAL or time.monotonic() > deadline:
                            break
                        time.sleep(0.2)
                    label = job["status"] + (f" ({job['error']['type']})" if job.get("error")
                                             else "")
                    outcomes[label] = outcomes.get(label, 0) + 1
                    restarts = max(restarts, job.get("restarts", 0))
                    attempts = max(attempts, job.get("attempts", 0))
        finally:
            server.send_signal(signal.SIGTERM)
            server.wait(timeout=30)
    return {"cycles": cycles, "accepted": len(accepted), "outcomes": outcomes,
            "max_restarts_of_a_job": restarts, "max_attempts_of_a_job": attempts,
            "seconds": round(time.perf_counter() - started, 1)}


_MEASURE = r"""
import sys, json, tracemalloc
from pathlib import Path
kind, path = sys.argv[1], Path(sys.argv[2])
import numpy as np, curvature
from service import inputs, uploads
body = path.read_bytes() if kind == "json" else None  # a JSON body is in memory anyway
tracemalloc.start()
if kind == "json":
    uploads._decode_cloud(body, path.parent, max_points=10_000_000)
else:
    cloud = inputs.load_input(path, "file", path.name, 10_000_000)
    inputs.check_cloud(cloud)
print(json.dumps({"growth_bytes": tracemalloc.get_traced_memory()[1]}))
"""


def _write_text_formats(folder: Path, points: np.ndarray) -> dict[str, Path]:
    """The text formats the library reads but does not write, written here."""
    n = len(points)
    lines = "\n".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in points) + "\n"
    out = {"xyz": folder / "cloud.xyz", "pcd": folder / "cloud.pcd",
           "obj": folder / "cloud.obj", "off": folder / "cloud.off"}
    out["xyz"].write_text(lines)
    out["pcd"].write_text("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                          f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
                          f"DATA ascii\n{lines}")
    out["obj"].write_text("".join(f"v {line}\n" for line in lines.splitlines()))
    out["off"].write_text(f"OFF\n{n} 0 0\n{lines}")
    return out


def memory_per_byte(n: int = 1_000_000) -> list[dict]:
    """Peak allocations per input byte of loading each format (tracemalloc, fresh process
    each; numpy's buffers are traced)."""
    import curvature

    rng = np.random.default_rng(0)
    points = rng.normal(size=(n, 3))
    rows = []
    with tempfile.TemporaryDirectory(prefix="curvature-mem-") as tmp:
        folder = Path(tmp)
        files = {}
        for fmt in ("ply", "csv"):
            files[fmt] = folder / f"cloud.{fmt}"
            curvature.write(files[fmt], curvature.PointCloud(points=points))
        files["ply-ascii"] = folder / "ascii.ply"
        files["ply-ascii"].write_text(
            f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nend_header\n"
            + "\n".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in points) + "\n")
        files.update(_write_text_formats(folder, points))
        np.save(folder / "cloud.npy", points)
        files["npy"] = folder / "cloud.npy"
        np.savez_compressed(folder / "cloud.npz", points=points)
        files["npz"] = folder / "cloud.npz"
        (folder / "body.json").write_text(json.dumps({"points": points.round(6).tolist()}))
        files["json"] = folder / "body.json"
        for fmt, path in files.items():
            out = subprocess.run([sys.executable, "-c", _MEASURE,
                                  "json" if fmt == "json" else "file", str(path)], cwd=REPO,
                                 capture_output=True, text=True, timeout=600)
            if out.returncode != 0:
                rows.append({"format": fmt, "error": out.stderr[-300:]})
                continue
            growth = json.loads(out.stdout.strip().splitlines()[-1])["growth_bytes"]
            size = path.stat().st_size
            rows.append({"format": fmt, "file_bytes": size, "growth_bytes": growth,
                         "bytes_per_input_byte": round(growth / size, 2)})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20, help="kill -9 cycles (0: skip)")
    parser.add_argument("--skip-memory", action="store_true")
    parser.add_argument("--json", type=Path, help="also write the report here")
    args = parser.parse_args(argv)
    report: dict = {}
    if not args.skip_memory:
        report["memory"] = memory_per_byte()
        for row in report["memory"]:
            if "bytes_per_input_byte" in row:
                print(f"  {row['format']:<5} {row['file_bytes'] / 1e6:8.1f} MB file: peak "
                      f"+{row['growth_bytes'] / 1e6:8.1f} MB = {row['bytes_per_input_byte']} "
                      "bytes per input byte")
            else:
                print(f"  {row['format']:<5} {row.get('skipped') or row.get('error')}")
    if args.cycles:
        report["kill"] = kill_cycles(args.cycles)
        k = report["kill"]
        print(f"{k['cycles']} kill -9 cycles in {k['seconds']} s: {k['accepted']} jobs "
              f"accepted, outcomes {k['outcomes']}, at most {k['max_restarts_of_a_job']} "
              f"restart(s) and {k['max_attempts_of_a_job']} attempt(s) for one job")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    kill = report.get("kill")
    return 0 if kill is None or set(kill["outcomes"]) <= {"succeeded"} else 1


if __name__ == "__main__":
    raise SystemExit(main())
