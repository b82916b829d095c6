"""The boundaries of the source tree (the layers themselves: import-linter, pyproject.toml):
no function over 100 lines, no private name imported from another module, no import cycle
between modules, no user-facing text naming an issue number; and of the tests: their folders
mirror the packages, and no file fetched from another repository is committed under tests/."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "starnav"
TESTS = ROOT / "tests"
MAX_FUNCTION_LINES = 100
# test folders that are no package: our own data, and the tests over real photographs
TEST_FOLDERS_OF_THEIR_OWN = {"data", "corpus"}
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".fits", ".fit", ".gif"}


def _modules() -> dict[str, ast.Module]:
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = ast.parse(path.read_text(), str(path))
    return out


MODULES = _modules()


def _imports(tree: ast.Module):
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("starnav"):
            yield node


def test_no_function_longer_than_100_lines():
    long = [
        f"{name}.{node.name}: {node.end_lineno - node.lineno + 1} lines"
        for name, tree in MODULES.items()
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]
    assert not long


def test_no_private_name_imported_from_another_module():
    private = [
        f"{name}: from {node.module} import {alias.name}"
        for name, tree in MODULES.items()
        for node in _imports(tree)
        for alias in node.names
        if alias.name.startswith("_") or any(p.startswith("_") for p in node.module.split("."))
    ]
    assert not private


def test_no_import_cycle_between_modules():
    """Every import counts, those inside functions too (they run when called)."""
    graph = {
        name: {node.module for node in _imports(tree) if node.module in MODULES} - {name}
        for name, tree in MODULES.items()
    }
    # a package imports its submodules to re-export them: that edge is not a cycle
    graph = {
        name: {t for t in targets if not t.startswith(name + ".")}
        for name, targets in graph.items()
    }
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join([*path[path.index(nxt) :], nxt]))
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    assert not cycles


def test_no_user_facing_text_names_an_issue_number():
    pattern = re.compile(r"\bissue\s*#?\d+", re.IGNORECASE)
    found = [
        f"{name}: {node.value!r}"
        for name, tree in MODULES.items()
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and pattern.search(node.value)
    ]
    assert not found


def test_test_folders_mirror_the_packages():
    folders = {p.name for p in TESTS.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    packages = {p.parent.name for p in SRC.glob("*/__init__.py")}
    assert folders - TEST_FOLDERS_OF_THEIR_OWN <= packages, "a test folder that is no package"


def test_no_fetched_file_is_committed_under_tests():
    """Images and code from other repositories live in ../shared/data, never in tests/."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the committed files cannot be listed")
    listed = subprocess.run(["git", "ls-files", "tests"], cwd=ROOT, capture_output=True,
                            text=True, check=True).stdout.split()  # fmt: skip
    images = [p for p in listed if any(p.lower().endswith(s) for s in IMAGE_SUFFIXES)]
    assert not images, f"image files committed under tests/: {images}"
    assert not [p for p in listed if p.startswith("tests/vendor/")]
