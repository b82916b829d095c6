"""FITS WCS from a starnav attitude: compared with starnav's own projection of catalog stars."""

import astropy.units as u
import numpy as np
import pytest
from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.wcs import WCS

from starnav.camera import (
    Camera,
    Equidistant,
    Equisolid,
    KannalaBrandt,
    Orthographic,
    Stereographic,
)
from starnav.catalog import load_catalog
from starnav.errors import CameraError, ImageError, StarnavError
from starnav.geometry import attitude_from_radec_roll, radec_to_unit, unit_to_radec
from starnav.output.wcs import (
    MAX_SIP_ORDER,
    choose_sip_order,
    fit_sip,
    projection,
    wcs_from_attitude,
    write_wcs,
)
from starnav.simulate import project_catalog


@pytest.fixture(scope="module")
def catalog():
    return load_catalog(None, mag_limit=6.5)


def _attitudes(n, seed):
    """Random boresights over the sphere, rolls and both parities, plus the two poles."""
    rng = np.random.default_rng(seed)
    out = [(0.0, 90.0, 0.0, 1), (123.0, 90.0, 77.0, -1), (5.0, -90.0, 10.0, 1)]
    for k in range(n):
        ra, dec = rng.uniform(0, 360), np.degrees(np.arcsin(rng.uniform(-1, 1)))
        out.append((ra, dec, rng.uniform(0, 360), 1 if k % 2 else -1))
    return out


def _distorted(fov_deg, width, height, k1, k2=0.0, cx=None, cy=None):
    cam = Camera.from_fov(fov_deg, width, height)
    return Camera(width, height, cam.focal_px, cx, cy, k1, k2)


def _sky(catalog, rows):
    return SkyCoord(catalog.ra_deg[rows] * u.deg, catalog.dec_deg[rows] * u.deg, frame="icrs")


def _starnav_px(wcs, sky):
    """starnav pixels of sky positions through the WCS (astropy's 0-based pixels + 0.5)."""
    return np.column_stack(wcs.world_to_pixel(sky)) + 0.5


@pytest.mark.parametrize(
    "camera, tolerance_px",
    [
        (Camera.from_fov(20.0, 1024, 768), 1e-6),
        (Camera(640, 480, 900.0, 300.25, 250.5), 1e-6),  # off-centre principal point
        # the SIP fits of distorted cameras: ~2 s each
        pytest.param(_distorted(20.0, 1024, 1024, -0.05), 0.05, marks=pytest.mark.slow),
        pytest.param(
            _distorted(20.0, 1280, 960, -0.05, 0.02, cx=650.0, cy=470.0),
            0.05,
            marks=pytest.mark.slow,
        ),
    ],
)
def test_wcs_puts_catalog_stars_where_starnav_projects_them(catalog, camera, tolerance_px):
    worst, stars = 0.0, 0
    for ra, dec, roll, parity in _attitudes(12, seed=3):
        R = attitude_from_radec_roll(ra, dec, roll, parity)
        rows, xy = project_catalog(catalog, R, camera)
        wcs = wcs_from_attitude(R, camera)
        assert wcs.wcs.ctype[0] == ("RA---TAN-SIP" if camera.k1 else "RA---TAN")
        worst = max(worst, float(np.abs(_starnav_px(wcs, _sky(catalog, rows)) - xy).max()))
        stars += len(rows)
    assert stars > 200
    assert worst <= tolerance_px


def test_inverse_sip_polynomials_match_the_camera(catalog):
    """AP/BP (sky -> pixel without iterating, what many viewers use) within 0.05 px."""
    camera = _distorted(20.0, 1024, 1024, -0.05)
    for ra, dec, roll, parity in _attitudes(6, seed=4):
        R = attitude_from_radec_roll(ra, dec, roll, parity)
        rows, xy = project_catalog(catalog, R, camera)
        wcs = wcs_from_attitude(R, camera)
        sky = _sky(catalog, rows)
        undistorted = wcs.wcs_world2pix(np.column_stack([sky.ra.deg, sky.dec.deg]), 1)
        # astropy's sip_foc2pix takes focal-plane coordinates relative to CRPIX
        fits_px = wcs.sip_foc2pix(undistorted - wcs.wcs.crpix, 1)
        assert np.abs(fits_px - 0.5 - xy).max() <= 0.05


