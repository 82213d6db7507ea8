"""Load: benchmarks/load.py (a real server, and a separate client process on loopback that
submits 200 jobs at once and polls them) finishes every job, loses and duplicates none, and
the service's memory stays bounded."""

from __future__ import annotations

import json
import subprocess
import sys

from service_helpers import REPO

# Growth allowed over the idle service (proportional set size of server + fork server +
# workers); the 200 small jobs themselves need a few MiB each at most, one per worker at once.
MEMORY_GROWTH_MIB = 256


def test_two_hundred_concurrent_jobs(tmp_path):
    out = tmp_path / "load.json"
    run = subprocess.run([sys.executable, str(REPO / "benchmarks" / "load.py"), "--jobs", "200",
                          "--points", "500", "--keys", "4", "--timeout", "240",
                          "--json", str(out)],
                         cwd=REPO, capture_output=True, text=True, timeout=400)
    assert out.exists(), run.stdout + run.stderr
    report = json.loads(out.read_text())
    print(run.stdout)
    assert report["accepted"] == report["unique_ids"] == 200
    assert report["succeeded"] == 200, report["errors"]
    assert report["failed_jobs"] == 0 and report["wrong_results"] == 0
    assert report["lost"] == 0 and report["duplicated_in_listings"] == 0
    assert report["foreign_in_listings"] == 0 and report["listings_match_keys"]
    assert report["server_errors"] == 0 and report["http_errors"] == 0
    assert report["server_errors_logged"] == 0
    assert report["max_attempts"] == 1  # nothing crashed or ran twice
    memory = report["memory"]
    assert memory["samples"] > 10
    assert memory["peak_pss_mib"] < memory["idle_pss_mib"] + MEMORY_GROWTH_MIB, memory
    assert run.returncode == 0, run.stdout + run.stderr
