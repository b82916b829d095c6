"""Why an image was not solved: the failure classes of ``starnav.pipeline.diagnose``, named on
images made to fail each way and in the JSON of ``starnav solve``."""

import json

import numpy as np
import pytest

from starnav.cli import main
from starnav.detect.stars import Detections
from starnav.pipeline.diagnose import (
    BUDGET,
    DISTORTED,
    FEW_STARS,
    OUTSIDE,
    TRAILED,
    diagnose,
)
from starnav.pipeline.image import solve_image
from starnav.simulate.render import RenderSettings, render_stars, write_image

SIZE = 512


def _field(n: int, seed: int, trail_px: float = 0.0) -> np.ndarray:
    """A 512 px frame of n stars at random places (no sky's: it cannot be identified), each
    trailed ``trail_px`` along x when given."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(30, SIZE - 30, (n, 2))
    flux = np.exp(rng.uniform(np.log(5e3), np.log(5e4), n))
    if not trail_px:
        return render_stars(xy, flux, SIZE, SIZE, RenderSettings(), rng)
    steps = np.linspace(-trail_px / 2, trail_px / 2, 15)
    xy_t = np.vstack([xy + np.array([dx, 0.0]) for dx in steps])
    return render_stars(xy_t, np.tile(flux / len(steps), len(steps)), SIZE, SIZE,
                        RenderSettings(), rng)  # fmt: skip


def test_few_stars():
    result = solve_image(_field(5, 1), time_budget_s=1.0)
    assert result.solution is None and result.failure == FEW_STARS
    assert result.reason.startswith("too few stars: ")
    assert "only 5 stars above 5 sigma" in result.reason
    assert "--threshold-sigma 4" in result.reason


def test_trailed_stars():
    result = solve_image(_field(40, 2, trail_px=14.0), time_budget_s=1.0)
    assert result.detections.elongation >= 2.0
    assert result.solution is None and result.failure == TRAILED
    assert "longer than wide" in result.reason


def test_no_match_in_the_range_names_the_range():
    result = solve_image(_field(40, 3), fov_range_deg=(10.0, 20.0), time_budget_s=2.0)
    assert result.detections.elongation < 1.5
    assert result.solution is None and result.failure in (OUTSIDE, BUDGET)
    if result.failure == OUTSIDE:
        assert "in 10-20°" in result.reason and "--fov-range" in result.reason


@pytest.mark.parametrize(
    ("reason", "kind"),
    [
        ("only 10 of 22 stars agree with the best attitude (need 50%)", DISTORTED),
        ("time budget spent (10 s): 3553 hypotheses, 3312 verified", BUDGET),
        ("no hypothesis agreed with enough stars to be convincing", OUTSIDE),
        ("best hypothesis not convincing (false-match probability 0.059 > 0.0001)", FEW_STARS),
    ],
)
def test_the_solve_reason_picks_the_class(reason, kind):
    found = Detections(np.zeros((30, 2)), *(np.zeros(30),) * 3, np.zeros(30, bool),
                       0.0, 1.0, 1.0, 0, 0, 100, 100)  # fmt: skip
    failure = diagnose(found, reason, fov_range_deg=(5.0, 40.0), threshold_sigma=5.0,
                       lens="pinhole")  # fmt: skip
    assert failure.kind == kind
    assert failure.explain(reason) == f"{kind}: {reason}; {failure.advice}"


def test_cli_json_names_the_failure(tmp_path, capsys):
    path = tmp_path / "few.png"
    write_image(path, _field(5, 1))
    assert main(["solve", str(path), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] is False and out["failure"] == FEW_STARS
    assert main(["solve", str(path)]) == 1
    assert "too few stars" in capsys.readouterr().out
