"""The core stays free of web code, and reaches ``curvature remote`` only through the generic
``curvature.cli`` entry-point hook."""

from __future__ import annotations

import ast
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path

import pytest

import curvature.cli
from curvature.cli import PLUGIN_GROUP, main

CORE = Path(curvature.cli.__file__).resolve().parent
FORBIDDEN = {"httpx", "fastapi", "starlette", "pydantic", "pydantic_settings", "uvicorn",
             "multipart", "service", "curvature_client"}


def imported_roots(tree: ast.AST) -> set[str]:
    """Top-level names of every absolute import in a module, at any depth (lazy imports and
    ``importlib.import_module("...")`` calls with a literal name included)."""
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) == "import_module"
                   or getattr(node.func, "id", None) in ("import_module", "__import__"))):
            roots.add(node.args[0].value.split(".")[0])
    return roots


def test_scanner_sees_lazy_and_dynamic_imports():
    source = ("def f():\n    import httpx.x\n    from fastapi import A\n"
              "    importlib.import_module('uvicorn.main')\n    __import__('pydantic')\n"
              "from . import io\n")
    assert imported_roots(ast.parse(source)) == {"httpx", "fastapi", "uvicorn", "pydantic"}


def test_core_imports_no_web_package():
    modules = sorted(CORE.rglob("*.py"))
    assert len(modules) > 20
    offenders = {}
    for path in modules:
        bad = imported_roots(ast.parse(path.read_text(), filename=str(path))) & FORBIDDEN
        if bad:
            offenders[str(path.relative_to(CORE.parent))] = sorted(bad)
    assert offenders == {}


def test_remote_is_registered_through_the_entry_point_group():
    names = {ep.name: ep.value for ep in entry_points(group=PLUGIN_GROUP)}
    assert names.get("remote") == "curvature_client.cli:register"


def test_remote_help_lists_its_commands(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["remote", "-h"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    for command in ("submit", "status", "wait", "result", "preview", "cancel", "list"):
        assert command in out


class FakeEntryPoints:
    def __init__(self, *eps):
        self.eps = eps

    def __call__(self, group):
        assert group == PLUGIN_GROUP
        return self.eps


def hello_register(subparsers):
    parser = subparsers.add_parser("hello", help="say hello")
    parser.add_argument("--name", default="world")
    parser.set_defaults(handler=lambda args: print(f"hello {args.name}") or 0)


def test_a_plugin_adds_a_command(monkeypatch, capsys):
    ep = EntryPoint("hello", f"{__name__}:hello_register", PLUGIN_GROUP)
    monkeypatch.setattr(curvature.cli, "entry_points", FakeEntryPoints(ep))
    assert main(["hello", "--name", "scan"]) == 0
    assert capsys.readouterr().out == "hello scan\n"


def test_a_broken_plugin_explains_itself_and_breaks_nothing(monkeypatch, capsys, tmp_path):
    ep = EntryPoint("broken", "no_such_module_for_curvature:register", PLUGIN_GROUP)
    monkeypatch.setattr(curvature.cli, "entry_points", FakeEntryPoints(ep))
    assert main(["broken", "anything", "--at-all"]) == 2
    err = capsys.readouterr().err
    assert "curvature broken: unavailable" in err and "no_such_module_for_curvature" in err
    assert main(["info", str(tmp_path / "missing.ply")]) == 2  # other commands still parse
    assert "missing.ply" in capsys.readouterr().err
