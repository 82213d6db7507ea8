"""The Dockerfile builds without a registry and ships compiled kernels (static checks; the
image itself is built and run by .ci/docker.sh)."""

from __future__ import annotations

import re

from service_helpers import REPO

TEXT = (REPO / "Dockerfile").read_text(encoding="utf-8")


def test_no_frontend_line_and_the_base_image_is_an_argument():
    assert not re.search(r"^#\s*syntax\s*=", TEXT, flags=re.M | re.I)  # BuildKit would fetch
    first_instruction = next(line for line in TEXT.splitlines()
                             if line.strip() and not line.startswith("#"))
    assert first_instruction.startswith("ARG BASE_IMAGE=")
    froms = re.findall(r"^FROM (\S+) AS (\w+)$", TEXT, flags=re.M)
    assert froms == [("${BASE_IMAGE}", "build"), ("${BASE_IMAGE}", "runtime")]


def test_kernels_are_compiled_at_build_into_the_cache_the_runtime_reads():
    build, runtime = TEXT.split("AS runtime", 1)
    assert "python -m curvature.warmup" in build
    cache = re.findall(r"NUMBA_CACHE_DIR=(\S+)", build)
    assert cache and re.findall(r"NUMBA_CACHE_DIR=(\S+)", runtime) == cache
    # numba only uses a cache folder it may write to: the service user's.
    assert f"--chown=10001:10001 {cache[0]} {cache[0]}" in runtime
    assert re.search(r"^USER curvature$", runtime, flags=re.M)


def test_the_warm_up_compiles_the_installed_package_not_the_source_copy():
    # python -m imports from the working directory first: run in /src, the warm-up would fill
    # the cache for /src/curvature, which the runtime image does not have (it compiled again)
    build = TEXT.split("AS runtime", 1)[0]
    before = build[:build.index("python -m curvature.warmup")]
    workdirs = re.findall(r"^WORKDIR (\S+)$", before, flags=re.M)
    assert workdirs and workdirs[-1] == "/", workdirs
    after = build[build.index("python -m curvature.warmup"):]
    assert "cache_is_warm()" in after  # the build fails if the stamp was not written