def test_orientation_of_the_sky_on_the_image():
    """Independent of starnav's projection code: parity +1, roll 0 is North up (-y), East left;
    parity -1 puts East on the right; roll 90 turns East up."""
    camera = Camera.from_fov(10.0, 800, 600)
    centre = np.array([[camera.cx - 0.5, camera.cy - 0.5]])  # astropy 0-based pixels

    def sky_at(wcs, dx, dy):
        ra, dec = wcs.all_pix2world(centre + np.array([dx, dy]), 0)[0]
        return ra, dec

    wcs = wcs_from_attitude(attitude_from_radec_roll(150.0, 30.0, 0.0, 1), camera)
    assert np.allclose(wcs.wcs.crval, [150.0, 30.0])
    assert sky_at(wcs, 0, -100)[1] > 30.1  # up is North
    assert sky_at(wcs, -100, 0)[0] > 150.1  # left is East
    mirrored = wcs_from_attitude(attitude_from_radec_roll(150.0, 30.0, 0.0, -1), camera)
    assert sky_at(mirrored, 0, -100)[1] > 30.1
    assert sky_at(mirrored, 100, 0)[0] > 150.1  # right is East
    assert np.linalg.det(wcs.wcs.cd) * np.linalg.det(mirrored.wcs.cd) < 0
    rolled = wcs_from_attitude(attitude_from_radec_roll(150.0, 30.0, 90.0, 1), camera)
    assert sky_at(rolled, 0, -100)[0] > 150.1  # up is East
    scale_deg = np.degrees(1.0 / camera.focal_px)  # at the tangent point
    assert np.isclose(np.sqrt(abs(np.linalg.det(wcs.wcs.cd))), scale_deg, rtol=1e-12)


@pytest.mark.parametrize("k1", [0.0, -0.05])
def test_pixel_to_world_round_trip_and_bearings(k1):
    camera = _distorted(20.0, 1024, 768, k1)
    R = attitude_from_radec_roll(287.3, -41.2, 133.0, -1)
    wcs = wcs_from_attitude(R, camera)
    xy = np.random.default_rng(5).uniform([0, 0], [1024, 768], (200, 2))
    sky = wcs.pixel_to_world(xy[:, 0] - 0.5, xy[:, 1] - 0.5)
    back = _starnav_px(wcs, sky)
    assert np.abs(back - xy).max() < 1e-3
    # the same directions as the camera model gives
    truth = camera.pixels_to_bearings(xy) @ R  # rows: ICRS unit vectors (R orthogonal)
    got = radec_to_unit(sky.ra.rad, sky.dec.rad)
    error_px = np.degrees(np.linalg.norm(got - truth, axis=1)) / np.degrees(1 / camera.focal_px)
    assert error_px.max() < (1e-6 if k1 == 0 else 0.05)


def test_sip_fit_error_is_reported_and_falls_with_order():
    camera = _distorted(20.0, 1024, 1024, -0.05)
    fit4 = fit_sip(camera)
    fit5 = fit_sip(camera, order=5)
    assert fit4.order == 4 and fit4.a.shape == (5, 5)
    assert 1.0 < fit4.max_distortion_px < 5.0  # the corners move by a couple of pixels
    assert 1e-4 < fit4.max_error_px < 0.02
    assert fit5.max_error_px < fit4.max_error_px / 10
    assert fit4.max_inverse_error_px < 1e-6  # k1 only: the inverse is an exact cubic
    assert fit4.a[0, 0] == fit4.a[1, 0] == fit4.a[0, 1] == 0.0
    # a radial model about the image centre: no even terms survive
    assert fit4.a[2, 0] == fit4.a[1, 1] == fit4.b[0, 2] == 0.0
    with pytest.raises(StarnavError, match="sip_order"):
        fit_sip(camera, order=1)
    with pytest.raises(CameraError, match="cannot be inverted"):
        fit_sip(_distorted(90.0, 1000, 1000, -2.0))


