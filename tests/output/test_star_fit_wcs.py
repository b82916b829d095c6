"""The WCS fitted to matched stars (``starnav.output.wcs.fit_wcs_to_stars``): the SIP order
its F-tests choose, the residuals as a reader of the written file sees them (astropy's
``all_world2pix`` on the file read back), corners included, and on real photographs the
centre against astrometry.net's."""

from __future__ import annotations

import json

import numpy as np
import pytest
from astropy.io import fits
from astropy.wcs import WCS

from shared_data import DATA, REAL, shared_file
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll, unit_to_radec
from starnav.output.wcs import fit_wcs_to_stars, write_wcs

W, H = 1280, 960
# a header-only WCS file has NAXIS = 0: astropy says so when it reads one back
pytestmark = pytest.mark.filterwarnings("ignore::astropy.wcs.FITSFixedWarning")


def _stars(camera: Camera, R: np.ndarray, mag_limit: float = 7.0):
    """Catalog stars inside the image: their exact pixels and unit vectors."""
    cat = load_catalog(mag_limit=mag_limit)
    cam_vectors = cat.vectors @ R.T
    ahead = cam_vectors[:, 2] > 0.5
    xy = camera.bearings_to_pixels(cam_vectors[ahead])
    inside = (
        (xy[:, 0] > 0) & (xy[:, 0] < camera.width) & (xy[:, 1] > 0) & (xy[:, 1] < camera.height)
    )
    return xy[inside], cat.vectors[ahead][inside]


def _through_file(fit, vectors, tmp_path) -> np.ndarray:
    """The stars' pixels (starnav px) by astropy from the WCS written and read back."""
    path = tmp_path / "fit.wcs"
    write_wcs(path, fit.wcs)
    wcs = WCS(fits.getheader(path))
    ra, dec = np.degrees(unit_to_radec(vectors))
    return wcs.all_world2pix(np.column_stack([ra, dec]), 0, tolerance=1e-8, maxiter=100) + 0.5


def test_strong_barrel_distortion_is_fitted_to_the_corners(tmp_path):
    """A 25° pinhole with k1 = -0.15 (corners moved by ~25 px): the F-tests keep the cubic
    terms, every star, the corner ones too, lands within 0.05 px through the written file,
    and those pixels are the fit's own residuals."""
    camera = Camera(W, H, focal_px=W / 2 / np.tan(np.radians(12.5)), k1=-0.15)
    R = attitude_from_radec_roll(83.8, -5.4, 30.0)
    xy, vectors = _stars(camera, R)
    assert len(xy) > 60
    fit = fit_wcs_to_stars(xy, vectors, W, H, start=R[2])
    assert fit.order >= 3 and fit.wcs.wcs.ctype[0] == "RA---TAN-SIP"
    assert fit.rms_px < 0.05
    through = _through_file(fit, vectors, tmp_path)
    np.testing.assert_allclose(through - xy, fit.residual_px, atol=1e-4)
    corner = np.hypot(xy[:, 0] - W / 2, xy[:, 1] - H / 2) > 0.8 * np.hypot(W / 2, H / 2)
    assert corner.sum() >= 3  # stars in the corners are part of the check
    assert np.abs(through[corner] - xy[corner]).max() < 0.05
    # the image corners themselves, through the true camera and back through the file
    corners = np.array([[0.5, 0.5], [W - 0.5, 0.5], [0.5, H - 0.5], [W - 0.5, H - 0.5]])
    corner_vectors = camera.pixels_to_bearings(corners) @ R
    assert np.abs(_through_file(fit, corner_vectors, tmp_path) - corners).max() < 0.1
    # AP/BP (what DS9 and astrometry.net's own tools use) agree with the iteration
    assert fit.max_inverse_error_px < 0.01


