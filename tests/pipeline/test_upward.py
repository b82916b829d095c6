"""An all-sky camera looking up, with its site and time: the attitude guessed from the zenith
(pipeline.upward: the roll, mirror, focal length and principal point voted and fitted), then
tracked and verified; a camera that does not look up is not guessed into a wrong answer."""

import dataclasses

import astropy.units as u
import numpy as np
import pytest
from astropy.coordinates import AltAz, SkyCoord

from starnav.camera import Equisolid
from starnav.catalog import load_catalog
from starnav.catalog.sky import Site, offline_iers, sky_at
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import detect_image, solve_image
from starnav.pipeline.upward import enu_from_icrs, zenith_guesses
from starnav.simulate.render import RenderSettings, render_frame

SITE = Site(78.148, 16.043, 520.0)  # the Kjell Henriksen Observatory, Svalbard
UTC = "2020-12-11T20:09:33"
# a 185° equisolid lens on a 4:3 sensor, its axis 24 px right of and 16 px below the centre
LENS = dataclasses.replace(
    Equisolid(1024, 768, 360.0 / (2 * np.sin(np.radians(46.25))), image_circle_deg=185.0),
    cx=536.0,
    cy=400.0,
)


def looking(altitude_deg: float, azimuth_deg: float, roll_deg: float, parity: int):
    """``R_cam_from_icrs`` of a camera whose axis points at this altitude and azimuth at the
    site and time (astropy's AltAz to ICRS: independent of the vote's own frame)."""
    frame = AltAz(obstime=UTC, location=SITE.location())
    with offline_iers():
        axis = SkyCoord(alt=altitude_deg * u.deg, az=azimuth_deg * u.deg, frame=frame).icrs
    return attitude_from_radec_roll(axis.ra.deg, axis.dec.deg, roll_deg, parity)


def frame_of(R: np.ndarray) -> np.ndarray:
    sky = load_catalog(None, mag_limit=6.5)
    return render_frame(sky, LENS, R, RenderSettings(seed=5, mag_limit=6.5)).image


@pytest.mark.parametrize("parity", [1, -1])
def test_a_tilted_upward_camera_is_guessed_within_a_degree(parity):
    R = looking(86.5, 40.0, 75.0, parity)  # 3.5° from the zenith
    found = detect_image(frame_of(R), lens="equisolid")
    sky = sky_at(load_catalog(None, mag_limit=6.0), SITE, UTC)
    start = LENS.with_centre(found.circle.cx, found.circle.cy)
    lo, hi = (start.focal_for_radius(found.circle.radius_px, v) for v in (230.0, 140.0))
    order = np.arange(len(found.xy))  # detections come brightest first
    camera, R_guess = next(
        zenith_guesses(found.xy, order, start, (lo, hi), sky, enu_from_icrs(sky, SITE, UTC))
    )
    assert max(attitude_difference_deg(R_guess, R)) < 1.0
    assert np.linalg.det(R_guess) == pytest.approx(parity, abs=1e-9)
    assert abs(camera.focal_px / LENS.focal_px - 1.0) < 0.03


@pytest.mark.parametrize("parity", [1, -1])
def test_an_upward_camera_with_its_site_solves_from_the_guess(parity):
    R = looking(88.0, 200.0, -30.0, parity)
    res = solve_image(frame_of(R), lens="equisolid", site=SITE, utc=UTC, time_budget_s=30.0)
    s = res.solution
    assert s is not None, res.reason
    assert max(attitude_difference_deg(s.R_cam_from_icrs, R)) < 0.1
    assert s.parity == parity
    assert abs(s.camera.cx - LENS.cx) < 2.0 and abs(s.camera.cy - LENS.cy) < 2.0


def test_a_camera_far_from_the_zenith_is_not_guessed_wrong():
    R = looking(45.0, 120.0, 10.0, 1)  # a meteor camera looking 45° up
    res = solve_image(frame_of(R), lens="equisolid", site=SITE, utc=UTC, time_budget_s=20.0)
    if res.solution is not None:  # the scan may find it; the guess must not mislead it
        assert max(attitude_difference_deg(res.solution.R_cam_from_icrs, R)) < 0.1


def test_enu_from_icrs_puts_the_zenith_overhead():
    sky = load_catalog(None, mag_limit=4.0)
    R_enu = enu_from_icrs(sky, SITE, UTC)
    zenith_icrs = looking(90.0, 0.0, 0.0, 1)[2]
    assert np.degrees(np.arccos(min(1.0, (R_enu @ zenith_icrs)[2]))) < 0.01
