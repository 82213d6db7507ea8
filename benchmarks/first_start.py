"""Time from ``make run`` to a ready service: ``/healthz`` and ``/readyz`` answering 200.

Issue 17's target: on a fresh clone, after the install step (``make venv``), the first
``make run`` answers ``/readyz`` 200 within 30 s of the process start. This script starts
``make run`` in ``--repo`` (by default this checkout) on a free loopback port with an empty
data folder, polls both probes every 0.1 s, stops the server's whole process group, and
repeats ``--runs`` times. The first run is the one the issue asks about (the first start
after the install); the later ones show the steady state. Only the standard library is used,
so the script measures the repository it is pointed at, not the one it lives in.

Usage::

    git clone /path/to/repo /tmp/fresh && make -C /tmp/fresh venv
    python3 benchmarks/first_start.py --repo /tmp/fresh --runs 3 --json first_start.json
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
import urllib.error
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port nothing listens on right now (the kernel's pick)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def answers_200(url: str) -> bool:
    """True when ``url`` answers 200 (any other status or no answer: False)."""
    try:
        with urllib.request.urlopen(url, timeout=2) as response:
            return response.status == 200
    except (urllib.error.URLError, OSError):
        return False


def fmt(seconds: float | None) -> str:
    """``12.3 s``, or ``not reached``."""
    return "not reached" if seconds is None else f"{seconds:.1f} s"


def stop(proc: subprocess.Popen) -> None:
    """SIGTERM the server's process group (make, python, workers), SIGKILL if it lingers."""
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def one_start(repo: Path, limit: float, log: Path) -> dict:
    """Start ``make run`` once; seconds from the start until each probe answered 200.

    Returns
    -------
    dict
        ``healthz`` and ``readyz`` in seconds (None when not reached within ``limit``),
        ``exit`` (the server's exit status if it ended by itself, else None).
    """
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="first-start-") as data, open(log, "ab") as out:
        env = {**os.environ, "CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
               "CURVATURE_DATA_DIR": data}
        base = f"http://127.0.0.1:{port}"
        seen: dict[str, float | None] = {"healthz": None, "readyz": None}
        t0 = time.monotonic()
        proc = subprocess.Popen(["make", "--no-print-directory", "run"], cwd=repo, env=env,
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            while time.monotonic() - t0 < limit and proc.poll() is None:
                for probe in ("healthz", "readyz"):
                    if seen[probe] is None and answers_200(f"{base}/{probe}"):
                        seen[probe] = time.monotonic() - t0
                if seen["readyz"] is not None:
                    break
                time.sleep(0.1)
        finally:
            ended = proc.poll()
            stop(proc)
    return {**seen, "exit": ended}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=REPO,
                        help="checkout to start (after its `make venv`); default: this one")
    parser.add_argument("--runs", type=int, default=3, help="starts, one after the other")
    parser.add_argument("--limit", type=float, default=600.0,
                        help="seconds to wait for /readyz before giving up on a start")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error(f"--runs must be >= 1, got {args.runs}")
    repo = args.repo.resolve()
    if not (repo / ".venv" / ".kernels").exists():
        print(f"note: {repo}/.venv/.kernels is missing: `make run` installs first and that "
              "time is counted", file=sys.stderr)
    log = Path(tempfile.gettempdir()) / f"first-start-{os.getpid()}.log"
    runs = []
    for i in range(args.runs):
        run = one_start(repo, args.limit, log)
        runs.append(run)
        print(f"start {i + 1}: /healthz {fmt(run['healthz'])}, /readyz {fmt(run['readyz'])}"
              + ("" if run["exit"] is None else f", exited with status {run['exit']}"))
    ready = [r["readyz"] for r in runs if r["readyz"] is not None]
    summary = {"repo": str(repo), "runs": runs, "first_readyz": runs[0]["readyz"],
               "median_readyz": statistics.median(ready) if ready else None,
               "load_average": os.getloadavg()[0], "log": str(log)}
    print(f"first start ready in {fmt(summary['first_readyz'])}; median of {len(ready)} "
          f"ready starts {fmt(summary['median_readyz'])}; load average "
          f"{summary['load_average']:.1f}; server log {log}")
    if args.json:
        args.json.write_text(json.dumps(summary, indent=2) + "\n")
    return 0 if len(ready) == len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
