"""A lens model is its class: the facts the rest of starnav asks (kind, how an unknown focal
length is found, field-of-view range, FITS projection, SIP order) live on it, and a class
defined here, registered, goes through camera files, the FITS writer, the renderer and the
command line without an entry anywhere else."""

from __future__ import annotations

import numpy as np
import pytest

from starnav.camera import (
    MODELS,
    Camera,
    Equisolid,
    load_camera,
    model_class,
    register_model,
    save_camera,
)
from starnav.errors import CameraError
from starnav.geometry import attitude_from_radec_roll, radec_to_unit
from starnav.output.wcs import choose_sip_order, fit_sip, projection, wcs_from_attitude


class Lambert(Equisolid):
    """A variant of the equisolid lens (its arithmetic, ``model_code``) with facts of its own."""

    model = "lambert-test"
    default_fov_range_deg = (150.0, 190.0)
    fov_limits_deg = (90.0, 360.0)
    fits_projection = "ZEA"


class Rectilinear(Camera):
    """A pinhole variant whose SIP polynomials stop at order 5."""

    model = "rectilinear-test"
    sip_max_order = 5


@pytest.fixture
def registered():
    """The two variants registered for one test, and forgotten after it."""
    before = dict(MODELS)
    for cls in (Lambert, Rectilinear):
        assert register_model(cls) is cls
    yield
    MODELS.clear()
    MODELS.update(before)


def test_built_in_models_declare_their_facts():
    facts = {
        name: (cls.kind, cls.scans_focal, cls.fits_projection, cls.sip_max_order)
        for name, cls in MODELS.items()
    }
    assert facts == {
        "pinhole": ("pinhole", False, "TAN", 7),
        "equidistant": ("fisheye", True, "ARC", 9),
        "equisolid": ("fisheye", True, "ZEA", 9),
        "stereographic": ("fisheye", True, "STG", 9),
        "orthographic": ("fisheye", True, "SIN", 9),
        "kannala-brandt": ("fisheye", True, "ARC", 9),
    }
    assert Camera.default_fov_range_deg == (5.0, 40.0) and Camera.fov_limits_deg == (0.625, 100.0)
    assert model_class("equisolid").default_fov_range_deg == (100.0, 200.0)
    assert model_class("kannala-brandt").fov_limits_deg == (10.0, 360.0)
    assert model_class("pinhole") is Camera
    with pytest.raises(CameraError, match="unknown lens model 'gnomonic'; known: pinhole, "):
        model_class("gnomonic")


def test_a_model_defined_here_is_known_by_its_name(registered, tmp_path):
    assert model_class("lambert-test") is Lambert and list(MODELS)[-2:] == [
        "lambert-test",
        "rectilinear-test",
    ]
    camera = Lambert.from_fov(180.0, 400, 300).with_circle(175.0)
    save_camera(tmp_path / "lambert.json", camera)
    again = load_camera(tmp_path / "lambert.json")
    assert type(again) is Lambert and again == camera
    xy = np.array([[200.0, 150.0], [30.0, 280.0]])  # the equisolid arithmetic
    equisolid = Equisolid(400, 300, camera.focal_px, image_circle_deg=175.0)
    assert np.array_equal(again.pixels_to_bearings(xy), equisolid.pixels_to_bearings(xy))
    register_model(Lambert)  # again: nothing changes
    assert model_class("lambert-test") is Lambert


def _pix2world_error_px(camera, wcs, R) -> float:
    """Largest angle (in px at the centre) between astropy's pixel -> sky and the camera's."""
    rng = np.random.default_rng(3)
    xy = rng.uniform([0, 0], [camera.width, camera.height], (2000, 2))
    bearings = camera.pixels_to_bearings(xy)
    inside = camera.sees(bearings)
    ra, dec = np.radians(wcs.all_pix2world(xy[inside] - 0.5, 0)).T
    error = np.linalg.norm(radec_to_unit(ra, dec) - bearings[inside] @ R, axis=1)
    return float(error.max()) * camera.focal_px


def test_a_model_defined_here_gets_its_fits_projection_and_sip_order(registered):
    R = attitude_from_radec_roll(120.0, -35.0, 20.0, 1)
    lambert = Lambert.from_fov(185.0, 500, 500).with_circle(185.0)
    wcs = wcs_from_attitude(R, lambert)
    assert projection(lambert) == "ZEA" and list(wcs.wcs.ctype) == ["RA---ZEA", "DEC--ZEA"]
    assert _pix2world_error_px(lambert, wcs, R) < 1e-6

    rectilinear = Rectilinear(800, 600, 700.0, k1=-0.08, k2=0.01)
    assert rectilinear.undistorted() == Rectilinear(800, 600, 700.0)
    order = choose_sip_order(rectilinear, max_error_px=1e-9)  # never good enough: its top
    assert (
        order
        == Rectilinear.sip_max_order
        == 5
        < choose_sip_order(Camera(800, 600, 700.0, k1=-0.08, k2=0.01), max_error_px=1e-9)
    )
    wcs = wcs_from_attitude(R, rectilinear, sip_order=order)
    assert list(wcs.wcs.ctype) == ["RA---TAN-SIP", "DEC--TAN-SIP"] and wcs.sip.a_order == 5
    assert (
        _pix2world_error_px(rectilinear, wcs, R) < 2.0 * fit_sip(rectilinear, order=5).max_error_px
    )


def test_a_model_defined_here_is_rendered_and_offered_by_its_kind(registered):
    from starnav.cli import build_parser
    from starnav.simulate.render import (
        FISHEYE_VIGNETTING_POWER,
        RenderSettings,
        imaged_directions,
        pixel_illumination,
    )

    lambert = Lambert.from_fov(200.0, 120, 80).with_circle(150.0)  # a circle on the sensor
    assert RenderSettings().vignetting_power_for(lambert) == FISHEYE_VIGNETTING_POWER
    assert RenderSettings().vignetting_power_for(Rectilinear(120, 80, 100.0)) == 0.0
    behind = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    assert imaged_directions(lambert, behind).tolist() == [False, True]
    corners = pixel_illumination(lambert, 0.0)
    assert corners is not None and corners[0, 0] == 0.0 < corners[40, 60]
    assert pixel_illumination(Rectilinear(120, 80, 100.0), 0.0) is None

    args = build_parser().parse_args(["identify", "stars.csv", "--lens", "lambert-test"])
    assert model_class(args.lens).scans_focal and not model_class("rectilinear-test").scans_focal


@pytest.mark.parametrize(
    "facts, complaint",
    [
        ({"kind": "catadioptric"}, "kind 'catadioptric' is not one of"),
        ({"scans_focal": 1}, "scans_focal is not True or False"),
        ({"fov_limits_deg": (10.0, 400.0)}, "fov_limits_deg .* not a range within 0..360"),
        ({"default_fov_range_deg": (5.0, 20.0)}, r"default_fov_range_deg .* within \(10.0, 360"),
        ({"fits_projection": ""}, "fits_projection '' is not a FITS projection code"),
        ({"sip_max_order": 1}, "sip_max_order 1 is not an order of 2 or more"),
    ],
)
def test_a_model_with_a_missing_or_bad_fact_is_refused(facts, complaint):
    bad = type("Bad", (Equisolid,), {"model": "bad-test", **facts})
    with pytest.raises(CameraError, match=f"lens model 'bad-test' \\(Bad\\): {complaint}"):
        register_model(bad)
    assert "bad-test" not in MODELS
    clash = type("Clash", (Equisolid,), {"model": "equisolid"})
    with pytest.raises(CameraError, match="'equisolid' is taken by Equisolid"):
        register_model(clash)
