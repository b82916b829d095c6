"""The README's examples run as written and print what the README shows: the Python block
(its output block beside it, exactly) and the star-list command (its answer lines)."""

import contextlib
import io
import re
from pathlib import Path

import pytest

from shared_data import CONTEST
from starnav.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_readme_is_short_and_says_how_long_the_tests_take():
    assert len(README.splitlines()) < 200
    assert "python -m pytest" in README and 'pytest -m "not slow"' in README
    assert "(measured by the maintainers" not in README, "fill in the measured test times"


def test_the_python_example_prints_what_the_readme_shows():
    # the block right after the Python one is its output
    ((code, shown),) = re.findall(r"```python\n(.*?)```\s*```\n(.*?)```", README, flags=re.S)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md", "exec"), {})
    assert out.getvalue() == shown


def test_the_star_list_example_gives_the_readme_s_answer(capsys):
    if not CONTEST.exists():
        pytest.skip(f"the contest data are not here: {CONTEST}")
    example = next(b for b in _blocks("") if "starnav identify" in b)
    answer = [line for line in example.splitlines() if line.startswith(("solved:", "     A0"))]
    code = main(
        [
            "identify",
            str(CONTEST / "images" / "xingtu01.csv"),
            "--catalog",
            str(CONTEST / "catalog.csv"),
            "--fov-deg",
            "12",
            "--width",
            "512",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    for line in answer:
        assert line in out.splitlines(), line
