"""An all-sky frame whose lens's rim is hidden: a light-polluted sky inside trees, the rest
clipped to black with a caption burnt in (the Maryland All Sky Network's frames). No image
circle is seen, so the sky mask takes the flat black and its caption away
(``detect.skymask``), the sky left suggests a disc (``SkyMask.lit_disc``) and the focal scan
starts from a 180° circle as wide as the shorter side (``pipeline.fov.scan_starts``)."""

import dataclasses

import numpy as np
import pytest

from starnav.camera import Equidistant
from starnav.catalog import load_catalog
from starnav.detect.circle import find_image_circle
from starnav.detect.skymask import find_sky_mask
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import detect_image, solve_image
from starnav.simulate.render import RenderSettings, render_frame

WIDTH, HEIGHT = 1024, 768
HORIZON_PX = 0.51 * HEIGHT  # the 180° circle overflows the shorter side a little
# the optical axis 4 px left of and 20 px below the image centre
TRUE = dataclasses.replace(
    Equidistant(WIDTH, HEIGHT, HORIZON_PX / (np.pi / 2)), cx=WIDTH / 2 - 4.0, cy=HEIGHT / 2 + 20.0
)
CAPTION = (slice(10, 70), slice(10, 330))  # rows, columns


@pytest.fixture(scope="module")
def frame():
    sky = load_catalog(None, mag_limit=6.0)
    R = attitude_from_radec_roll(60.0, 38.0, 75.0, 1)  # an upward camera at 38° N
    settings = RenderSettings(psf_sigma_px=0.9, background_e=3000.0, exposure_s=1.0,
                              zero_point_e_per_s=4e5, mag_limit=6.0, seed=8,
                              vignetting_power=0.0)  # fmt: skip
    image = render_frame(sky, TRUE, R, settings).image.astype(np.float32)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    r = np.hypot(x - TRUE.cx, y - TRUE.cy)
    phi = np.arctan2(y - TRUE.cy, x - TRUE.cx)
    # tree crowns all round, 12-30° high: the sky seen ends well short of the horizon
    edge = HORIZON_PX * (0.74 + 0.06 * np.sin(7 * phi) + 0.04 * np.sin(17 * phi + 1.0))
    lit = r < edge
    # an 8-bit picture: the sky at ~60, everything outside it clipped to black
    level = float(np.median(image[r < 0.5 * HORIZON_PX]))
    image = np.clip((image - level) * 0.5 + 60.0, 0.0, 255.0)
    image[~lit] = 0.0
    # a caption: three lines of saturated glyphs in the black corner, and hot pixels there
    rng = np.random.default_rng(4)
    for row in range(3):
        for column in range(24):
            if rng.random() < 0.8:
                y0, x0 = CAPTION[0].start + 20 * row, CAPTION[1].start + 13 * column
                image[y0 : y0 + 9, x0 : x0 + 6] = 255.0
    hot = rng.integers(0, [HEIGHT, WIDTH], size=(60, 2))
    image[hot[:, 0], hot[:, 1]] = np.where(lit[hot[:, 0], hot[:, 1]], image[hot[:, 0], hot[:, 1]],
                                           200.0)  # fmt: skip
    return np.round(image), R, lit


def test_the_black_and_its_caption_are_masked_and_the_sky_kept(frame):
    image, _, lit = frame
    assert find_image_circle(image) is None  # no lens's edge: the trees hide it
    mask = find_sky_mask(image)
    assert mask.excluded[CAPTION].all()
    assert mask.excluded[~lit].mean() > 0.97
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    inner = np.hypot(x - TRUE.cx, y - TRUE.cy) < 0.5 * HORIZON_PX  # the trees reach 0.6
    assert not mask.excluded[inner].any()
    assert (~mask.excluded[lit]).mean() > 0.75  # the edge's blocks go with the black
    disc = mask.lit_disc()
    assert disc is not None and disc.contrast == 0.0
    assert np.hypot(disc.cx - TRUE.cx, disc.cy - TRUE.cy) < 0.1 * HORIZON_PX
    assert 0.6 * HORIZON_PX < disc.radius_px < HORIZON_PX
    found = detect_image(image, lens="equidistant")
    inside = (found.xy[:, 1] < CAPTION[0].stop + 5) & (found.xy[:, 0] < CAPTION[1].stop + 5)
    assert len(found) >= 40 and not inside.any()


def test_a_sky_clipped_to_black_keeps_its_stars():
    # stars on a sky clipped to black, a lit horizon glow along the bottom: the flat black is
    # the sky here (the stars are in it), not a surround
    rng = np.random.default_rng(6)
    image = np.zeros((HEIGHT, WIDTH), dtype=np.float32)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    image[y > 0.85 * HEIGHT] = 40.0 + rng.normal(0, 3, (y > 0.85 * HEIGHT).sum())
    for sx, sy in rng.uniform([8, 8], [WIDTH - 8, 0.8 * HEIGHT], size=(400, 2)):
        box = (slice(int(sy) - 6, int(sy) + 7), slice(int(sx) - 6, int(sx) + 7))
        image[box] += 120.0 * np.exp(-((x[box] - sx) ** 2 + (y[box] - sy) ** 2) / (2 * 1.2**2))
    image = np.clip(np.round(image), 0, 255)
    mask = find_sky_mask(image)
    assert (~mask.excluded[: int(0.8 * HEIGHT)]).mean() > 0.9


@pytest.mark.slow
def test_the_frame_solves_with_only_the_lens_named(frame):
    image, R, _ = frame
    res = solve_image(image, lens="equidistant", time_budget_s=120.0)
    s = res.solution
    assert s is not None, res.reason
    assert abs(s.camera.cx - TRUE.cx) < 3.0 and abs(s.camera.cy - TRUE.cy) < 3.0
    # the boresight is the solved principal point's direction (a pixel off is 0.23° here)
    seen = R.T @ TRUE.pixels_to_bearings(np.array([[s.camera.cx, s.camera.cy]]))[0]
    off_deg = np.degrees(np.arccos(min(1.0, float(seen @ s.R_cam_from_icrs[2]))))
    assert off_deg < 5 * s.sigma_boresight_arcsec / 3600.0
    assert attitude_difference_deg(s.R_cam_from_icrs, R)[1] < 0.05  # the roll
    assert abs(s.focal_px / TRUE.focal_px - 1) < 0.01
