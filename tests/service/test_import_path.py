"""The test session's import path resolves the project's packages to the packages.

Worker processes (forkserver or spawn) start with the importing process's ``sys.path``. A test
module that put a folder holding a same-named file in front (``benchmarks/`` has a
``service.py``) made every worker import that file instead of the ``service`` package: the
pools' processes died at start, over and over, and every job of the session waited for its
time limit (CI ran out of time that way).
"""

from __future__ import annotations

import importlib.machinery
import sys

import pytest
from service_helpers import REPO


@pytest.mark.parametrize("package", ["service", "curvature", "curvature_client"])
def test_a_fresh_import_finds_the_package(package):
    spec = importlib.machinery.PathFinder.find_spec(package, sys.path)
    assert spec is not None and spec.origin is not None
    assert spec.origin == str(REPO / package / "__init__.py"), (
        f"a new process would import {package} from {spec.origin}; sys.path: {sys.path}")


def test_the_check_sees_a_shadowing_file(tmp_path):
    (tmp_path / "service.py").write_text("")
    spec = importlib.machinery.PathFinder.find_spec("service", [str(tmp_path), *sys.path])
    assert spec.origin == str(tmp_path / "service.py")
