"""The examples of README.md and docs/usage.md, run as tests.

Every fenced ``python`` and ``bash`` block of these pages is executed, in order, in one scratch
folder per page that starts with ``scan.ply`` (a small noisy torus):

- ``python`` blocks run in this process, in one namespace per page (so a block may use what an
  earlier block of the same page defined);
- ``bash`` blocks run with ``bash -euo pipefail``; ``.venv/bin/`` means this environment's
  scripts folder;
- blocks that talk to ``http://127.0.0.1:8000`` go to a real ``python -m service`` started
  for the page on a free port, with the API key the examples use;
- a ``text`` block shows output: each of its lines (but ``...``) must appear in the output of
  the block run just before it.

A block that cannot run here says so in its first line, visibly in the page:
``# docs-test: skip (reason)``, or ``# docs-test: fails with "message"`` for an example of a
refusal (it must exit non-zero and print the message). The number of run, skipped and checked
blocks per page is pinned below, so an example cannot silently stop being tested.

Besides running the examples, the pages' links, ``CURVATURE_*`` variables, endpoints and
problem types are checked against the code, and the numbers of the README's method table
against the reports it links to.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import traceback
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import curvature

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "service"))
from service_helpers import start_limit, stop_group  # noqa: E402

DOCS = ("README.md", "docs/usage.md")
# (blocks run, blocks skipped, text blocks checked) per page.
EXPECTED = {"README.md": (9, 6, 5), "docs/usage.md": (14, 0, 0)}
# The service the examples talk to, and the key they send.
DOCS_URL = "http://127.0.0.1:8000"
DOCS_KEY = "my-key-0123456789abcdef"
# Client-side variables of `curvature remote`, not service settings.
CLIENT_VARIABLES = {"CURVATURE_URL", "CURVATURE_API_KEY"}
CODE_LANGUAGES = {"python", "bash"}
OTHER_LANGUAGES = {"text", "json"}
BLOCK_TIMEOUT = 180
FENCE = re.compile(r"^```(\S*)\s*$")
MARKER = re.compile(r"^#\s*docs-test:\s*(.*)$")
SKIP = re.compile(r"^skip \((.+)\)$")
FAILS = re.compile(r'^fails with "(.+)"$')


def venv_bin() -> Path:
    """Where ``.venv/bin/`` of the examples points: the running interpreter's scripts."""
    local = REPO / ".venv" / "bin"
    return local if (local / "curvature").exists() else Path(sys.executable).parent


@dataclass
class Block:
    doc: str
    line: int  # of the opening fence, 1-based
    lang: str
    code: str

    @property
    def where(self) -> str:
        return f"{self.doc}:{self.line}"

    @property
    def marker(self) -> str | None:
        first = self.code.lstrip("\n").split("\n", 1)[0].strip()
        found = MARKER.match(first)
        return found.group(1).strip() if found else None

    @property
    def needs_server(self) -> bool:
        return DOCS_URL in self.code


def blocks(doc: str) -> list[Block]:
    """Fenced blocks of a page, with their language and first line."""
    found, current, lang, start = [], None, "", 0
    for number, line in enumerate((REPO / doc).read_text().splitlines(), 1):
        fence = FENCE.match(line)
        if current is None and fence:
            current, lang, start = [], fence.group(1), number
        elif current is not None and line.strip() == "```":
            found.append(Block(doc, start, lang, "\n".join(current) + "\n"))
            current = None
        elif current is not None:
            current.append(line)
    assert current is None, f"{doc}:{start}: unclosed code fence"
    return found


def classify(block: Block) -> str:
    """'run', 'fails', 'skip' or 'output'; anything unrecognised fails the test."""
    if block.lang in OTHER_LANGUAGES:
        return "output" if block.lang == "text" else "data"
    assert block.lang in CODE_LANGUAGES, (
        f"{block.where}: fence language {block.lang!r} is neither run ({sorted(CODE_LANGUAGES)})"
        f" nor plain text ({sorted(OTHER_LANGUAGES)})")
    marker = block.marker
    if marker is None:
        return "run"
    if SKIP.match(marker):
        return "skip"
    if FAILS.match(marker):
        return "fails"
    raise AssertionError(f"{block.where}: unknown marker {marker!r}; use 'skip (reason)' or "
                         "'fails with \"message\"'")


