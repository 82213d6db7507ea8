"""The layers of ``curvature/`` (docs/architecture.md), checked on the import graph.

The graph comes from the sources (ast), not from importing them: every ``import`` and
``from ... import`` at any depth (lazy imports in functions included) and every
``import_module("...")`` with a literal name, resolved to the deepest module of the package it
names. Importing ``a.b.c`` also runs ``a/__init__`` and ``a/b/__init__``; those implicit edges
are not counted, as every module would otherwise depend on the package's public ``__init__``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import curvature

PACKAGE = Path(curvature.__file__).resolve().parent
ARCHITECTURE_DOC = PACKAGE.parent / "docs" / "architecture.md"

#: Layer -> the modules and packages in it, relative to the package ("" is its ``__init__``).
LAYERS = {
    "base": ("errors", "status", "params", "validation", "cloud", "result", "field_info",
             "progress", "memory"),
    "kernels": ("neighborhoods", "fitting", "orientation", "uncertainty", "bounds"),
    "estimators": ("estimators",),
    "pipeline": ("pipeline",),
    "files": ("io", "preview"),
    "checking": ("synthetic", "evaluation"),
    "interface": ("", "__main__", "cli", "warmup"),
    "studies": ("studies",),
}
#: Layer -> the layers its modules may import (their own included).
ALLOWED = {
    "base": {"base"},
    "kernels": {"base", "kernels"},
    "estimators": {"base", "kernels", "estimators"},
    "pipeline": {"base", "kernels", "estimators", "pipeline"},
    "files": {"base", "files"},
    "checking": {"base", "files", "checking"},
    "interface": set(LAYERS) - {"studies"},
    "studies": set(LAYERS),
}
STUDIES = "studies"


def module_names(root: Path) -> dict[str, Path]:
    """Every module below the package folder ``root``: dotted name -> file."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = [root.name, *path.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


def _resolve(name: str, known) -> str | None:
    """The deepest known module that ``name`` (a module or a name in one) lies in."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(name: str, path: Path, known) -> set[str]:
    """The known modules that module ``name`` (file ``path``) imports."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            # ``from pkg import sub`` imports the module pkg.sub, ``from pkg import name`` pkg
            targets.update(f"{module}.{alias.name}" if f"{module}.{alias.name}" in known
                           else module for alias in node.names)
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) == "import_module"
                   or getattr(node.func, "id", None) == "import_module")):
            targets.add(node.args[0].value)
    resolved = {_resolve(t, known) for t in targets}
    return {t for t in resolved if t is not None and t != name}


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the modules of the same package it imports."""
    known = module_names(root)
    return {name: imports_of(name, path, known) for name, path in known.items()}


def layer_of(module: str) -> str | None:
    """The layer of a dotted module name (longest listed prefix wins), or None."""
    rel = module.partition(".")[2]
    best, layer = -1, None
    for name, members in LAYERS.items():
        for member in members:
            inside = rel == member or (member != "" and rel.startswith(member + "."))
            if inside and len(member) > best:
                best, layer = len(member), name
    return layer


def layer_violations(graph) -> list[tuple[str, str]]:
    """Imports ``(importer, imported)`` that the importer's layer may not make."""
    return sorted((a, b) for a, targets in graph.items() for b in targets
                  if layer_of(b) not in ALLOWED[layer_of(a)])


def study_imports(graph) -> list[tuple[str, str]]:
    """Imports of a study module by a module outside the studies."""
    return sorted((a, b) for a, targets in graph.items() for b in targets
                  if layer_of(b) == STUDIES and layer_of(a) != STUDIES)


def cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


@pytest.fixture(scope="module")
def graph():
    return import_graph()


def test_every_module_has_a_layer(graph):
    assert len(graph) > 60
    assert [m for m in graph if layer_of(m) is None] == []


def test_no_import_cycle(graph):
    assert cycles(graph) == []


def test_the_library_imports_nothing_from_the_studies(graph):
    assert study_imports(graph) == []


def test_each_layer_imports_only_what_its_rule_allows(graph):
    assert layer_violations(graph) == []


