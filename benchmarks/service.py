"""The REST service against the library on the same computation (DESIGN.md section 9).

A noisy torus of ``--points`` points (1M by default) in a binary PLY goes through the API
(upload, run, download the result as PLY) and through the library in this process
(``curvature.read`` + ``curvature.estimate`` + ``curvature.write``), alternating, ``--repeat``
times each in one run. Medians are reported side by side with their ratio (target <= 1.2, issue 21).
Both use the same number of threads: the service runs a pool of one worker process whose jobs
use ``--threads`` threads, the library call gets ``workers=--threads``. Numba compile time is
measured apart, before the timed runs.

Usage::

    python benchmarks/service.py                      # 1M points, 3 runs each
    python benchmarks/service.py --points 200000 --repeat 5 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

import curvature
from curvature import synthetic

REPO = Path(__file__).resolve().parents[1]


def make_input(path: Path, n: int) -> None:
    """A torus (R = 2, r = 1) with 0.1 % BBD noise, points only, binary PLY."""
    cloud = synthetic.torus(n, noise=0.1, seed=1)
    curvature.write(path, cloud.points)


def library_run(source: Path, target: Path, params: dict, threads: int) -> dict:
    """read + estimate + write, timed by stage."""
    t0 = time.perf_counter()
    cloud = curvature.read(source)
    t1 = time.perf_counter()
    p = dict(params)
    result = curvature.estimate(cloud.points, p.pop("method"), workers=threads, **p)
    t2 = time.perf_counter()
    curvature.write(target, result)
    t3 = time.perf_counter()
    return {"read": t1 - t0, "estimate": t2 - t1, "write": t3 - t2, "total": t3 - t0}


def api_run(client: httpx.Client, source: Path, target: Path, params: dict) -> dict:
    """Upload, poll until done, download the PLY result, timed by stage."""
    t0 = time.perf_counter()
    with open(source, "rb") as fh:
        response = client.post("/v1/jobs", files={"file": (source.name, fh)},
                               data={"params": json.dumps(params)})
    response.raise_for_status()
    location = response.headers["location"]
    t1 = time.perf_counter()
    while True:
        job = client.get(location).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            break
        time.sleep(0.02)
    if job["status"] != "succeeded":
        raise RuntimeError(f"job ended {job['status']}: {job.get('error')}")
    t2 = time.perf_counter()
    with client.stream("GET", f"{location}/result",
                       headers={"Accept": "application/x-ply"}) as stream:
        stream.raise_for_status()
        with open(target, "wb") as out:
            for chunk in stream.iter_bytes(1 << 20):
                out.write(chunk)
    t3 = time.perf_counter()
    client.delete(location)  # free the disk between runs
    return {"upload": t1 - t0, "run": t2 - t1, "download": t3 - t2, "total": t3 - t0,
            "worker_compute": job["result"]["compute_seconds"]}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_server(data_dir: Path, threads: int, log_path: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {**os.environ, "CURVATURE_PORT": str(port), "CURVATURE_DATA_DIR": str(data_dir),
           "CURVATURE_WORKERS": "1", "CURVATURE_ESTIMATE_WORKERS": str(threads),
           "CURVATURE_MAX_UPLOAD_BYTES": str(8 << 30), "CURVATURE_LOG_LEVEL": "warning"}
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO, env=env,
                                stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 300
    while True:
        try:
            if httpx.get(f"{url}/readyz", timeout=5).status_code == 200:
                return proc, url
        except httpx.TransportError:
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"server did not start; see {log_path}")
        time.sleep(0.2)


def median(runs: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                        help="threads of the computation, on both sides")
    parser.add_argument("--method", default="auto", help="auto (the default estimator) or a "
                        "fixed method, with --fit and (knn) --k")
    parser.add_argument("--k", type=int, default=24)
    parser.add_argument("--fit", default="implicit")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    params = {"method": args.method}
    if args.method != "auto":
        params["fit"] = args.fit
    if args.method == "knn":
        params["k"] = args.k

    with tempfile.TemporaryDirectory(prefix="curvature-bench-") as tmp:
        tmp = Path(tmp)
        source = tmp / "torus.ply"
        t = time.perf_counter()
        make_input(source, args.points)
        print(f"input: {args.points} points, {source.stat().st_size / 1e6:.1f} MB binary PLY "
              f"({time.perf_counter() - t:.1f} s to make); params {params}; "
              f"{args.threads} thread(s) on both sides")

        t = time.perf_counter()
        small = tmp / "small.ply"
        make_input(small, 2000)
        library_run(small, tmp / "small_out.ply", params, args.threads)
        print(f"library first call (numba compile or cache load): "
              f"{time.perf_counter() - t:.1f} s")
        t = time.perf_counter()
        server, url = start_server(tmp / "data", args.threads, tmp / "server.log")
        print(f"server start incl. worker warm-up: {time.perf_counter() - t:.1f} s")
        lib_runs, api_runs = [], []
        try:
            with httpx.Client(base_url=url, timeout=3600) as client:
                api_run(client, small, tmp / "small_api.ply", params)  # first job: warm path
                for i in range(args.repeat):
                    # Alternate the order so drifting machine load hits both sides alike.
                    order = ("lib", "api") if i % 2 == 0 else ("api", "lib")
                    for side in order:
                        if side == "lib":
                            lib_runs.append(library_run(source, tmp / "lib.ply", params,
                                                        args.threads))
                        else:
                            api_runs.append(api_run(client, source, tmp / "api.ply", params))
                    print(f"run {i + 1}: library {lib_runs[-1]['total']:.2f} s, "
                          f"API {api_runs[-1]['total']:.2f} s")
        finally:
            server.send_signal(signal.SIGTERM)
            server.wait(timeout=60)
        same_size = (tmp / "lib.ply").stat().st_size == (tmp / "api.ply").stat().st_size

    lib_total, api_total = median(lib_runs, "total"), median(api_runs, "total")
    ratio = api_total / lib_total
    print()
    print(f"medians of {args.repeat} runs each (seconds)")
    print(f"  library: read {median(lib_runs, 'read'):.2f} + estimate "
          f"{median(lib_runs, 'estimate'):.2f} + write {median(lib_runs, 'write'):.2f} "
          f"= {lib_total:.2f}")
    print(f"  API:     upload {median(api_runs, 'upload'):.2f} + queue/run "
          f"{median(api_runs, 'run'):.2f} + download {median(api_runs, 'download'):.2f} "
          f"= {api_total:.2f}   (worker read+estimate+store "
          f"{median(api_runs, 'worker_compute'):.2f})")
    per_run = [round(a["total"] / b["total"], 2)
               for a, b in zip(api_runs, lib_runs, strict=True)]
    print(f"  ratio API / library: {ratio:.2f}  (target <= 1.2, issue 21)   per run: {per_run}")
    print(f"  result PLY sizes equal: {same_size}")
    if args.json:
        args.json.write_text(json.dumps({
            "points": args.points, "repeat": args.repeat, "threads": args.threads,
            "params": params, "library": lib_runs, "api": api_runs,
            "median_library_s": lib_total, "median_api_s": api_total, "ratio": ratio},
            indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