# -- a real service for the HTTP examples --------------------------------------------------


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def clean_env() -> dict[str, str]:
    """This environment without CURVATURE_* variables, the venv's scripts first on PATH."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVATURE_")}
    env["PATH"] = f"{venv_bin()}{os.pathsep}{env.get('PATH', '')}"
    return env


class DocsServer:
    """``python -m service`` with the examples' API key, started when first needed."""

    def __init__(self, root: Path):
        self.root = root
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = root / "server.log"
        self.process: subprocess.Popen | None = None

    def start(self) -> None:
        if self.process is not None:
            return
        env = {**clean_env(), "CURVATURE_HOST": "127.0.0.1", "CURVATURE_PORT": str(self.port),
               "CURVATURE_DATA_DIR": str(self.root / "data"), "CURVATURE_API_KEYS": DOCS_KEY,
               "CURVATURE_WORKERS": "1", "CURVATURE_DISPATCH_POLL_SECONDS": "0.2",
               "CURVATURE_PROGRESS_INTERVAL_SECONDS": "0.1"}
        with open(self.log, "ab") as log:
            self.process = subprocess.Popen([sys.executable, "-m", "service"], cwd=REPO,
                                            env=env, stdout=log, stderr=subprocess.STDOUT,
                                            start_new_session=True)

    def wait_ready(self, timeout: float | None = None) -> str:
        """Start if needed and wait for /readyz 200: seconds with numba's cache warm, many
        minutes when a worker compiles the kernels first. A failed start is stopped."""
        self.start()
        try:
            return self._wait(start_limit() if timeout is None else timeout)
        except BaseException:
            self.stop()
            raise

    def _wait(self, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                pytest.fail(f"the service exited early:\n{self.tail()}")
            try:
                with urllib.request.urlopen(f"{self.url}/readyz", timeout=5) as answer:
                    if answer.status == 200:
                        return self.url
            except OSError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"the service was not ready in {timeout} s:\n{self.tail()}")
            time.sleep(0.2)

    def stop(self) -> None:
        if self.process is not None:
            stop_group(self.process)

    def tail(self) -> str:
        return self.log.read_text(errors="replace")[-4000:] if self.log.exists() else ""


# -- running a page -------------------------------------------------------------------------


def make_scan(path: Path) -> None:
    """The stand-in for the reader's scan: a 2,000-point torus, 0.2 % noise, no normals."""
    torus = curvature.synthetic.torus(2000, noise=0.2, seed=3)
    curvature.write(path, curvature.PointCloud(points=torus.points))


def prepare(block: Block, url: str | None) -> str:
    code = re.sub(r"(?<![\w/.])\.venv/bin/", f"{venv_bin()}/", block.code)
    return code.replace(DOCS_URL, url) if url else code


def run_python(block: Block, code: str, namespace: dict) -> str:
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, block.where, "exec"), namespace)
    except Exception:
        pytest.fail(f"{block.where}: python example failed\n--- output\n{out.getvalue()}"
                    f"--- error\n{traceback.format_exc()}")
    return out.getvalue()


def run_bash(block: Block, code: str, cwd: Path, env: dict, expect: str | None) -> str:
    try:
        done = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=BLOCK_TIMEOUT)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{block.where}: still running after {BLOCK_TIMEOUT} s\n{exc.output}")
    output = done.stdout + done.stderr
    if expect is None:
        assert done.returncode == 0, (
            f"{block.where}: exit status {done.returncode}\n--- script\n{code}--- output\n"
            f"{output}")
    else:
        assert done.returncode != 0 and expect in output, (
            f"{block.where}: expected a failure saying {expect!r}, got exit status "
            f"{done.returncode}\n--- output\n{output}")
    return output


