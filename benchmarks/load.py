"""Load test: a real service on loopback and a separate client process submitting many jobs at
once, polling them to the end and checking every result.

Usage::

    python benchmarks/load.py                       # 200 jobs of 500 points, 4 API keys
    python benchmarks/load.py --jobs 400 --points 2000 --json /tmp/load.json

The script starts ``python -m service`` on a free port of 127.0.0.1 with a temporary data
folder and fresh API keys, then runs itself as the client (``load.py client ...``) in another
process: it submits every job concurrently (httpx, asyncio), retrying 429/503 after their
Retry-After, polls each job until it is final, downloads each result and checks its curvature
(job i is a sphere of radius 1 + i / jobs, so its k1 must be 1 / radius), and pages through
each key's job list. Meanwhile the server's process tree (server, fork server, workers) is
sampled for memory. The report gives jobs, failures, lost and duplicated jobs, latency
percentiles and peak memory; ``--json`` also writes it to a file. Only loopback is used, and
every loop is bounded in count and time.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import os
import random
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FINAL = ("succeeded", "failed", "cancelled")


# -- the client process --------------------------------------------------------------------------

def sphere(n: int, radius: float, seed: int) -> np.ndarray:
    """``n`` points on a sphere (jittered Fibonacci lattice): k1 = k2 = 1 / radius."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i + np.random.default_rng(seed).uniform(0, 0.01, n)
    return radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {}
    arr = np.asarray(values) * 1000.0
    return {"n": len(values), "p50_ms": round(float(np.percentile(arr, 50)), 1),
            "p95_ms": round(float(np.percentile(arr, 95)), 1),
            "p99_ms": round(float(np.percentile(arr, 99)), 1),
            "max_ms": round(float(arr.max()), 1)}


async def run_client(url: str, keys: list[str], jobs: int, points: int,
                     timeout: float) -> dict:
    """Submit ``jobs`` jobs at once over ``keys``, poll them, check results and listings."""
    import httpx

    deadline = time.monotonic() + timeout
    limits = httpx.Limits(max_connections=jobs, max_keepalive_connections=jobs)
    lat = {"submit": [], "poll": [], "turnaround": [], "result": [], "list": []}
    counts = {"retried_429_503": 0, "http_errors": 0, "server_errors": 0, "transport_errors": 0}
    records: list[dict] = [{} for _ in range(jobs)]

    async def request(client, method, path, key, what, **kwargs):
        """One call; 429/503 are retried after Retry-After, transport errors a few times."""
        headers = {"Authorization": f"Bearer {key}"}
        for _ in range(100):
            if time.monotonic() > deadline:
                raise TimeoutError(f"{what}: out of time")
            start = time.perf_counter()
            try:
                response = await client.request(method, path, headers=headers, **kwargs)
            except httpx.TransportError:
                counts["transport_errors"] += 1
                await asyncio.sleep(0.5)
                continue
            elapsed = time.perf_counter() - start
            if response.status_code in (429, 503):
                counts["retried_429_503"] += 1
                await asyncio.sleep(float(response.headers.get("retry-after", "1")))
                continue
            if response.status_code >= 500:
                counts["server_errors"] += 1
            elif response.status_code >= 400:
                counts["http_errors"] += 1
            lat[what].append(elapsed)
            return response
        raise RuntimeError(f"{what}: gave up after 100 attempts")

    async def one_job(client, i: int) -> None:
        key = keys[i % len(keys)]
        radius = 1.0 + i / jobs
        body = {"points": sphere(points, radius, i).tolist(),
                "params": {"method": "knn", "k": 12, "fit": "monge"}}
        record = records[i]
        record.update(key=key, radius=radius)
        submitted = time.perf_counter()
        response = await request(client, "POST", "/v1/jobs", key, "submit", json=body)
        if response.status_code != 202:
            record["error"] = f"submit: {response.status_code} {response.text[:200]}"
            return
        record["id"] = response.json()["id"]
        # Spread the polls so 200 jobs do not poll in lock step.
        await asyncio.sleep(random.uniform(0.0, 0.5))
        while True:
            response = await request(client, "GET", f"/v1/jobs/{record['id']}", key, "poll")
            if response.status_code != 200:
                record["error"] = f"poll: {response.status_code} {response.text[:200]}"
                return
            job = response.json()
            if job["status"] in FINAL:
                break
            await asyncio.sleep(0.5)
        lat["turnaround"].append(time.perf_counter() - submitted)
        record.update(status=job["status"], n_points=job["n_points"], attempts=job["attempts"])
        if job["status"] != "succeeded":
            record["error"] = f"job {job['status']}: {job.get('error')}"
            return
        response = await request(client, "GET", f"/v1/jobs/{record['id']}/result", key,
                                 "result", params={"format": "npz"})
        with np.load(io.BytesIO(response.content)) as data:
            k1 = data["k1"][data["status"] == 0]
        record["k1_median"] = float(np.median(k1)) if k1.size else float("nan")

    async def listing(client, key: str) -> list[str]:
        ids, cursor = [], None
        for _ in range(1000):
            params = {"limit": 200} | ({"cursor": cursor} if cursor else {})
            page = (await request(client, "GET", "/v1/jobs", key, "list", params=params)).json()
            ids += [item["id"] for item in page["items"]]
            cursor = page["next_cursor"]
            if cursor is None:
                break
        return ids

    started = time.perf_counter()
    async with httpx.AsyncClient(base_url=url, timeout=120.0, limits=limits) as client:
        await asyncio.gather(*(one_job(client, i) for i in range(jobs)))
        listed = {key: await listing(client, key) for key in keys}
    duration = time.perf_counter() - started

    submitted = [r["id"] for r in records if "id" in r]
    wrong = [r for r in records if "k1_median" in r
             and not abs(r["k1_median"] * r["radius"] - 1.0) < 0.05]
    listed_all = [i for ids in listed.values() for i in ids]
    by_key_ok = all(sorted(listed[key]) == sorted(r["id"] for r in records
                                                 if r.get("key") == key and "id" in r)
                    for key in keys)
    return {
        "jobs": jobs, "points_per_job": points, "keys": len(keys),
        "accepted": len(submitted), "unique_ids": len(set(submitted)),
        "succeeded": sum(r.get("status") == "succeeded" for r in records),
        "failed_jobs": sum(r.get("status") in ("failed", "cancelled") for r in records),
        "errors": [r["error"] for r in records if "error" in r][:10],
        "wrong_results": len(wrong),
        "lost": len(set(submitted) - set(listed_all)),
        "duplicated_in_listings": len(listed_all) - len(set(listed_all)),
        "foreign_in_listings": len(set(listed_all) - set(submitted)),
        "listings_match_keys": by_key_ok,
        "max_attempts": max((r.get("attempts", 0) for r in records), default=0),
        **counts,
        "duration_s": round(duration, 2),
        "jobs_per_s": round(jobs / duration, 2),
        "latency": {what: percentiles(values) for what, values in lat.items()},
    }


