import numpy as np
import pytest

import starnav
from shared_data import CONTEST
from starnav import StarListError, StarnavError
from starnav.results import SOLVE_KEYS


def test_solution_fields(contest_catalog):
    xy = np.loadtxt(CONTEST / "images" / "xingtu02.csv", delimiter=",", skiprows=1, usecols=(1, 2))
    s = starnav.solve(xy, width=512, height=512, fov_deg=12.0, catalog=contest_catalog)
    assert isinstance(s, starnav.Solution)
    R = s.R_cam_from_icrs
    assert R.shape == (3, 3) and np.allclose(R @ R.T, np.eye(3))
    assert np.isclose(np.linalg.det(R), s.parity)
    d = s.to_dict()
    assert d["solved"] and len(d["stars"]) == len(xy) and d["n_matched"] == s.n_matched
    assert s.sigma_boresight_arcsec > 0 and s.sigma_roll_arcsec > s.sigma_boresight_arcsec


def test_solved_and_unsolved_json_have_the_same_keys(contest_catalog):
    xy = np.loadtxt(CONTEST / "images" / "xingtu02.csv", delimiter=",", skiprows=1, usecols=(1, 2))
    solved = starnav.solve_stars(xy, width=512, fov_deg=12.0, catalog=contest_catalog)
    d = solved.to_dict()
    assert tuple(d) == SOLVE_KEYS and d["solved"] and d["reason"] is None
    assert d["time_ms"] == solved.solution.time_ms and len(d["stars"]) == len(xy)
    random_xy = np.random.default_rng(8).uniform(0, 512, (10, 2))
    unsolved = starnav.solve_stars(random_xy, width=512, fov_deg=12.0, catalog=contest_catalog)
    u = unsolved.to_dict(["p"] * 10, random_xy)
    assert tuple(u) == SOLVE_KEYS and u["solved"] is False and u["reason"] == unsolved.reason
    assert u["ra_deg"] is None and u["n_matched"] == 0 and u["time_ms"] == unsolved.time_ms
    assert [m["label"] for m in u["stars"]] == ["p"] * 10 and u["stars"][3]["x"] == random_xy[3, 0]
    assert [m["label"] for m in unsolved.to_dict(None, random_xy)["stars"]][:2] == ["1", "2"]


def test_returns_none_when_unsure(contest_catalog):
    """Random points (enough of them for hypotheses to be tested) get no answer."""
    rng = np.random.default_rng(8)
    for _ in range(5):
        xy = rng.uniform(0, 512, (10, 2))
        assert starnav.solve(xy, width=512, fov_deg=12.0, catalog=contest_catalog) is None
        result = starnav.solve_stars(xy, width=512, fov_deg=12.0, catalog=contest_catalog)
        assert result.solution is None and result.reason and result.hypotheses > 0


@pytest.mark.parametrize(
    "xy,kwargs,needle",
    [
        ([[1, 2], [3, 4]], {}, "at least 3 stars to identify, got 2"),
        ([[1, 2], [3, np.nan], [5, 6]], {}, "star 2 has a NaN"),
        ([[1, 2, 3], [3, 4, 5], [5, 6, 7]], {}, "shape (n, 2), got (3, 3)"),
        ([[1, 2], [3, 4], [900, 6]], {}, "star 3 at (900, 6) px is far outside"),
        ([[1, 2], [3, 4], [1, 2]], {}, "duplicate star position (1, 2)"),
        ([[1, 2], [3, 4], [5, 6]], {"brightness": [1.0, 2.0]}, "2 brightness values for 3"),
        ([[1, 2], [3, 4], [5, 6]], {"sigma_px": -1.0}, "sigma_px must be"),
        ([[1, 2], [3, 4], [5, 6]], {"parity": 2}, "parity must be"),
        ([[1, 2], [3, 4], [5, 6]], {"algorithm": "magic"}, "unknown algorithm 'magic'"),
        ([[1, 2], [3, 4], [5, 6]], {"fov_deg": 0.0}, "fov_deg must be"),
    ],
)
def test_bad_input_raises_named_error(contest_catalog, xy, kwargs, needle):
    args = {"width": 512, "fov_deg": 12.0, "catalog": contest_catalog, **kwargs}
    with pytest.raises(StarnavError) as err:
        starnav.solve(xy, **args)
    assert isinstance(err.value, ValueError)
    assert needle in str(err.value)


def test_star_list_error_is_specific():
    with pytest.raises(StarListError):
        starnav.solve([[1.0, 2.0]], width=512, fov_deg=12.0)
