"""The sky mask (``starnav.detect.skymask``) on a rendered all-sky frame with a horizon: a
jagged tree line, a lit wall with three lit windows, the Moon (a saturated disc and its
halo). What stands above the horizon and the glare go; the stars of the clear sky stay."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from starnav.camera.fisheye import Equidistant
from starnav.catalog import load_catalog
from starnav.detect.skymask import find_sky_mask
from starnav.detect.stars import detect_stars
from starnav.geometry import attitude_from_radec_roll
from starnav.pipeline.image import detect_image, solve_image
from starnav.simulate.render import RenderSettings, render_frame

SIZE = 1024
SATURATED = 65535.0


@pytest.fixture(scope="module")
def scene():
    camera = Equidistant.from_fov(185.0, SIZE, SIZE).with_circle(185.0)
    settings = RenderSettings(psf_sigma_px=1.1, background_e=400.0, exposure_s=1.0,
                              zero_point_e_per_s=2e5, mag_limit=6.5, seed=5)  # fmt: skip
    catalog = load_catalog(None, mag_limit=6.5)
    frame = render_frame(catalog, camera, attitude_from_radec_roll(120.0, 50.0, 10.0), settings)
    image = frame.image.astype(np.float32)
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    r = np.hypot(x - camera.cx, y - camera.cy)
    phi = np.degrees(np.arctan2(y - camera.cy, x - camera.cx)) % 360.0
    disc_r = SIZE / 2 * 180.0 / 185.0  # the horizon (90°; the circle is 92.5°)
    sky = float(np.median(image[r < 0.5 * disc_r]))
    noise = np.sqrt(sky)
    # trees: a dark, jagged silhouette over 100° of the horizon
    jagged = 0.05 * np.abs(np.sin(np.radians(9 * phi))) + 0.03 * np.sin(np.radians(23 * phi))
    edge = disc_r * (0.80 + jagged)
    trees = (phi > 100) & (phi < 200) & (r > edge) & (r < disc_r)
    image[trees] = 0.3 * sky + rng.normal(0, 0.6 * noise, trees.sum())
    # a lit wall with three lit windows (saturated 4 x 4 px: "stars" to a detector)
    wall = ((phi > 330) | (phi < 20)) & (r > 0.82 * disc_r) & (r < disc_r)
    image[wall] = 2.5 * sky + rng.normal(0, noise, wall.sum())
    for angle in (340.0, 355.0, 10.0):
        wx = camera.cx + 0.9 * disc_r * np.cos(np.radians(angle))
        wy = camera.cy + 0.9 * disc_r * np.sin(np.radians(angle))
        image[(np.abs(x - wx) < 2) & (np.abs(y - wy) < 2)] = SATURATED
    # the Moon: a saturated disc of 6 px and a halo 30 sigma bright at its edge
    d = np.hypot(x - (camera.cx - 0.15 * disc_r), y - (camera.cy - 0.4 * disc_r))
    image += (30 * noise * np.exp(-d / 25.0)).astype(np.float32)
    image[d < 6] = SATURATED
    image = np.clip(image, 0, SATURATED)
    clear = (r < 0.99 * disc_r) & ~trees & ~wall & (d >= 40)
    return frame, image, {"trees": trees, "wall": wall, "moon": d < 40}, clear


def test_sky_mask_takes_the_horizon_and_the_moon_and_leaves_the_sky(scene):
    frame, image, junk, clear = scene
    mask = find_sky_mask(image)
    assert mask.circle is not None and abs(mask.circle.radius_px - SIZE / 2) < 5  # 92.5°
    for name, where in junk.items():
        assert mask.excluded[where].mean() > 0.97, name
    assert mask.obstacles > 0 and mask.glare > 0
    assert "horizon obstacles" in mask.words() and "glare" in mask.words()
    # the clear sky is kept, but for the blocks beside the junk (a block of 16 px, widened
    # by one)
    assert mask.excluded[clear].mean() < 0.07
    any_junk = junk["trees"] | junk["wall"] | junk["moon"]
    beside = ndimage.distance_transform_edt(~any_junk)
    ij = np.clip(frame.xy.astype(int), 0, SIZE - 1)
    lost = mask.excluded[ij[:, 1], ij[:, 0]] & clear[ij[:, 1], ij[:, 0]] & (frame.mag < 5.5)
    kept = ~mask.excluded[ij[:, 1], ij[:, 0]] & clear[ij[:, 1], ij[:, 0]] & (frame.mag < 5.5)
    assert lost.sum() < 0.05 * kept.sum()
    assert beside[ij[lost, 1], ij[lost, 0]].max() <= 3 * mask.block_px


def test_fisheye_detection_skips_the_junk_and_keeps_the_stars(scene):
    frame, image, junk, clear = scene
    any_junk = junk["trees"] | junk["wall"] | junk["moon"]
    circle_only = image.copy()
    circle_only[~(clear | any_junk)] = np.nan
    before = detect_stars(circle_only, max_stars=100)
    after = detect_image(image, lens="equidistant", max_stars=100)
    true_stars = cKDTree(frame.xy)

    def in_junk(found):
        ij = np.clip(found.xy.astype(int), 0, SIZE - 1)
        return any_junk[ij[:, 1], ij[:, 0]]

    assert in_junk(before).sum() >= 3  # the windows and the Moon are among the brightest
    assert in_junk(after).sum() == 0
    assert (true_stars.query(after.xy)[0] < 2.0).all()  # every detection is a star
    assert 0.55 < after.sky_fraction < 0.7 and after.threshold_sigma == 5.0


def test_clear_frame_and_small_frames(scene):
    frame, *_ = scene
    mask = find_sky_mask(frame.image)  # the clear render: nothing but the circle
    assert mask.obstacles < 0.005 and mask.glare == 0.0
    assert mask.words() == "nothing inside the sky masked" or mask.obstacles > 0
    rng = np.random.default_rng(2)
    small = find_sky_mask(rng.normal(100.0, 5.0, (120, 160)))  # too small to judge
    assert not small.excluded.any() and small.circle is None and small.sky == 1.0
    flat = find_sky_mask(rng.normal(100.0, 5.0, (600, 800)))  # a full frame of noise
    assert flat.circle is None and flat.excluded.mean() < 0.01


def _faint_allsky(zero_point_e_per_s: float) -> tuple:
    """A 512 px all-sky frame of the stars to magnitude 3.5, dim (a narrow filter, a short
    exposure), no vignetting; and its camera."""
    camera = Equidistant.from_fov(185.0, 512, 512).with_circle(185.0)
    settings = RenderSettings(psf_sigma_px=1.0, background_e=200.0, exposure_s=1.0,
                              zero_point_e_per_s=zero_point_e_per_s, mag_limit=3.5, seed=7,
                              vignetting_power=0.0)  # fmt: skip
    catalog = load_catalog(None, mag_limit=3.5)
    return render_frame(catalog, camera, attitude_from_radec_roll(200.0, 40.0, 0.0), settings)


def test_few_stars_are_looked_for_deeper():
    frame = _faint_allsky(1500.0)
    truth = cKDTree(frame.xy)
    disc = frame.image.astype(np.float32)
    disc[_outside(frame)] = np.nan
    at_five = detect_stars(disc, threshold_sigma=5.0, max_stars=100)
    assert len(at_five) < 15
    found = detect_image(frame.image, lens="equidistant")
    assert found.threshold_sigma == 4.0
    real = truth.query(found.xy)[0] < 2.0
    assert len(found) >= len(at_five) + 4  # deeper: more stars
    assert real.all()  # and no noise peak


def test_no_stars_is_refused_in_words_an_operator_acts_on():
    frame = _faint_allsky(1.0)  # cloud: no star above the noise
    result = solve_image(frame.image, lens="equidistant")
    assert result.solution is None and result.failure == "too few stars"
    assert re.search(r"only \d+ stars? above [345] sigma inside the sky \(7\d % of the frame\)",
                     result.reason)  # fmt: skip
    assert "longer exposure" in result.reason and "--threshold-sigma " in result.reason


def _outside(frame) -> np.ndarray:
    camera = frame.camera
    y, x = np.mgrid[0 : camera.height, 0 : camera.width] + 0.5
    return np.hypot(x - camera.cx, y - camera.cy) > 0.99 * camera.width / 2