@pytest.mark.slow
def test_chosen_sip_order_is_the_lowest_good_to_a_hundredth_of_a_pixel():
    assert choose_sip_order(_distorted(20.0, 1024, 1024, 0.0)) == 4  # nothing to fit
    assert choose_sip_order(_distorted(20.0, 1024, 1024, -0.05)) == 4  # 0.007 px at order 4
    camera = _distorted(30.0, 1024, 1024, -0.1)
    order = choose_sip_order(camera)
    assert order == 5 and fit_sip(camera, order=order).max_error_px <= 0.01
    assert fit_sip(camera, order=order - 1).max_error_px > 0.01
    assert choose_sip_order(camera, max_error_px=1e-6) == 7  # no higher than 7
    assert choose_sip_order(camera, max_error_px=1e-6, highest=6) == 6


@pytest.mark.filterwarnings("ignore:The WCS transformation has more axes")  # NAXIS = 0
def test_header_written_and_read_back_gives_the_same_mapping(tmp_path, catalog):
    camera = _distorted(15.0, 900, 700, -0.05, 0.01)
    R = attitude_from_radec_roll(83.8, -5.4, 30.0, -1)
    wcs = wcs_from_attitude(R, camera, date_obs="2024-03-01T22:15:00")
    path = tmp_path / "wcs.fits"
    write_wcs(path, wcs)
    with fits.open(path) as hdul:
        header = hdul[0].header
        assert hdul[0].data is None and header["NAXIS"] == 0
    assert header["CTYPE1"] == "RA---TAN-SIP" and header["CTYPE2"] == "DEC--TAN-SIP"
    assert (header["IMAGEW"], header["IMAGEH"]) == (900, 700)
    assert header["RADESYS"] == "ICRS" and header["EQUINOX"] == 2000.0
    assert header["DATE-OBS"].startswith("2024-03-01T22:15:00")
    assert "CD1_1" in header and "PC1_1" not in header
    assert header["CRPIX1"] == camera.cx + 0.5 and header["CRPIX2"] == camera.cy + 0.5
    again = WCS(header)
    rows, xy = project_catalog(catalog, R, camera)
    sky = _sky(catalog, rows)
    assert np.abs(_starnav_px(again, sky) - _starnav_px(wcs, sky)).max() < 1e-9
    assert np.abs(_starnav_px(again, sky) - xy).max() < 0.05
    assert np.allclose(again.wcs.cd, wcs.wcs.cd, rtol=1e-12, atol=0)


def test_image_written_under_the_header(tmp_path):
    camera = Camera.from_fov(10.0, 64, 48)
    wcs = wcs_from_attitude(attitude_from_radec_roll(10.0, 20.0, 0.0), camera)
    image = np.arange(48 * 64, dtype=np.uint16).reshape(48, 64)
    path = tmp_path / "image.fits"
    write_wcs(path, wcs, image=image)
    with fits.open(path) as hdul:
        assert np.array_equal(hdul[0].data, image)  # row 0 stays row 0 (FITS y = 1)
        again = WCS(hdul[0].header)
    ra, dec = again.all_pix2world([[camera.cx + 0.5, camera.cy + 0.5]], 1)[0]
    assert np.isclose(ra, 10.0) and np.isclose(dec, 20.0)
    with pytest.raises(ImageError, match="does not match"):
        write_wcs(path, wcs, image=image.T)
    with pytest.raises(ImageError, match="2-D"):
        write_wcs(path, wcs, image=np.zeros((48, 64, 3)))
    with pytest.raises(StarnavError, match="cannot write"):
        write_wcs(tmp_path / "no" / "such" / "dir.fits", wcs)