def check_output(block: Block, previous: str | None) -> None:
    assert previous is not None, f"{block.where}: a text block must follow an example it shows"
    printed = {line.rstrip() for line in previous.splitlines()}
    for line in block.code.splitlines():
        if line.strip() and line.strip() != "...":
            assert line.rstrip() in printed, (
                f"{block.where}: shown output line not printed by the example before it:\n"
                f"  {line!r}\n--- actual output\n{previous}")


def run_page(doc: str, workdir: Path, server: DocsServer) -> dict[str, list[str]]:
    """Run every example of ``doc`` in ``workdir``; returns the blocks by what happened."""
    page = blocks(doc)
    kinds = [classify(b) for b in page]
    if any(b.needs_server and k in ("run", "fails") for b, k in zip(page, kinds, strict=True)):
        server.start()  # starts up while the first examples run
    make_scan(workdir / "scan.ply")
    env = {**clean_env(), "CURVATURE_PORT": str(free_port())}  # a refused start binds nothing
    namespace: dict = {"__name__": "__docs__"}
    done: dict[str, list[str]] = {"run": [], "skip": [], "output": []}
    previous = None
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        for block, kind in zip(page, kinds, strict=True):
            if kind == "output":
                check_output(block, previous)
                done["output"].append(block.where)
                continue
            if kind in ("skip", "data"):
                if kind == "skip":
                    done["skip"].append(block.where)
                continue
            url = server.wait_ready() if block.needs_server else None
            code = prepare(block, url)
            started = time.perf_counter()
            if block.lang == "python":
                previous = run_python(block, code, namespace)
            else:
                expect = FAILS.match(block.marker).group(1) if kind == "fails" else None
                previous = run_bash(block, code, workdir, env, expect)
            done["run"].append(f"{block.where} ({block.lang}, "
                               f"{time.perf_counter() - started:.1f} s)")
    finally:
        os.chdir(cwd)
    return done


@pytest.fixture
def server(tmp_path):
    proc = DocsServer(tmp_path)
    yield proc
    proc.stop()


needs_tools = pytest.mark.skipif(shutil.which("curl") is None or shutil.which("jq") is None,
                                 reason="the HTTP examples need curl and jq")


@needs_tools
@pytest.mark.timeout(300)
def test_readme_examples_run(tmp_path, server):
    work = tmp_path / "work"
    work.mkdir()
    done = run_page("README.md", work, server)
    print("\n".join(done["run"]))
    assert (len(done["run"]), len(done["skip"]), len(done["output"])) == EXPECTED["README.md"], done
    # What the examples claim to produce, read back.
    for name in ("torus_curvature.ply", "result.ply", "scan_knn.ply"):
        res = curvature.io.read_result(work / name)
        ok = res.status == 0
        assert ok.mean() > 0.95 and np.all(res.k1[ok] >= res.k2[ok]), name
    assert len(curvature.read(work / "result.ply")) == 2000
    assert len(curvature.read(work / "torus_paper.csv")) == 10_000
    for name in ("torus_knn.npz", "result.npz"):
        assert "k1" in np.load(work / name).files, name
    for name in ("result.csv", "scan_remote.csv"):
        assert (work / name).read_text().startswith("x,y,z,"), name
    assert json.loads((work / "paraboloid.json").read_text())["points"][40] == [0, 0, 0]


@pytest.mark.timeout(300)
def test_usage_examples_run(tmp_path, server):
    done = run_page("docs/usage.md", tmp_path, server)
    print("\n".join(done["run"]))
    assert (len(done["run"]), len(done["skip"]), len(done["output"])) == \
        EXPECTED["docs/usage.md"], done
    doc = json.loads((tmp_path / "scan_tc24.json").read_text())
    assert doc["info"]["method"] == "tc" and doc["info"]["fit"] == "monge"
    assert len(curvature.read(tmp_path / "bowl.ply").faces) == 3200


