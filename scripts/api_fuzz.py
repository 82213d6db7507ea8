"""schemathesis with every check against a real service, reproducibly (fixed seed).

Usage::

    python scripts/api_fuzz.py                          # seed 18, 100 examples an operation
    python scripts/api_fuzz.py --seed 7 --examples 30 --report /tmp/fuzz

Starts ``python -m service`` on a free loopback port with a fresh API key, small limits and
a temporary data folder, runs ``schemathesis run openapi/openapi.json --checks all`` against
it (phases examples, coverage, fuzzing and stateful; one worker, so the run is the same for
the same seed), prints schemathesis' summary and one line per distinct failure, and exits
with schemathesis' status. ``docs/reliability.md`` lists what it finds and why each
remaining finding is not a defect.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import secrets
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _load_benchmark_helpers():
    """benchmarks/load.py as a private module. Putting benchmarks/ on sys.path instead would
    let its service.py shadow the service package in every process started afterwards (a
    test importing this script broke the test session's worker pools that way)."""
    spec = importlib.util.spec_from_file_location("_api_fuzz_load",
                                                  REPO / "benchmarks" / "load.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_load = _load_benchmark_helpers()
free_port, wait_ready = _load.free_port, _load.wait_ready

# Checks switched off, each with its reason in docs/reliability.md ("API fuzzing").
EXCLUDED: tuple[str, ...] = ()

# Findings that are not defects (docs/reliability.md, "API fuzzing"): (check, what the case
# text must contain, why). Anything else the run reports is a defect.
DOCUMENTED: tuple[tuple[str, str, str], ...] = (
    ("ST202", r'"status":422.*"type":"/problems/(malformed-file|too-few-points|'
              r'non-finite-coordinates)"|"type":"/problems/(malformed-file|too-few-points|'
              r'non-finite-coordinates)".*"status":422',
     "a schema-valid upload whose bytes are not a readable cloud (OpenAPI cannot describe "
     "a file's content)"),
    ("ST202", r'"type":"/problems/invalid-cloud".*(normals must have shape|faces: row|'
              r'faces: vertex|non-finite|outside)',
     "cross-member or value rules JSON Schema cannot state (normals as many as points, "
     "face indices below the point count, finite products)"),
    ("ST202", r"multipart/form-data.*needs per-point normals",
     "orientation 'normals' on an uploaded file without normals (what a file holds is not "
     "in the schema; for JSON bodies the schema says it)"),
    ("ST202", r"/problems/invalid-parameters.*method '\w+': (\w+ \([^)]*\) must be [<>]= "
              r"\w+ \(|.* gives more than \d+ )",
     "a parameter bounded by another (beta_min <= beta_max, alpha_step <= alpha_start, "
     "candidates >= min_neighbors, at most 1000 beta or alpha steps): JSON Schema compares "
     "a value with constants only"),
    ("ST202", r'"type":"/problems/too-costly"',
     "a synchronous request whose estimated work exceeds CURVATURE_SYNC_MAX_COST (depends "
     "on the point count times the parameters)"),
    ("ST201", r"Invalid component:[ \t]*\n([ \t]*- (query: violates `additionalProperties`|"
              r"header: violates `required` \(was Authorization\))[ \t]*(\n|\Z))+"
              r"([ \t]*\n|Content-Type:|\Z)",
     "unknown query parameters are ignored (as most HTTP APIs do, so clients can add "
     "cache busters or newer parameters); a case that drops the Authorization header gets it "
     "back from the harness, which sends the key with every request (the ignored_auth check "
     "tests authentication itself)"),
    ("ST201", r"Invalid component:( in body)?(([ \t]*\n[ \t]*| )- (header: violates "
              r"`required` \(was Authorization\)|query: violates `additionalProperties`|"
              r"(body: )?violates `\w+` at \S*/allOf/\d+/anyOf/0\S*( \(was fit\))?))+"
              r"[ \t]*(\n|\Z)([ \t]*\n|Content-Type:|\Z)",
     "a fit-only parameter (solver, normal_k): the schema's anyOf admits it with a matching fit "
     "(its first branch), with the parameter null, or with fit absent when the default fit "
     "takes it; schemathesis breaks the first branch only (removes 'fit' or gives another "
     "fit) and takes the request for invalid, while another branch still accepts it"),
    ("ST301", r'"status":"cancelled"',
     "DELETE of a queued or running job cancels it; the record stays readable as "
     "'cancelled' until it expires (DESIGN.md section 7)"),
    ("error", r"Unsupported type: 'Binary'",
     "schemathesis' coverage phase cannot evaluate if/then conditions on a multipart body "
     "holding a file; the fuzzing and stateful phases still cover the operation"),
)


def serve(data_dir: Path, port: int, key: str, log) -> subprocess.Popen:
    """The service with limits small enough that generated uploads stay cheap."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
    env.update({"CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(port),
                "CURVATURE_DATA_DIR": str(data_dir), "CURVATURE_API_KEYS": key,
                "CURVATURE_LOG_LEVEL": "warning", "CURVATURE_SYNC_MAX_POINTS": "2000",
                "CURVATURE_MAX_UPLOAD_BYTES": str(1 << 20),
                "CURVATURE_MAX_JSON_BYTES": str(1 << 20),
                "CURVATURE_JOB_TIME_LIMIT_SECONDS": "20", "CURVATURE_WARMUP": "false"})
    server = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO, env=env,
                              stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    wait_ready(f"http://127.0.0.1:{port}", server)
    return server


def command(url: str, key: str, seed: int, examples: int, report: Path,
            phases: str, max_time: float | None) -> list[str]:
    cmd = [str(Path(sys.executable).with_name("schemathesis")), "--no-color", "run",
           str(REPO / "openapi" / "openapi.json"), "--url", url, "--checks", "all",
           "--seed", str(seed), "--max-examples", str(examples), "--workers", "1",
           "--phases", phases, "--header", f"Authorization: Bearer {key}",
           "--request-timeout", "60", "--suppress-health-check", "all",
           "--report", "junit", "--report-dir", str(report), "--output-truncate", "true"]
    if EXCLUDED:
        cmd += ["--exclude-checks", ",".join(EXCLUDED)]
    if max_time:
        cmd += ["--max-time", str(max_time)]
    return cmd


def classify(report: Path) -> list[tuple[str, str, str | None]]:
    """(operation, check, reason or None) for every failing case and error of the JUnit
    report; the reason is None for an undocumented finding."""
    import xml.etree.ElementTree as ET

    found = []
    for xml in sorted(report.glob("*.xml")):
        for case in ET.parse(xml).getroot().iter("testcase"):
            for node in list(case.iter("failure")) + list(case.iter("error")):
                text = node.text or ""
                parts = re.split(r"\n(?=\d+\. Test Case ID)", text) if node.tag == "failure" \
                    else [text]
                for part in parts:
                    code = node.tag if node.tag == "error" else \
                        (re.search(r"^- (ST\d+)", part, re.M) or [None, "?"])[1]
                    reason = next((why for check, pattern, why in DOCUMENTED
                                   if check == code and re.search(pattern, part, re.S)), None)
                    found.append((case.get("name"), code, reason))
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=18)
    parser.add_argument("--examples", type=int, default=100, help="per operation")
    parser.add_argument("--phases", default="examples,coverage,fuzzing,stateful")
    parser.add_argument("--max-time", type=float, help="seconds for the whole run")
    parser.add_argument("--report", type=Path, help="folder for the JUnit report")
    args = parser.parse_args(argv)
    key = secrets.token_urlsafe(24)
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="curvature-fuzz-") as tmp:
        report = args.report or Path(tmp) / "report"
        with open(Path(tmp) / "server.log", "wb") as log:
            server = serve(Path(tmp) / "data", port, key, log)
            try:
                done = subprocess.run(command(f"http://127.0.0.1:{port}", key, args.seed,
                                              args.examples, report, args.phases,
                                              args.max_time),
                                      cwd=REPO, text=True, capture_output=True)
            finally:
                server.terminate()
                server.wait(timeout=30)
        print(done.stdout[-20000:])
        if done.stderr.strip():
            print(done.stderr[-3000:], file=sys.stderr)
        errors = [line for line in (Path(tmp) / "server.log").read_text("utf-8", "replace")
                  .splitlines() if "Traceback" in line or "ERROR" in line]
        print(f"server log: {len(errors)} error line(s)")
        for line in errors[:20]:
            print("  " + line)
        findings = classify(report)
    print(f"{len(findings)} finding(s):")
    for operation, code, reason in findings:
        print(f"  {operation}: {code}: " + (f"documented: {reason}" if reason else "DEFECT"))
    defects = [f for f in findings if f[2] is None]
    print(f"undocumented findings: {len(defects)}")
    return 1 if defects or errors or (done.returncode and not findings) else 0


if __name__ == "__main__":
    raise SystemExit(main())