def test_bad_attitude_and_date_are_refused():
    camera = Camera.from_fov(10.0, 64)
    with pytest.raises(StarnavError, match="orthonormal"):
        wcs_from_attitude(2.0 * np.eye(3), camera)
    with pytest.raises(StarnavError, match="3x3"):
        wcs_from_attitude(np.eye(2), camera)
    with pytest.raises(StarnavError, match="sip_order"):
        wcs_from_attitude(np.eye(3), camera, sip_order=12)
    with pytest.raises(StarnavError, match="date_obs"):
        wcs_from_attitude(np.eye(3), camera, date_obs="yesterday")


def test_crval_is_the_boresight():
    R = attitude_from_radec_roll(359.9, -12.0, 200.0, -1)
    wcs = wcs_from_attitude(R, Camera.from_fov(5.0, 100))
    ra, dec = np.degrees(unit_to_radec(R[2]))
    assert np.allclose(wcs.wcs.crval, [ra, dec])


# --- every lens model in its own projection ------------------------------------------------

_KB_NORMAL = {"k1": -0.02, "k2": 0.003, "k3": -0.0005}
_KB_WIDE = {"k1": 0.0368, "k2": -0.0129, "k3": 0.0011}


def _circular(cls, circle_deg, size=1000, **coefficients):
    """A circular fisheye: the image circle of ``circle_deg`` just fits the image's width."""
    return cls.from_fov(circle_deg, size, size, **coefficients).with_circle(circle_deg)


# (camera, FITS projection, tolerance in px): the exact projections to 1e-6 px (they agree to
# ~1e-12), SIP to 0.1 px; the orthographic circle stops short of 180° because with a 180°
# circle ``sees`` takes directions up to 0.57° behind the image plane (kernels.MARGIN_RAD),
# which r = f sin θ folds back into the image and SIN cannot reach;
# 90° across 1200 x 900 px, or a 185° circular fisheye (the orthographic stops at 180°)
WIDE_CAMERAS = [
    (Camera.from_fov(90.0, 1200, 900), "TAN", 1e-6),
    (Equidistant.from_fov(90.0, 1200, 900), "ARC", 1e-6),
    (_circular(Equidistant, 185.0), "ARC", 1e-6),
    (Stereographic.from_fov(90.0, 1200, 900), "STG", 1e-6),
    (_circular(Stereographic, 185.0), "STG", 1e-6),
    (Equisolid.from_fov(90.0, 1200, 900), "ZEA", 1e-6),
    (_circular(Equisolid, 185.0), "ZEA", 1e-6),
    (Orthographic.from_fov(90.0, 1200, 900), "SIN", 1e-6),
    (_circular(Orthographic, 178.0), "SIN", 1e-6),
    (KannalaBrandt.from_fov(90.0, 1200, 900, **_KB_NORMAL), "ARC-SIP", 0.1),
    (_circular(KannalaBrandt, 185.0, **_KB_WIDE), "ARC-SIP", 0.1),
]
_IDS = [f"{c.model}-{c.fov_deg:.0f}" for c, _, _ in WIDE_CAMERAS]


@pytest.fixture(scope="module")
def wide_wcs():
    """For each camera: its WCS at a few attitudes (both parities, the poles), SIP of the
    order ``choose_sip_order`` picks (the one ``starnav solve --wcs`` writes)."""
    attitudes = [attitude_from_radec_roll(*a) for a in _attitudes(3, seed=8)]
    out = {}
    for camera, _, _ in WIDE_CAMERAS:
        order = choose_sip_order(camera)
        out[id(camera)] = [(R, wcs_from_attitude(R, camera, sip_order=order)) for R in attitudes]
    return out


def _radec(catalog, rows):
    """(n, 2) RA, Dec (degrees) of catalog rows, as astropy's array methods take them."""
    return np.column_stack([catalog.ra_deg[rows], catalog.dec_deg[rows]])