# -- the pages against the code ------------------------------------------------------------


@pytest.mark.parametrize("doc", DOCS)
def test_every_block_is_run_or_marked(doc):
    """Cheap inventory: the counts above, and a reason for every skipped block."""
    page = blocks(doc)
    kinds = [classify(b) for b in page]
    counts = (kinds.count("run") + kinds.count("fails"), kinds.count("skip"),
              kinds.count("output"))
    assert counts == EXPECTED[doc], [(b.where, k) for b, k in zip(page, kinds, strict=True)]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    return {slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, flags=re.M)}


@pytest.mark.parametrize("doc", DOCS)
def test_links_resolve(doc):
    path = REPO / doc
    text = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert links
    for link in links:
        if re.match(r"[a-z]+:", link):
            continue
        target, _, anchor = link.partition("#")
        file = (path.parent / target).resolve() if target else path
        assert file.exists(), f"{doc}: link {link!r}: no such file"
        if anchor:
            assert anchor in anchors(file), f"{doc}: link {link!r}: no such heading"


@pytest.mark.parametrize("doc", DOCS)
def test_settings_named_exist(doc):
    from service.settings import Settings

    named = set(re.findall(r"CURVATURE_[A-Z][A-Z0-9_]*", (REPO / doc).read_text()))
    unknown = {v for v in named - CLIENT_VARIABLES
               if v.removeprefix("CURVATURE_").lower() not in Settings.model_fields}
    assert not unknown, f"{doc} names settings the service does not have: {sorted(unknown)}"


def test_endpoints_and_problem_types_exist():
    from service.problem_types import PROBLEM_TYPES

    text = (REPO / "README.md").read_text()
    spec = json.loads((REPO / "openapi" / "openapi.json").read_text())["paths"]
    endpoints = re.findall(r"\b(GET|POST|DELETE|PUT|PATCH) (/[\w/{}.-]*)", text)
    assert len(endpoints) >= 10
    for verb, path in endpoints:
        assert verb.lower() in spec.get(path, {}), f"README: {verb} {path} is not in the API"
    for slug_ in re.findall(r"/problems/([a-z][a-z-]*)", text):
        assert slug_ in PROBLEM_TYPES, f"README: no problem type {slug_!r}"
    assert DOCS_KEY in text


# -- the method table against the reports ---------------------------------------------------


def method_table() -> list[tuple[str, str]]:
    """(method cell, evidence cell) of each row of the README's 'Which method when' table."""
    text = (REPO / "README.md").read_text()
    section = text.split("## Which method when", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ")]
    cells = [[c.strip() for c in re.split(r"(?<!\\)\|", row)[1:-1]] for row in rows[1:]]
    return [(c[0], c[2]) for c in cells if not set(c[0]) <= {"-"}]


NUMBER = r"(?<![\d.]){}(?![\d])"


def test_method_table_covers_every_choice():
    firsts = " ".join(method for method, _ in method_table())
    for name in ("auto", "knn", "monge", "tc", "egg", "mesh", "nfr"):
        assert f"`{name}" in firsts or f'"{name}"' in firsts, name


@pytest.mark.parametrize("row", range(6))
def test_method_table_numbers_are_in_the_linked_reports(row):
    """Each decimal number of a row's evidence occurs in the report(s) that row links."""
    method, evidence = method_table()[row]
    links = re.findall(r"\]\((docs/[^)#]+)", evidence)
    assert links, f"row {method}: no link to its source"
    sources = "\n".join((REPO / link).read_text() for link in links)
    missing = [n for n in re.findall(r"\d+\.\d+", evidence)
               if not re.search(NUMBER.format(re.escape(n)), sources)]
    if missing and method.startswith("`auto`"):
        report = (REPO / "docs" / "accuracy.md").read_text()
        if "bench accuracy" not in report:
            pytest.skip("docs/accuracy.md has no table of the default estimator yet; "
                        f"not yet backed: {missing}")
    assert not missing, f"row {method}: {missing} not found in {links}"
