"""Star lists solved as ``starnav identify`` does: the way chosen once by the options, sets of
files read and solved in order."""

import pytest

from shared_data import CONTEST
from starnav.api import SolveOptions, solve_stars
from starnav.errors import StarnavError
from starnav.pipeline.star_files import read_star_files, solve_star_files
from starnav.results import SOLVE_KEYS
from starnav.starlist import read_star_csv

CATALOG = CONTEST / "catalog.csv"
MAP1 = CONTEST / "images" / "xingtu01.csv"


def test_known_fov_solves_directly_and_a_search_refuses_what_it_chooses_itself():
    stars = read_star_csv(MAP1)
    result = solve_stars(stars, width=512, fov_deg=12.0, catalog=CATALOG)
    assert result.solution is not None and result.solution.n_matched == 15
    assert result.solution.algorithm == "pyramid"
    for options in ({"algorithm": "triangle"}, {"mag_limit": 5.0}, {"algorithm_options": {"a": 1}}):
        with pytest.raises(StarnavError, match="need fov_deg"):
            solve_stars(stars, width=512, catalog=CATALOG, **options)


def test_files_read_and_solved_in_order(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n")
    files = read_star_files([MAP1, bad])
    assert list(files.lists) == [MAP1] and "no stars" in files.errors[bad]
    with pytest.raises(StarnavError, match="fov_deg"):
        solve_star_files(files, SolveOptions(catalog=CATALOG), width=512)
    done = []
    options = SolveOptions(fov_deg=12.0, catalog=CATALOG)
    results = solve_star_files(files, options, width=512, workers=1, progress=done.append)
    assert [r.path for r in results] == [MAP1, bad] and done == [1]
    good, refused = results
    assert not good.bad_input and refused.bad_input and refused.time_ms is None
    assert "no stars" in refused.error and refused.reason == f"error: {refused.error}"
    line = good.to_dict()
    assert list(line) == ["file", *SOLVE_KEYS] and line["time_ms"] == good.time_ms
    assert refused.to_dict() == {"file": str(bad), "solved": False, "reason": refused.reason}
