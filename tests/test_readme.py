"""The README's examples run as written and print what the README shows: the Python block
(its output block beside it, exactly) and the star-list command (its answer lines)."""

import contextlib
import io
import re
from pathlib import Path

import pytest

from shared_data import CONTEST, SHARED
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


@pytest.mark.corpus
def test_the_photo_example_gives_the_readme_s_answer(capsys):
    """The README's photograph: its answer line, its star-count line and its first star rows
    (the time line is the machine's)."""
    photo = SHARED / "real" / "granasat_pleyades_05sec.jpg"
    if not photo.exists():
        pytest.skip(f"the photograph is not here: {photo}")
    example = next(b for b in _blocks("") if "starnav solve ../shared" in b)
    answer = [line for line in example.splitlines()[1:] if line[:9].strip().isdigit()]
    answer += [line for line in example.splitlines() if line.startswith(("solved:", "  26/50"))]
    assert len(answer) == 6
    code = main(["solve", str(photo)])
    out = capsys.readouterr().out
    assert code == 0
    for line in answer:
        assert line in out.splitlines(), line


def test_the_python_page_s_first_example_prints_the_line_it_shows():
    """docs/python.md's SolveOptions example: the one-line SolveResult it quotes in its
    comment (the time aside, which is the machine's, and the catalog's epoch, this year)."""
    page = (ROOT / "docs" / "python.md").read_text()
    code = re.findall(r"```python\n(.*?)```", page, flags=re.S)[0]
    quoted = " ".join(
        line.lstrip("# ").strip()
        for line in code.splitlines()
        if line.startswith(("# SolveResult", "#   "))
    )
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/python.md", "exec"), {})
    printed = out.getvalue().splitlines()[0]

    def machine_free(line: str) -> str:
        line = re.sub(r"\), [0-9.]+ ms, ", "), ms, ", line)
        return re.sub(r"epoch [0-9]{4}", "epoch YYYY", line)

    assert machine_free(printed) == machine_free(quoted)


def test_the_star_tracker_example_names_its_faint_stars(capsys, tmp_path, monkeypatch):
    """The README's 6° tracker, as written: every star of the list named, to Hp 10.3."""
    (block,) = [b for b in _blocks("") if "tracker.csv" in b]
    monkeypatch.chdir(tmp_path)
    codes = [main(line.split()[1:]) for line in block.strip().splitlines()]
    out = capsys.readouterr().out
    assert codes == [0, 0], out
    solved = next(line for line in out.splitlines() if "stars matched" in line)
    matched, total = map(int, solved.split()[0].split("/"))
    assert matched == total > 40, solved
    assert "match_probability" in out
