"""The WCS fitted again on every detection a deeper catalog explains
(``starnav.output.tweak.deep_fit``): from a fit on a solve's few bright stars to one on
hundreds, false detections and missing stars included, the centre nearer the truth."""

from __future__ import annotations

import numpy as np

from starnav.camera import Camera
from starnav.catalog import GAIA, load_catalog
from starnav.geometry import attitude_from_radec_roll, radec_to_unit
from starnav.output.tweak import deep_fit
from starnav.output.wcs import fit_wcs_to_stars

W, H = 1600, 1200


def _sky_at(fit, xy) -> np.ndarray:
    ra, dec = fit.wcs.all_pix2world(np.asarray(xy, float) - 0.5, 0).T
    return radec_to_unit(np.radians(ra), np.radians(dec))


def _field(seed: int):
    """A 12° frame through a lens with k1 = -0.08 (corners ~8 px): the Gaia catalog, the rows
    of its stars in the frame (brightest first) and their true pixels."""
    camera = Camera(W, H, focal_px=W / 2 / np.tan(np.radians(6.0)), k1=-0.08)
    R = attitude_from_radec_roll(84.0, 3.0, 25.0)
    cat = load_catalog(GAIA)
    cam = cat.vectors @ R.T
    ahead = np.flatnonzero(cam[:, 2] > 0.9)
    xy = camera.bearings_to_pixels(cam[ahead])
    inside = (xy[:, 0] > 0) & (xy[:, 0] < W) & (xy[:, 1] > 0) & (xy[:, 1] < H)
    rows = ahead[inside][np.argsort(cat.mag[ahead[inside]], kind="stable")]
    xy = camera.bearings_to_pixels(cat.vectors[rows] @ R.T)
    return cat, rows, xy, np.random.default_rng(seed)


def test_deep_fit_equals_least_squares_on_the_true_pairs():
    """From a plain TAN on the solve's 15 brightest stars, among 80 % of the 400 brightest
    stars and 150 false detections: nearly every star seen is paired, none falsely (the rms
    is the noise's), the distortion becomes measurable, and the sky at the centre is the one
    the fit on all the true pairs gives."""
    cat, rows, xy, rng = _field(1)
    measured = xy + rng.normal(0.0, 0.3, xy.shape)
    start = fit_wcs_to_stars(measured[:15], cat.vectors[rows[:15]], W, H)
    seen = rng.random(400) < 0.8
    false = rng.uniform((0, 0), (W, H), (150, 2))
    deep = deep_fit(start, np.concatenate([measured[:400][seen], false]), (cat,), W, H)
    truth = fit_wcs_to_stars(measured[:400][seen], cat.vectors[rows[:400][seen]], W, H)
    assert deep is not None and deep.n_stars >= 0.9 * seen.sum()
    assert deep.order == truth.order >= 3 and start.order == 1
    assert deep.rms_px < 0.45  # 0.3 px a coordinate: 0.42 px, no false pair among them
    middle = [[W / 2, H / 2]]
    apart_px = np.degrees(np.arccos(min(1.0, _sky_at(deep, middle)[0] @ _sky_at(truth, middle)[0])))
    assert apart_px / (12.0 / W) < 0.01


def test_no_deeper_stars_no_deep_fit():
    """Detections no more than the stars fitted already: None (the fit stands)."""
    cat, rows, xy, _ = _field(2)
    start = fit_wcs_to_stars(xy[:20], cat.vectors[rows[:20]], W, H)
    assert deep_fit(start, xy[:20], (cat,), W, H) is None
