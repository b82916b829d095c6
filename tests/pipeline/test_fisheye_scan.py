"""A circular fisheye solved from its image circle: the circle found, the principal point
started at its centre and fitted, the common models tried when the lens is not named, and an
image with nothing said recognised as a fisheye's (pipeline.fov.scan_starts, scan_focal)."""

import dataclasses

import numpy as np
import pytest

from starnav.camera import Equisolid
from starnav.catalog import load_catalog
from starnav.detect.circle import dark_corners, find_image_circle
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.fov import ScanStart
from starnav.pipeline.image import solve_image
from starnav.simulate.render import RenderSettings, render_frame

# a 180° equisolid lens on a 4:3 sensor, its axis 24 px right of and 16 px below the centre
TRUE = dataclasses.replace(
    Equisolid(1024, 768, 360.0 / (2 * np.sin(np.radians(45))), image_circle_deg=180.0),
    cx=536.0,
    cy=400.0,
)


@pytest.fixture(scope="module")
def frame():
    sky = load_catalog(None, mag_limit=6.5)
    R = attitude_from_radec_roll(120.0, 35.0, 20.0, 1)
    settings = RenderSettings(seed=11, vignetting_power=2.0, mag_limit=6.5)
    return render_frame(sky, TRUE, R, settings).image, R


def test_the_image_circle_is_sharp_and_the_corners_dark(frame):
    image, _ = frame
    circle = find_image_circle(image)
    assert abs(circle.cx - TRUE.cx) < 6 and abs(circle.cy - TRUE.cy) < 6
    assert abs(circle.radius_px - 360.0) < 12
    assert circle.contrast > 0.8 and dark_corners(image)


def test_vignetting_is_not_an_image_circle():
    y, x = np.mgrid[0:600, 0:800] + 0.5
    r2 = ((x - 400) ** 2 + (y - 300) ** 2) / 500.0**2
    image = 1000.0 * np.exp(-1.5 * r2) + np.random.default_rng(2).normal(0, 3, r2.shape)
    circle = find_image_circle(image)
    assert circle is None  # its edge is too soft for a lens's (LENS_EDGE_CONTRAST)


def test_trial_focal_lengths_start_at_the_first_and_go_outward():
    start = ScanStart(TRUE, (200.0, 300.0), 240.0)
    focals = start.focals(0.02)
    assert focals[0] == 240.0 and min(focals) <= 200.0 * 1.02 and max(focals) >= 300.0 / 1.02
    distance = np.abs(np.log(np.array(focals) / 240.0))
    assert np.all(np.diff(distance) >= -1e-12)


@pytest.mark.slow
# None: nothing said, the image taken for a fisheye's from its circle, then exactly the scan
# of ``lens="fisheye"`` (each common model), which is therefore not run a second time here
# (104 s on a 2-core machine)
@pytest.mark.parametrize("lens", ["equisolid", None])
def test_a_fisheye_solves_from_its_circle_with_the_lens_named_or_not(frame, lens):
    image, R = frame
    res = solve_image(image, **({} if lens is None else {"lens": lens}), time_budget_s=300.0)
    s = res.solution
    assert s is not None, res.reason
    assert s.camera_model == "equisolid"
    assert max(attitude_difference_deg(s.R_cam_from_icrs, R)) < 0.1
    assert abs(s.camera.cx - TRUE.cx) < 2.0 and abs(s.camera.cy - TRUE.cy) < 2.0
    assert abs(s.focal_px / TRUE.focal_px - 1) < 0.005


def test_sky_between_trees_is_not_an_image_circle():
    # a bright region whose edge wanders 25 % in and out of its circle (a photograph's sky
    # between dark tree crowns), dark at every corner: its edge is not a lens's circle
    y, x = np.mgrid[0:600, 0:800] + 0.5
    radius = np.hypot(x - 400, y - 300)
    wobble = 250.0 * (1.0 + 0.25 * np.sin(7.0 * np.arctan2(y - 300, x - 400)))
    image = np.where(radius < wobble, 1000.0, 20.0) + np.random.default_rng(3).normal(0, 3, x.shape)
    assert dark_corners(image)
    assert find_image_circle(image) is None
