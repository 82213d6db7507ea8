"""Soak of issue 18: kill -9 cycles of the server under a mix of jobs.

Usage::

    python benchmarks/soak.py                 # 20 kill -9 cycles
    python benchmarks/soak.py --cycles 5 --seed 3 --json /tmp/soak.json

``kill`` phase: a real service on loopback; each cycle submits a mix of jobs (small JSON
clouds and 200k-point NPY uploads), waits a random 0.5 to 3 s, kills the server with SIGKILL
(its workers follow it) and starts it again on the same data folder. At the end every
accepted job is followed to its end; the report counts them by final status and error type
(none may fail because of the restarts: a restart is not an attempt).

Memory per input byte of every format is measured by ``benchmarks/read_memory.py``.
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
    refused: dict[int, int] = {}  # submissions not accepted, by status
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
                        else:
                            refused[r.status_code] = refused.get(r.status_code, 0) + 1
                    buffer = io.BytesIO()
                    np.save(buffer, np.random.default_rng(cycle).normal(size=(200_000, 3)))
                    r = client.post("/v1/jobs", files={"file": ("c.npy", buffer.getvalue())},
                                    data={"params": json.dumps({"method": "knn", "k": 10})})
                    if r.status_code == 202:
                        accepted.append(r.json()["id"])
                    else:
                        refused[r.status_code] = refused.get(r.status_code, 0) + 1
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
    return {"cycles": cycles, "accepted": len(accepted), "refused": refused,
            "outcomes": outcomes,
            "max_restarts_of_a_job": restarts, "max_attempts_of_a_job": attempts,
            "seconds": round(time.perf_counter() - started, 1)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20, help="kill -9 cycles (0: skip)")
    parser.add_argument("--seed", type=int, default=0, help="waits between kills")
    parser.add_argument("--json", type=Path, help="also write the report here")
    args = parser.parse_args(argv)
    report: dict = {}
    if args.cycles:
        report["kill"] = kill_cycles(args.cycles, args.seed)
        k = report["kill"]
        print(f"{k['cycles']} kill -9 cycles in {k['seconds']} s: {k['accepted']} jobs "
              f"accepted (refused by status: {k['refused']}), outcomes {k['outcomes']}, "
              f"at most {k['max_restarts_of_a_job']} "
              f"restart(s) and {k['max_attempts_of_a_job']} attempt(s) for one job")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    kill = report.get("kill")
    return 0 if kill is None or set(kill["outcomes"]) <= {"succeeded"} else 1


if __name__ == "__main__":
    raise SystemExit(main())
