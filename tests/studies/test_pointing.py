"""The three-star pointing study: figures written, ranking, analytic against Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from starnav.camera import Camera
from starnav.geometry import ARCSEC_PER_RAD, attitude_from_radec_roll
from starnav.studies.pointing import (
    ATTITUDE_RADEC_ROLL_DEG,
    analytic_sigma_arcsec,
    classic_arrangements,
    equilateral,
    geometric_factor,
    monte_carlo_rms_arcsec,
    run_study,
)

EDGE = "equilateral at the field edge (R 0.45 W, centred)"
SMALL = "small equilateral at the centre (R 0.08 W)"
NEARLY_COLLINEAR = "nearly collinear (3 px off a line)"


@pytest.fixture(scope="module")
def camera():
    return Camera.from_fov(12.0, 512)


@pytest.fixture(scope="module")
def R():
    return attitude_from_radec_roll(*ATTITUDE_RADEC_ROLL_DEG)


def test_study_writes_figures_and_ranks_arrangements(tmp_path):
    result = run_study(trials=200, out_dir=tmp_path, progress=False, n_random=200, placement_grid=9)
    names = {"pointing_arrangements.png", "pointing_placement_map.png", "pointing_volume.png"}
    assert {p.name for p in result.figures} == names
    for p in result.figures:
        assert p.parent == tmp_path and p.stat().st_size > 10_000
    edge = result.row(EDGE).analytic_arcsec
    assert edge < result.row(SMALL).analytic_arcsec
    assert 10 * edge < result.row(NEARLY_COLLINEAR).analytic_arcsec
    assert result.row("exactly collinear").rejected
    assert result.best.name == EDGE
    assert result.worst.name == NEARLY_COLLINEAR
    assert result.volume_slope < 0


def test_monte_carlo_agrees_with_analytic_edge_equilateral(camera, R):
    xy = classic_arrangements(512)[EDGE]
    analytic = analytic_sigma_arcsec(xy, camera, R, 0.5)
    mc = monte_carlo_rms_arcsec(xy, camera, R, 0.5, 20_000, np.random.default_rng(1))
    assert mc == pytest.approx(analytic, rel=0.10)


def test_closed_form_matches_covariance(camera, R):
    rng = np.random.default_rng(3)
    per_sigma_f = 0.5 / camera.focal_px * ARCSEC_PER_RAD
    for _ in range(50):
        xy = rng.uniform(0, 512, (3, 2))
        expected = analytic_sigma_arcsec(xy, camera, R, 0.5)
        assert geometric_factor(xy, camera) * per_sigma_f == pytest.approx(expected, rel=1e-9)
    # small centred equilateral: the floor sqrt(4/3), whatever the size
    for radius in (5.0, 50.0):
        g = geometric_factor(equilateral(256, 256, radius), camera)
        assert g == pytest.approx(np.sqrt(4 / 3), rel=1e-3)


def test_result_does_not_depend_on_attitude(camera, R):
    xy = classic_arrangements(512)["right triangle, legs 0.8 W, centre inside"]
    other = attitude_from_radec_roll(250.0, -75.0, 123.0)
    assert analytic_sigma_arcsec(xy, camera, other, 0.5) == pytest.approx(
        analytic_sigma_arcsec(xy, camera, R, 0.5), rel=1e-6
    )