def test_without_distortion_or_with_few_stars_it_stays_tan():
    """Noise only (0.3 px): no SIP term passes the F-test; 10 stars support no order 2 at all
    (12 are needed): plain TAN, the centre where the stars say."""
    camera = Camera(W, H, focal_px=W / 2 / np.tan(np.radians(10.0)))
    R = attitude_from_radec_roll(200.0, 40.0, -20.0)
    xy, vectors = _stars(camera, R, mag_limit=7.5)
    noisy = xy + np.random.default_rng(3).normal(0.0, 0.3, xy.shape)
    fit = fit_wcs_to_stars(noisy, vectors, W, H)
    assert fit.order == 1 and fit.wcs.wcs.ctype[0] == "RA---TAN"
    assert 0.2 < fit.rms_px < 0.6
    centre = fit.wcs.all_pix2world([[W / 2 + 0.5, H / 2 + 0.5]], 1)[0]
    truth = np.degrees(unit_to_radec(R[2]))
    assert np.hypot((centre[0] - truth[0]) * np.cos(np.radians(40.0)), centre[1] - truth[1]) < 1e-3
    few = fit_wcs_to_stars(xy[:10], vectors[:10], W, H)
    assert few.order == 1 and few.p_values == {}
    with pytest.raises(StarnavError, match="at least 3 stars"):
        fit_wcs_to_stars(xy[:2], vectors[:2], W, H)
    with pytest.raises(StarnavError, match="catalog vectors"):
        fit_wcs_to_stars(xy[:5], vectors[:4], W, H)


def test_crpix_elsewhere_keeps_the_sky():
    """CRPIX at a corner (solve-field's --crpix-x/--crpix-y): CRVAL is the sky there and the
    stars land where they did with CRPIX at the centre."""
    camera = Camera(W, H, focal_px=W / 2 / np.tan(np.radians(12.5)), k1=-0.05)
    R = attitude_from_radec_roll(10.0, 60.0, 0.0)
    xy, vectors = _stars(camera, R)
    centre = fit_wcs_to_stars(xy, vectors, W, H)
    corner = fit_wcs_to_stars(xy, vectors, W, H, crpix_px=(0.0, 0.0))
    assert tuple(corner.wcs.wcs.crpix) == (0.5, 0.5)
    assert np.abs(corner.residual_px).max() < 0.05 and np.abs(centre.residual_px).max() < 0.05
    sky = corner.wcs.all_pix2world([[0.5, 0.5]], 1)[0]
    np.testing.assert_allclose(sky, corner.wcs.wcs.crval, atol=1e-9)


GRANASAT = ("granasat_pleyades_05sec.jpg", "granasat_cisne_02sec.jpg")


@pytest.mark.slow
@pytest.mark.parametrize("name", GRANASAT)
def test_real_lens_centre_and_residuals(name, tmp_path):
    """GranaSAT's lens (27°, 1280 x 960): the plate's WCS is TAN-SIP fitted on the deep
    stars (``output.tweak``), its centre within 0.3 px of astrometry.net's (CRVAL of its
    --crpix-center solve: on cisne, 0.2 px apart, astrometry.net's middle is 0.12 px from the
    Gaia stars there, starnav's 0.03 px; docs/wcs.md), and the solve's matched stars through
    the written file are nearer their detections than through the pinhole solution."""
    from starnav.pipeline.plate import PlateHints, solve_plate, write_plate_files

    path = shared_file(REAL / name)
    res = solve_plate(path, PlateHints())
    assert res.plate is not None, res.reason
    wcs = res.plate.wcs
    assert wcs.wcs.ctype[0] == "RA---TAN-SIP"
    ref = json.loads((DATA / "real" / "reference.json").read_text())["images"][name]
    an = ref["astrometry_net"]["wcs"]
    centre = wcs.all_pix2world([[(W + 1) / 2, (H + 1) / 2]], 1)[0]
    from astropy.coordinates import angular_separation

    sep = np.degrees(angular_separation(*np.radians([*centre, an["CRVAL1"], an["CRVAL2"]])))
    scale = np.sqrt(abs(np.linalg.det([[an["CD1_1"], an["CD1_2"]], [an["CD2_1"], an["CD2_2"]]])))
    assert sep / scale < 0.3
    written = write_plate_files(res, path, wcs=tmp_path / "a.wcs")
    table = res.solution.star_table
    matched = table.catalog_id >= 0
    vectors = res.catalog.vectors[res.catalog.rows(table.catalog_id[matched])]
    back = WCS(fits.getheader(written["wcs"]))
    ra, dec = np.degrees(unit_to_radec(vectors))
    through = back.all_world2pix(np.column_stack([ra, dec]), 0) + 0.5
    rms = np.sqrt(np.mean(np.sum((through - table.xy[matched]) ** 2, axis=1)))
    assert rms < res.solution.rms_px


def test_stars_on_a_line_are_refused():
    xy = np.column_stack([np.linspace(100, 900, 6), np.linspace(100, 700, 6)])
    camera = Camera(W, H, focal_px=2000.0)
    vectors = camera.pixels_to_bearings(xy)
    with pytest.raises(StarnavError, match="on a line"):
        fit_wcs_to_stars(xy, vectors, W, H)