@pytest.mark.slow
@pytest.mark.parametrize("camera, code, tolerance_px", WIDE_CAMERAS, ids=_IDS)
def test_each_lens_model_projects_catalog_stars_through_its_wcs(
    catalog, wide_wcs, camera, code, tolerance_px
):
    """Sky -> pixel: astropy's all_world2pix against the camera model, over the whole field
    (past 90° from the axis for the 185° lenses)."""
    worst, stars, widest_deg = 0.0, 0, 0.0
    for R, wcs in wide_wcs[id(camera)]:
        assert projection(camera) == code.removesuffix("-SIP")
        assert wcs.wcs.ctype[0] == f"RA---{code}" and wcs.wcs.ctype[1] == f"DEC--{code}"
        assert wcs.wcs.lonpole == 180.0
        c = catalog.vectors @ R.T
        rows = np.flatnonzero(camera.sees(c))
        xy = camera.bearings_to_pixels(c[rows])
        got = wcs.all_world2pix(_radec(catalog, rows), 0) + 0.5  # astropy 0-based -> ours
        worst = max(worst, float(np.linalg.norm(got - xy, axis=1).max()))
        stars += len(rows)
        widest_deg = max(widest_deg, float(np.degrees(np.arccos(c[rows, 2].min()))))
    assert stars > 1000
    assert widest_deg > (90.0 if camera.fov_deg > 180.0 else 0.4 * camera.fov_deg)
    assert worst <= tolerance_px, f"{camera.model}: {worst:.3g} px"


@pytest.mark.slow
@pytest.mark.parametrize("camera, code, tolerance_px", WIDE_CAMERAS, ids=_IDS)
def test_each_lens_model_maps_pixels_to_the_camera_model_directions(
    wide_wcs, camera, code, tolerance_px
):
    """Pixel -> sky: astropy's all_pix2world against ``pixels_to_bearings``, within the angle
    of ``tolerance_px`` at the centre of the image (1 px = 1 / focal_px radians)."""
    rng = np.random.default_rng(9)
    xy = rng.uniform([0, 0], [camera.width, camera.height], (3000, 2))
    bearings = camera.pixels_to_bearings(xy)
    inside = camera.sees(bearings)  # within the image circle
    xy, bearings = xy[inside], bearings[inside]
    worst = 0.0
    for R, wcs in wide_wcs[id(camera)]:
        ra, dec = np.radians(wcs.all_pix2world(xy - 0.5, 0)).T
        truth = bearings @ R  # rows: ICRS unit vectors (R orthogonal)
        angle = np.linalg.norm(radec_to_unit(ra, dec) - truth, axis=1)
        worst = max(worst, float(angle.max()) * camera.focal_px)
    assert worst <= tolerance_px, f"{camera.model}: {worst:.3g} px"


@pytest.mark.slow
@pytest.mark.parametrize("camera", [c for c, code, _ in WIDE_CAMERAS if "SIP" in code])
def test_fisheye_inverse_sip_polynomials_match_the_camera(catalog, wide_wcs, camera):
    """AP/BP (sky -> pixel without iterating, what many viewers use) within 0.1 px."""
    worst = 0.0
    for R, wcs in wide_wcs[id(camera)]:
        rows, xy = project_catalog(catalog, R, camera)
        ideal = wcs.wcs_world2pix(_radec(catalog, rows), 1)
        # astropy's sip_foc2pix takes focal-plane coordinates relative to CRPIX
        fits_px = wcs.sip_foc2pix(ideal - wcs.wcs.crpix, 1)
        worst = max(worst, float(np.linalg.norm(fits_px - 0.5 - xy, axis=1).max()))
    assert worst <= 0.1


@pytest.mark.slow
def test_fisheye_sip_order_is_chosen_like_the_pinhole_s():
    normal = KannalaBrandt.from_fov(90.0, 1200, 900, **_KB_NORMAL)
    order = choose_sip_order(normal)
    assert fit_sip(normal, order=order).max_error_px <= 0.01
    assert fit_sip(normal, order=order - 1).max_error_px > 0.01
    # past 90° from the axis the lowest good to 0.01 px may not exist: the highest then
    wide = _circular(KannalaBrandt, 185.0, **_KB_WIDE)
    fit = fit_sip(wide, order=choose_sip_order(wide))
    assert fit.order == MAX_SIP_ORDER and fit.max_error_px < 0.05
    assert fit.max_distortion_px > 10.0  # far from an ideal equidistant lens
    assert choose_sip_order(Equidistant.from_fov(185.0, 1000)) == 4  # nothing to fit
    with pytest.raises(CameraError, match="no distortion"):
        fit_sip(Equidistant.from_fov(185.0, 1000))


