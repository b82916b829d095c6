"""Images whose pixels are not square (``detect.header`` reads their sizes; ``pipeline.image``
solves them in square pixels and answers in the file's): a CCD such as the SX Lodestar's,
8.6 x 8.3 µm, is 3.5 % off square, 17 px at 500 px from the centre."""

import numpy as np
import pytest
from astropy.io import fits
from scipy.ndimage import zoom

from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.detect.header import fits_hints
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import fitted_wcs, solve_image
from starnav.simulate.render import RenderSettings, render_frame

R_TRUE = attitude_from_radec_roll(83.8, -5.4, 30.0)
ASPECT = 0.9  # a pixel's height over its width
WIDTH, HEIGHT = 1024, 800  # the file's pixels


def _header(**cards) -> fits.Header:
    header = fits.Header()
    for key, value in cards.items():
        header[key] = value
    return header


def test_the_pixel_aspect_is_read_from_the_pixel_sizes(tmp_path):
    cases = [
        ({"XPIXSZ": 8.6, "YPIXSZ": 8.3}, 8.3 / 8.6, "XPIXSZ/YPIXSZ"),
        ({"PIXSIZE1": 9.0, "PIXSIZE2": 8.1}, 0.9, "PIXSIZE1/PIXSIZE2"),
        ({"XPIXSZ": 3.76, "YPIXSZ": 3.76}, 1.0, None),  # square
        ({"XPIXSZ": 3.76}, 1.0, None),  # one size alone says nothing
        ({"XPIXSZ": 3.76, "YPIXSZ": 376.0}, 1.0, None),  # a typo, not a 100x taller image
        ({"XPIXSZ": 8.6, "YPIXSZ": -8.3}, 1.0, None),
    ]
    for n, (cards, aspect, source) in enumerate(cases):
        path = tmp_path / f"{n}.fits"
        fits.PrimaryHDU(np.zeros((8, 8), np.uint16), _header(**cards)).writeto(path)
        hints = fits_hints(path)
        assert hints.pixel_aspect == pytest.approx(aspect, rel=1e-12), cards
        assert (source in hints.sources) if source else not any("/" in s for s in hints.sources)


def _non_square_frame(tmp_path, **cards):
    """A 20° frame rendered in square pixels (1024 x 720), its rows resampled to 800 pixels
    ``ASPECT`` times as tall as wide: the true stars at (x, y / ASPECT) in the file."""
    camera = Camera.from_fov(20.0, WIDTH, round(HEIGHT * ASPECT))
    frame = render_frame(load_catalog(None, mag_limit=7.5), camera, R_TRUE, RenderSettings(seed=3))
    rows = zoom(frame.image.astype(np.float32), (HEIGHT / camera.height, 1.0), order=1,
                grid_mode=True, mode="nearest")  # fmt: skip
    path = tmp_path / "lodestar.fits"
    fits.PrimaryHDU(rows, _header(**cards)).writeto(path)
    return path, frame


def test_a_non_square_pixel_image_is_solved_and_answered_in_its_own_pixels(tmp_path):
    path, frame = _non_square_frame(tmp_path, XPIXSZ=9.0, YPIXSZ=9.0 * ASPECT)
    result = solve_image(path, fov_deg=20.0)
    s = result.solution
    assert s is not None, result.reason
    assert s.pixel_aspect == pytest.approx(ASPECT)
    bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R_TRUE)
    assert bore < 0.01 and roll < 0.02, (bore, roll)
    assert s.fov_deg == pytest.approx(20.0, rel=2e-3)
    assert (result.detections.width, result.detections.height) == (WIDTH, HEIGHT)
    truth = {int(i): xy / (1.0, ASPECT) for i, xy in zip(frame.ids, frame.xy, strict=True)}
    table = s.star_table
    matched = np.flatnonzero(table.catalog_id >= 0)
    assert len(matched) >= 10
    offsets = [np.hypot(*(table.xy[k] - truth[int(table.catalog_id[k])])) for k in matched]
    assert np.median(offsets) < 0.3, offsets  # the stars in the file's pixels
    # the WCS maps the matched stars' catalog places onto them, in the file's pixels (FITS
    # pixel = starnav px + 0.5), with columns in the pixels' ratio
    catalog = result.catalog
    for wcs in (fitted_wcs(s, catalog), fitted_wcs(s, None)):  # from the stars; the camera's
        rows = catalog.rows(table.catalog_id[matched])
        px = np.column_stack(wcs.all_world2pix(catalog.ra_deg[rows], catalog.dec_deg[rows], 1))
        assert np.median(np.hypot(*(px - 0.5 - table.xy[matched]).T)) < 0.3
        cd = wcs.wcs.cd
        assert np.hypot(*cd[:, 1]) / np.hypot(*cd[:, 0]) == pytest.approx(ASPECT, rel=2e-3)
    assert result.to_dict()["pixel_aspect"] == pytest.approx(ASPECT)
    assert result.to_dict()["cy"] == pytest.approx(HEIGHT / 2.0, abs=0.01)


def test_without_the_pixel_sizes_the_same_image_is_not_answered_well(tmp_path):
    """The header is what makes the difference: read as square, the fit cannot hold the
    10 % aspect (not solved, or its roll and residuals far off)."""
    path, _ = _non_square_frame(tmp_path)
    s = solve_image(path, fov_deg=20.0).solution
    if s is not None:
        assert s.pixel_aspect == 1.0
        assert s.rms_px > 1.0 or attitude_difference_deg(s.R_cam_from_icrs, R_TRUE)[1] > 0.1
