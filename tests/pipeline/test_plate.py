"""pipeline.plate: astrometry.net's hints in and numbers out, checked against their formulas."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from astropy.coordinates import angular_separation
from astropy.wcs import WCS

from shared_data import LYRA, PEER_REFERENCE, peer_image
from starnav.errors import StarnavError
from starnav.pipeline.plate import (
    Plate,
    PlateHints,
    XYList,
    fov_range_from_scale,
    parity_from_nova,
    scale_bounds,
    solve_plate,
    width_deg_from_scale,
    write_plate_files,
)


def _sep_arcsec(ra1, dec1, ra2, dec2) -> float:
    """Angle between two sky positions (degrees in, arcsec out; astropy's Vincenty formula)."""
    return math.degrees(float(angular_separation(*np.radians([ra1, dec1, ra2, dec2])))) * 3600


def _tan(cd: np.ndarray, width=1000, height=800) -> WCS:
    w = WCS(naxis=2)
    w.wcs.ctype = ["RA---TAN", "DEC--TAN"]
    w.wcs.crval = [120.0, 30.0]
    w.wcs.crpix = [(width + 1) / 2, (height + 1) / 2]
    w.wcs.cd = cd
    return w


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, 135.0, -100.0])
@pytest.mark.parametrize("flip", [1.0, -1.0])
def test_orientation_and_parity_follow_astrometry_net(theta_deg, flip):
    """A CD matrix of scale s rotated by theta (and mirrored in x for flip -1): the parity is
    nova's sign of det CD, the orientation is sip.c's formula, which for such a matrix is
    -theta, mirrored or not — worked by hand from T = p cd11 + cd22 = 2 s cos(theta),
    A = p cd21 - cd12 = 2 s sin(theta), orient = -atan2(A, T)."""
    s = 1e-3
    t = math.radians(theta_deg)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    cd = s * rot @ np.diag([flip, 1.0])
    plate = Plate.from_wcs(_tan(cd), 1000, 800)
    assert plate.parity == (1.0 if flip > 0 else -1.0)
    assert plate.parity_name == ("neg" if flip > 0 else "pos")  # solve-field: det < 0 is "pos"
    expected = -theta_deg
    assert math.remainder(plate.orientation_deg - expected, 360.0) == pytest.approx(0, abs=1e-9)
    assert plate.pixscale_arcsec == pytest.approx(3.6)
    assert plate.radius_deg == pytest.approx(3.6 * math.hypot(1000, 800) / 2 / 3600)
    assert plate.ra_deg == pytest.approx(120.0) and plate.dec_deg == pytest.approx(30.0)
    cal = plate.calibration(jpeglike=True)
    assert cal["orientation"] == pytest.approx((180.0 - plate.orientation_deg) % 360.0)
    assert plate.calibration(jpeglike=False)["orientation"] == plate.orientation_deg
    assert cal["width_arcsec"] == pytest.approx(3600.0)


def test_scale_units():
    assert width_deg_from_scale("degwidth", 12.0, 1000) == 12.0
    assert width_deg_from_scale("arcminwidth", 600.0, 1000) == 10.0
    assert width_deg_from_scale("arcsecperpix", 36.0, 1000) == pytest.approx(10.0)
    # a 50 mm lens on a 36 mm wide sensor: 2 atan(18 / 50)
    assert width_deg_from_scale("focalmm", 50.0, 1000) == pytest.approx(39.5977, abs=1e-4)
    assert scale_bounds(20.0, 10.0) == pytest.approx((18.0, 22.0))
    with pytest.raises(StarnavError, match="unknown scale units 'furlongs'"):
        width_deg_from_scale("furlongs", 1.0, 1000)
    with pytest.raises(StarnavError, match="positive"):
        width_deg_from_scale("degwidth", -1.0, 1000)


def test_fov_range_is_clipped_to_what_starnav_searches():
    assert fov_range_from_scale("degwidth", 0.1, 180, 1000) == (5.0, 40.0)  # a catch-all
    assert fov_range_from_scale("degwidth", 10, 12, 1000) == (10.0, 12.0)
    assert fov_range_from_scale("degwidth", 50, 70, 1000) == (50.0, 70.0)  # outside the default
    assert fov_range_from_scale("degwidth", 4.3, 5.3, 1000) == (4.3, 5.3)  # not cut at 5°
    assert fov_range_from_scale("focalmm", 50, 100, 1000)[1] == pytest.approx(39.5977, abs=1e-4)
    with pytest.raises(StarnavError, match="outside the fields starnav solves"):
        fov_range_from_scale("arcminwidth", 10, 30, 1000)  # 0.17-0.5°
    assert fov_range_from_scale("arcminwidth", 10, 45, 1000) == (0.625, 0.75)  # 0.17-0.75°


def test_parity_words():
    assert parity_from_nova(1) == 1 and parity_from_nova("neg") == 1  # the sky as seen
    assert parity_from_nova(0) == -1 and parity_from_nova("0") == -1
    assert parity_from_nova(2) is None and parity_from_nova(None) is None
    for bad in (3, "up", True, [1]):
        with pytest.raises(StarnavError, match="parity must be"):
            parity_from_nova(bad)


def test_xylist_checks():
    with pytest.raises(StarnavError, match="differ in length"):
        XYList.make([1, 2], [1], 100, 100)
    with pytest.raises(StarnavError, match="lists of numbers"):
        XYList.make(["a"], [1], 100, 100)
    with pytest.raises(StarnavError, match="finite"):
        XYList.make([float("nan")], [1], 100, 100)
    with pytest.raises(StarnavError, match="image_width"):
        XYList.make([1], [1], None, 100)
    assert XYList.make([1.0], [2.0], 10, 10).xy.tolist() == [[0.5, 1.5]]


def test_solve_plate_image_and_list(tmp_path):
    """A real image with hints, then its own detections as a source list: both put the image
    centre within 60″ of the peers' reference, orientation = roll - 180°, parity "neg"."""
    ref = PEER_REFERENCE[LYRA]
    image = peer_image(LYRA)  # upstream's 16-bit TIFF
    hints = PlateHints(fov_range_deg=fov_range_from_scale("arcsecperpix", 35, 45, 1024),
                       ra_deg=ref["ra_deg"] + 3, dec_deg=ref["dec_deg"], radius_deg=8,
                       parity=1, downsample=2)  # fmt: skip
    res = solve_plate(image, hints)
    xy = XYList.make(*(res.xy[:40] + 0.5).T, 1024, 768)
    for r in (res, solve_plate(xy)):
        p = r.plate
        assert p is not None, r.reason
        assert _sep_arcsec(p.ra_deg, p.dec_deg, ref["ra_deg"], ref["dec_deg"]) < 60
        assert math.remainder(p.orientation_deg - (ref["roll_deg"] - 180), 360) == pytest.approx(
            0, abs=0.1
        )
        assert p.parity_name == "neg"
    assert tuple(res.plate.wcs.wcs.crpix) == (512.5, 384.5)  # the centre: --crpix-center holds
    written = write_plate_files(res, image, wcs=tmp_path / "a.wcs", new_fits=tmp_path / "a.new",
                                annotate=tmp_path / "a.png")  # fmt: skip
    assert set(written) == {"wcs", "new_fits", "annotate"}
    assert all(Path(p).stat().st_size > 0 for p in written.values())
    assert solve_plate(image, PlateHints(parity=-1)).plate is None  # the mirror sky: refused