@pytest.mark.filterwarnings("ignore:The WCS transformation has more axes")  # NAXIS = 0
@pytest.mark.parametrize("camera", [WIDE_CAMERAS[6][0], WIDE_CAMERAS[-1][0]], ids=["ZEA", "ARC"])
def test_fisheye_header_written_and_read_back(tmp_path, catalog, camera):
    """The solve --wcs path: wcs_from_attitude at the chosen SIP order, write_wcs, the file
    read back with astropy.io.fits."""
    R = attitude_from_radec_roll(250.0, -60.0, 300.0, -1)
    wcs = wcs_from_attitude(R, camera, sip_order=choose_sip_order(camera))
    path = tmp_path / "wcs.fits"
    write_wcs(path, wcs)
    with fits.open(path) as hdul:
        header = hdul[0].header
    code = projection(camera) + ("-SIP" if camera.distorted else "")
    assert header["CTYPE1"] == f"RA---{code}" and header["CTYPE2"] == f"DEC--{code}"
    assert (header["CRPIX1"], header["CRPIX2"]) == (camera.cx + 0.5, camera.cy + 0.5)
    assert "CD1_1" in header and "PC1_1" not in header
    assert header.get("A_ORDER") == header.get("AP_ORDER") == (9 if camera.distorted else None)
    scale_deg = np.degrees(1.0 / camera.focal_px)  # the same CD matrix form as TAN's
    cd = np.array([[header["CD1_1"], header["CD1_2"]], [header["CD2_1"], header["CD2_2"]]])
    assert np.isclose(np.linalg.det(cd), -(scale_deg**2), rtol=1e-12)  # mirrored
    again = WCS(header)
    rows, xy = project_catalog(catalog, R, camera)
    behind = (catalog.vectors[rows] @ R[2]) < 0.0
    assert behind.sum() > 10  # stars past 90° from the axis are in the file's field too
    got = again.all_world2pix(_radec(catalog, rows), 0) + 0.5
    assert np.abs(got - xy).max() < (0.1 if camera.distorted else 1e-6)


@pytest.mark.parametrize(
    "cls, theta_of_rho",
    [
        (Equidistant, lambda rho: rho),
        (Stereographic, lambda rho: 2.0 * np.arctan(0.5 * rho)),
        (Equisolid, lambda rho: 2.0 * np.arcsin(0.5 * rho)),
        (Orthographic, np.arcsin),
    ],
)
def test_fisheye_radius_and_orientation_independent_of_the_camera_code(cls, theta_of_rho):
    """From the domain formulas alone: a pixel r px above the principal point is θ(r / f)
    from the boresight, due North for parity +1 and roll 0 (East left; right when mirrored)."""
    camera = cls.from_fov(170.0, 1000, 1000)
    centre = np.array([camera.cx - 0.5, camera.cy - 0.5])  # astropy 0-based pixels
    for parity, east_sign in ((1, -1), (-1, 1)):
        wcs = wcs_from_attitude(attitude_from_radec_roll(40.0, 10.0, 0.0, parity), camera)
        r_px = np.array([50.0, 200.0, 450.0])
        up = wcs.all_pix2world(centre - np.column_stack([0 * r_px, r_px]), 0)
        distance = np.arccos(
            radec_to_unit(*np.radians(up).T) @ radec_to_unit(*np.radians([40, 10]))
        )
        assert np.allclose(distance, theta_of_rho(r_px / camera.focal_px), rtol=0, atol=1e-12)
        assert np.all(np.diff(up[:, 1]) > 0) and np.allclose(up[:, 0], 40.0)  # due North
        side = wcs.all_pix2world((centre + np.array([east_sign * 100.0, 0.0]))[None], 0)[0]
        assert 40.5 < side[0] < 90.0  # toward East: RA grows