def client_main(args) -> int:
    report = asyncio.run(run_client(args.url, args.keys.split(","), args.jobs, args.points,
                                    args.timeout))
    json.dump(report, sys.stdout)
    return 0


# -- the orchestrator ------------------------------------------------------------------------

def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def process_tree(root: int) -> list[int]:
    """``root`` and all its descendants (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [root]
    while todo:
        pid = todo.pop()
        tree.append(pid)
        todo += children.get(pid, [])
    return tree


def memory_of(pids: list[int]) -> tuple[int, int]:
    """Summed RSS and PSS in bytes (PSS shares pages common to forked workers fairly)."""
    rss = pss = 0
    for pid in pids:
        try:
            for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
                if line.startswith("Rss:"):
                    rss += int(line.split()[1]) * 1024
                elif line.startswith("Pss:"):
                    pss += int(line.split()[1]) * 1024
        except OSError:
            continue
    return rss, pss


class MemorySampler(threading.Thread):
    """Samples the memory of a process tree every ``interval`` seconds until stopped."""

    def __init__(self, root: int, interval: float = 0.2):
        super().__init__(daemon=True)
        self.root, self.interval = root, interval
        self.peak_rss = self.peak_pss = 0
        self.peak_processes = 0
        self.samples = 0
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.is_set():
            pids = process_tree(self.root)
            rss, pss = memory_of(pids)
            self.peak_rss, self.peak_pss = max(self.peak_rss, rss), max(self.peak_pss, pss)
            self.peak_processes = max(self.peak_processes, len(pids))
            self.samples += 1
            self._halt.wait(self.interval)

    def stop(self) -> None:
        self._halt.set()
        self.join()


def wait_ready(url: str, process: subprocess.Popen, timeout: float = 180.0) -> None:
    import httpx

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError("the service exited during startup")
        try:
            if httpx.get(f"{url}/readyz", timeout=5).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise RuntimeError(f"the service was not ready in {timeout} s")


def stop_server(server: subprocess.Popen) -> None:
    """SIGTERM, then SIGKILL after 30 s."""
    server.send_signal(signal.SIGTERM)
    try:
        server.wait(timeout=30)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()


def busy_phase(url: str, key: str, workers: int, points: int, polls: int = 200,
               lane_off: bool = False) -> dict:
    """Poll ``GET /v1/jobs/{id}`` while every worker computes a large job, and time a small
    job submitted meanwhile (issue 18, findings 6: head-of-line blocking and slow polling).

    One large job per worker (``points`` random points, k-NN with k = 24) is uploaded and
    waited for until all run; then ``polls`` sequential GETs of one of them are timed, and a
    100-point job is submitted and followed to its end.
    """
    import httpx

    headers = {"Authorization": f"Bearer {key}"}
    with httpx.Client(base_url=url, headers=headers, timeout=60) as client:
        large = []
        for i in range(workers):
            buffer = io.BytesIO()
            np.save(buffer, np.random.default_rng(i).normal(size=(points, 3)))
            response = client.post("/v1/jobs", files={"file": (f"big{i}.npy",
                                                               buffer.getvalue())},
                                   data={"params": json.dumps({"method": "knn", "k": 24})})
            response.raise_for_status()
            large.append(response.json()["id"])
        # With the small-job lane on, one worker stays free: then one large job runs.
        want = workers if lane_off else max(1, workers - 1)
        deadline = time.monotonic() + 120
        while sum(client.get(f"/v1/jobs/{j}").json()["status"] == "running"
                  for j in large) < want:
            if time.monotonic() > deadline:
                raise RuntimeError("the large jobs did not start")
            time.sleep(0.05)
        small = client.post("/v1/jobs", json={"points": sphere(100, 1.0, 0).tolist()})
        small.raise_for_status()
        small_id, small_start = small.json()["id"], time.perf_counter()
        small_seconds = None
        latencies = []
        for _ in range(polls):
            start = time.perf_counter()
            status = client.get(f"/v1/jobs/{large[0]}").json()["status"]
            latencies.append(time.perf_counter() - start)
            if small_seconds is None and client.get(
                    f"/v1/jobs/{small_id}").json()["status"] in FINAL:
                small_seconds = time.perf_counter() - small_start
        still_busy = status == "running"
        while small_seconds is None and time.perf_counter() - small_start < 600:
            if client.get(f"/v1/jobs/{small_id}").json()["status"] in FINAL:
                small_seconds = time.perf_counter() - small_start
            time.sleep(0.05)
        for job_id in large:
            client.delete(f"/v1/jobs/{job_id}")
    return {"large_points": points, "large_jobs": workers, "running_large": want,
            "small_lane": not lane_off, "poll": percentiles(latencies),
            "large_still_running_after_polls": still_busy,
            "small_job_seconds": None if small_seconds is None else round(small_seconds, 3)}


def run(jobs: int, points: int, keys: int, workers: int, timeout: float,
        busy_points: int = 0) -> dict:
    """Start the service, run the client process against it, return the combined report."""
    key_list = [secrets.token_urlsafe(24) for _ in range(keys)]
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="curvature-load-") as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
        env.update({"CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
                    "CURVATURE_DATA_DIR": str(Path(tmp) / "data"),
                    "CURVATURE_API_KEYS": ",".join(key_list),
                    "CURVATURE_WORKERS": str(workers), "CURVATURE_LOG_LEVEL": "warning"})
        log_path = Path(tmp) / "server.log"
        with open(log_path, "wb") as log:
            server = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO, env=env,
                                      stdout=log, stderr=subprocess.STDOUT,
                                      start_new_session=True)
        try:
            wait_ready(url, server)
            idle_rss, idle_pss = memory_of(process_tree(server.pid))
            sampler = MemorySampler(server.pid)
            sampler.start()
            client = subprocess.run(
                # "--keys=" form: a generated key may start with "-", which argparse would
                # take for an option
                [sys.executable, __file__, "client", "--url", url, "--keys=" + ",".join(key_list),
                 "--jobs", str(jobs), "--points", str(points), "--timeout", str(timeout)],
                capture_output=True, text=True, timeout=timeout + 60)
            sampler.stop()
            if client.returncode != 0:
                raise RuntimeError(f"the client failed:\n{client.stderr[-3000:]}")
            report = json.loads(client.stdout)
            end_rss, end_pss = memory_of(process_tree(server.pid))
            if busy_points:
                report["busy"] = [busy_phase(url, key_list[0], workers, busy_points)]
        finally:
            stop_server(server)
        server_log = log_path.read_text(errors="replace")
    mib = 1 << 20
    report["memory"] = {
        "workers": workers, "processes_peak": sampler.peak_processes,
        "samples": sampler.samples,
        "idle_rss_mib": round(idle_rss / mib), "idle_pss_mib": round(idle_pss / mib),
        "peak_rss_mib": round(sampler.peak_rss / mib),
        "peak_pss_mib": round(sampler.peak_pss / mib),
        "end_rss_mib": round(end_rss / mib), "end_pss_mib": round(end_pss / mib),
    }
    report["server_errors_logged"] = server_log.count(" ERROR ") + server_log.count("Traceback")
    if busy_points:
        # Every worker on a large job (the small-job lane switched off): polling while the
        # cores are all taken, and how long a small job waits then.
        report["busy"].append(busy_only(busy_points, workers))
    return report


def busy_only(busy_points: int, workers: int) -> dict:
    """:func:`busy_phase` on a fresh service whose workers all take large jobs."""
    key = secrets.token_urlsafe(24)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="curvature-busy-") as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
        env.update({"CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
                    "CURVATURE_DATA_DIR": str(Path(tmp) / "data"), "CURVATURE_API_KEYS": key,
                    "CURVATURE_WORKERS": str(workers), "CURVATURE_LOG_LEVEL": "warning",
                    "CURVATURE_SMALL_JOB_WORKERS": "0"})
        server = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO, env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  start_new_session=True)
        try:
            wait_ready(url, server)
            return busy_phase(url, key, workers, busy_points, lane_off=True)
        finally:
            stop_server(server)


def print_report(report: dict) -> None:
    m = report["memory"]
    print(f"{report['jobs']} jobs x {report['points_per_job']} points over {report['keys']} "
          f"keys, {m['workers']} workers: {report['duration_s']} s "
          f"({report['jobs_per_s']} jobs/s)")
    print(f"  accepted {report['accepted']}, succeeded {report['succeeded']}, failed "
          f"{report['failed_jobs']}, wrong results {report['wrong_results']}, lost "
          f"{report['lost']}, duplicated {report['duplicated_in_listings']}, server errors "
          f"{report['server_errors']}, retries after 429/503 {report['retried_429_503']}")
    for what, p in report["latency"].items():
        if p:
            print(f"  {what:<10} n={p['n']:<5} p50 {p['p50_ms']:>8} ms  p95 {p['p95_ms']:>8} ms"
                  f"  p99 {p['p99_ms']:>8} ms  max {p['max_ms']:>8} ms")
    for busy in report.get("busy", []):
        p = busy["poll"]
        lane = "small-job lane on" if busy["small_lane"] else "small-job lane off"
        print(f"  {busy['large_jobs']} jobs of {busy['large_points']} points submitted, "
              f"{busy['running_large']} running ({lane}): GET /v1/jobs/{{id}} p50 "
              f"{p['p50_ms']} ms, p95 {p['p95_ms']} ms, max {p['max_ms']} ms (n={p['n']}); "
              f"a 100-point job took {busy['small_job_seconds']} s")
    print(f"  memory of the service's {m['processes_peak']} processes: idle PSS "
          f"{m['idle_pss_mib']} MiB, peak PSS {m['peak_pss_mib']} MiB (peak RSS sum "
          f"{m['peak_rss_mib']} MiB), after the run PSS {m['end_pss_mib']} MiB")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command")
    client = sub.add_parser("client", help="(internal) the client process")
    client.add_argument("--url", required=True)
    client.add_argument("--keys", required=True)
    for p in (parser, client):
        p.add_argument("--jobs", type=int, default=200, help="jobs to submit at once")
        p.add_argument("--points", type=int, default=500, help="points per cloud")
        p.add_argument("--timeout", type=float, default=600.0, help="seconds for the run")
    parser.add_argument("--keys", type=int, default=4, help="API keys the jobs are spread over")
    parser.add_argument("--workers", type=int, default=2, help="CURVATURE_WORKERS")
    parser.add_argument("--json", type=Path, help="also write the report here")
    parser.add_argument("--busy-points", type=int, default=0,
                        help="then time polling while every worker runs a job of this many "
                        "points (0: skip)")
    args = parser.parse_args(argv)
    if args.command == "client":
        return client_main(args)
    report = run(args.jobs, args.points, args.keys, args.workers, args.timeout,
                 args.busy_points)
    print_report(report)
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    ok = (report["succeeded"] == report["jobs"] and report["lost"] == 0
          and report["duplicated_in_listings"] == 0 and report["wrong_results"] == 0)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
