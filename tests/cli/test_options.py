"""Algorithm options on the command line (``--algorithm-option NAME=VALUE``, with
``--triangle-selection`` short for ``selection=``), and the shape of the ``starnav.cli`` package."""

import ast
import json
from pathlib import Path

import pytest

from cli_helpers import run_cli
from shared_data import CONTEST, ROOT

CATALOG = str(CONTEST / "catalog.csv")
MAP1 = str(CONTEST / "images" / "xingtu01.csv")
IDENTIFY = ["identify", MAP1, "--fov-deg", "12", "--width", "512", "--catalog", CATALOG]
CLI = ROOT / "src" / "starnav" / "cli"


@pytest.mark.parametrize(
    "options",
    [["--algorithm-option", "selection=brightest"], ["--triangle-selection", "brightest"]],
)
def test_an_option_by_name_or_by_its_shorthand(capsys, options):
    code, out, _ = run_cli(capsys, *IDENTIFY, "--algorithm", "triangle", "--json", *options)
    result = json.loads(out)
    assert code == 0 and result["algorithm"] == "triangle" and result["n_matched"] == 15


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--algorithm-option", "selection=brightest"], "pyramid has no option 'selection'"),
        (["--algorithm", "triangle", "--algorithm-option", "size=3"], "no option 'size'"),
        (
            ["--algorithm", "triangle", "--algorithm-option", "selection=dimmest"],
            "must be one of optimized, brightest, got 'dimmest'",
        ),
        (["--algorithm-option", "selection"], "expected NAME=VALUE"),
        (["--algorithm-option", "=3"], "expected NAME=VALUE"),
    ],
)
def test_a_bad_option_is_one_line_naming_it(capsys, argv, needle):
    code, out, err = run_cli(capsys, *IDENTIFY, *argv)
    assert code == 2 and out == "" and needle in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_options_need_a_known_fov_and_evaluate_checks_them_too(capsys):
    code, _, err = run_cli(
        capsys, "identify", MAP1, "--width", "512", "--algorithm-option", "selection=brightest"
    )
    assert code == 2 and "--algorithm-option needs --fov-deg" in err
    code, _, err = run_cli(capsys, "evaluate", "--workers", "1", "--algorithm-option", "x=1")
    assert code == 2 and "pyramid has no option 'x'" in err and "\n" not in err.strip()


def _functions(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield node


@pytest.mark.parametrize("path", sorted(CLI.glob("*.py")), ids=lambda p: p.name)
def test_cli_modules_are_small_and_import_no_private_names(path):
    long = [f"{f.name}: {f.end_lineno - f.lineno + 1}" for f in _functions(path)]
    assert all(f.end_lineno - f.lineno < 100 for f in _functions(path)), long
    assert len(path.read_text().splitlines()) < 250
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            assert not [a.name for a in node.names if a.name.startswith("_")], node.module
    modules = {p.stem for p in CLI.glob("*.py")} - {
        "__init__",
        "__main__",
        "common",
        "field",
        "output",
        "parser",
        "plain",
        "site",
    }
    assert all((CLI / f"{m}.py").read_text().count("def add_parser(") == 1 for m in modules)