def test_the_layers_are_the_ones_the_document_describes():
    rows = re.findall(r"^\| `(\w+)` \| (.+?) \| (.+?) \|$", ARCHITECTURE_DOC.read_text(), re.M)
    documented = {layer: (tuple(m.strip("/") for m in re.findall(r"`([^`]+)`", members)),
                          {w.strip() for w in allowed.split(",")})
                  for layer, members, allowed in rows}
    assert {layer: tuple("" if m == "__init__" else m for m in mods)
            for layer, (mods, _) in documented.items()} == LAYERS

    def in_words(ok):
        return ({"every layer"} if ok == set(LAYERS)
                else {"every layer but studies"} if ok == set(LAYERS) - {STUDIES} else ok)

    assert {layer: allow for layer, (_, allow) in documented.items()} == \
        {layer: in_words(ok) for layer, ok in ALLOWED.items()}


# --- the checker itself ---------------------------------------------------------------------


def plant(root: Path, files: dict[str, str]) -> Path:
    """A package ``curvature`` under ``root`` with the given files (relative path -> source)."""
    pkg = root / "curvature"
    for rel, source in files.items():
        path = pkg / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(source)
    return pkg


def test_checker_catches_a_core_module_importing_a_study(tmp_path):
    pkg = plant(tmp_path, {
        "__init__.py": "",
        "errors.py": "",
        "pipeline/__init__.py": "from .block import run\n",
        # a lazy relative import, in a function, of a module that only a study may import
        "pipeline/block.py": "def run():\n    from ..studies import paper\n    return paper\n",
        "studies/__init__.py": "",
        "studies/paper.py": "from ..errors import *\n",
    })
    graph = import_graph(pkg)
    assert graph["curvature.pipeline.block"] == {"curvature.studies.paper"}
    assert study_imports(graph) == [("curvature.pipeline.block", "curvature.studies.paper")]
    assert layer_violations(graph) == [("curvature.pipeline.block", "curvature.studies.paper")]
    assert cycles(graph) == []


def test_checker_catches_absolute_and_dynamic_study_imports(tmp_path):
    pkg = plant(tmp_path, {
        "__init__.py": "",
        "cli.py": "import importlib\nimportlib.import_module('curvature.studies.cli')\n",
        "io/__init__.py": "import curvature.studies.peers.apss as apss\n",
        "studies/__init__.py": "",
        "studies/cli.py": "",
        "studies/peers/__init__.py": "",
        "studies/peers/apss.py": "",
    })
    assert study_imports(import_graph(pkg)) == [
        ("curvature.cli", "curvature.studies.cli"),
        ("curvature.io", "curvature.studies.peers.apss")]


def test_checker_catches_cycles_and_a_lower_layer_importing_a_higher_one(tmp_path):
    pkg = plant(tmp_path, {
        "__init__.py": "",
        "errors.py": "from .result import R\n",          # base -> base: allowed, but a cycle
        "result.py": "from . import errors\nR = 1\n",
        "synthetic/__init__.py": "from .base import S\n",  # package -> module -> package
        "synthetic/base.py": "from . import S\n",
        "fitting/__init__.py": "from ..pipeline import estimate\n",  # kernels -> pipeline
        "pipeline/__init__.py": "def estimate():\n    pass\n",
    })
    graph = import_graph(pkg)
    assert cycles(graph) == [["curvature.errors", "curvature.result"],
                             ["curvature.synthetic", "curvature.synthetic.base"]]
    assert layer_violations(graph) == [("curvature.fitting", "curvature.pipeline")]


def test_a_planted_edge_in_the_real_graph_is_caught(graph):
    planted = {m: set(t) for m, t in graph.items()}
    planted["curvature.pipeline.block"].add("curvature.studies.paper")
    planted["curvature.errors"].add("curvature.pipeline")  # pipeline imports errors: a cycle
    assert study_imports(planted) == [("curvature.pipeline.block", "curvature.studies.paper")]
    assert ("curvature.errors", "curvature.pipeline") in layer_violations(planted)
    assert any({"curvature.errors", "curvature.pipeline"} <= set(c) for c in cycles(planted))
