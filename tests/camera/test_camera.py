import json

import numpy as np
import pytest

from starnav.camera import Camera, focal_px_from_fov
from starnav.errors import CameraError, StarnavError


def test_focal_from_fov_matches_contest_numbers():
    assert np.isclose(focal_px_from_fov(12.0, 512), 2435.68, atol=0.01)
    assert np.isclose(focal_px_from_fov(20.0, 1024), 2903.70, atol=0.01)


def test_principal_point_and_axes():
    cam = Camera.from_fov(12.0, 512)
    assert (cam.cx, cam.cy) == (256.0, 256.0)
    b = cam.pixels_to_bearings([[256.0, 256.0], [300.0, 256.0], [256.0, 300.0]])
    assert np.allclose(b[0], [0, 0, 1])
    assert b[1, 0] > 0 and np.isclose(b[1, 1], 0)  # x right
    assert b[2, 1] > 0 and np.isclose(b[2, 0], 0)  # y down


@pytest.mark.parametrize("k1,k2", [(0.0, 0.0), (-0.05, 0.01)])
def test_pixels_bearings_round_trip(k1, k2):
    cam = Camera(640, 480, 900.0, 321.5, 238.25, k1, k2)
    xy = np.random.default_rng(1).uniform([0, 0], [640, 480], (50, 2))
    assert np.allclose(cam.bearings_to_pixels(cam.pixels_to_bearings(xy)), xy, atol=1e-6)


def test_fov_round_trip_and_height_default():
    cam = Camera.from_fov(20.0, 1024)
    assert cam.height == 1024
    assert np.isclose(cam.fov_deg, 20.0)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(fov_deg=0.0, width=512),
        dict(fov_deg=200.0, width=512),
        dict(fov_deg=float("nan"), width=512),
        dict(fov_deg=12.0, width=0),
    ],
)
def test_bad_camera_raises(kwargs):
    with pytest.raises(CameraError) as err:
        Camera.from_fov(**kwargs)
    assert isinstance(err.value, StarnavError) and isinstance(err.value, ValueError)


# ---- the camera-model contract, over every registered model


def _model_examples():
    from starnav.camera import MODELS
    from starnav.camera import fisheye as fe

    examples = {
        "pinhole": [Camera(640, 480, 900.0, 321.5, 238.25, -0.05, 0.01)],
        # 190° across the width: directions behind the image plane
        "equidistant": [fe.Equidistant.from_fov(190.0, 800, 600), fe.Equidistant(600, 600, 180)],
        "equisolid": [fe.Equisolid(640, 480, 170.0, 330.0, 235.0, image_circle_deg=180.0)],
        "stereographic": [fe.Stereographic.from_fov(185.0, 640, 640)],
        "orthographic": [fe.Orthographic(640, 640, 330.0)],
        "kannala-brandt": [
            fe.KannalaBrandt(1024, 768, 300.0, 515.0, 380.0, k1=0.02, k2=-0.004, k3=0.001, k4=-1e-4)
        ],
    }
    return [(name, cam) for name in MODELS for cam in examples[name]]


@pytest.mark.parametrize(("name", "cam"), _model_examples())
def test_model_jacobians_match_finite_differences(name, cam):
    """d(pixel)/d(direction) and d(pixel)/d(intrinsics) of ``project_with_jacobian`` against
    central differences (the intrinsics through the model's own update rule)."""
    from starnav.camera import kernels as k

    rng = np.random.default_rng(4)
    c = cam.pixels_to_bearings(rng.uniform([0, 0], [cam.width, cam.height], (40, 2)))
    c = c[c[:, 2] > np.cos(cam.half_diagonal_rad - 0.01)][:20]  # inside the image circle
    assert len(c) >= 10
    xy, J_c, J_p = cam.project_with_jacobian(c)
    assert np.allclose(xy, cam.bearings_to_pixels(c))
    h = 1e-7
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        numeric = (cam.bearings_to_pixels(c + e) - cam.bearings_to_pixels(c - e)) / (2 * h)
        assert np.allclose(J_c[:, :, i], numeric, rtol=1e-5, atol=1e-3)
    n_free = 1 + k.n_coefficients(cam.model_code)
    assert not J_p[:, :, n_free:].any()  # columns of coefficients the model lacks
    free = np.zeros(J_p.shape[2], dtype=bool)
    free[:n_free] = True
    for i in range(n_free):
        step = np.zeros(n_free)
        step[i] = h
        up = type(cam).from_params(cam.width, cam.height, k.update(0, cam.params, step, free))
        down = type(cam).from_params(cam.width, cam.height, k.update(0, cam.params, -step, free))
        numeric = (up.bearings_to_pixels(c) - down.bearings_to_pixels(c)) / (2 * h)
        assert np.allclose(J_p[:, :, i], numeric, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize(("name", "cam"), _model_examples())
def test_model_file_form_round_trips(name, cam, tmp_path):
    from starnav.camera import load_camera, save_camera

    path = tmp_path / "cam.json"
    save_camera(path, cam, note="test")
    back = load_camera(path)
    assert back == cam and back.model == name
    assert np.allclose(back.pixels_to_bearings([[10.0, 20.0]]), cam.pixels_to_bearings([[10, 20]]))


def test_camera_file_errors_name_the_problem(tmp_path):
    from starnav.camera import load_camera

    cases = {
        '{"model": "fisheye9", "width": 10}': "unknown camera model 'fisheye9'",
        '{"width": 640, "height": 480, "focal_px": 900, "cx": 320, "cy": 240, "k1": 0}': "k2",
        '{"width": 640, "height": 480, "focal_px": 900, "cx": 320, "cy": 240, "k1": 0,'
        ' "k2": NaN}': "k2 must be finite",
    }
    for text, needle in cases.items():
        path = tmp_path / "cam.json"
        path.write_text(text)
        with pytest.raises(CameraError, match=needle):
            load_camera(path)


# ---- fisheye models


@pytest.mark.parametrize(
    ("name", "radius"),
    [
        ("equidistant", lambda f, t: f * t),
        ("equisolid", lambda f, t: 2 * f * np.sin(t / 2)),
        ("stereographic", lambda f, t: 2 * f * np.tan(t / 2)),
        ("orthographic", lambda f, t: f * np.sin(t)),
        ("kannala-brandt", lambda f, t: f * t * (1 + 0.01 * t**2 - 0.002 * t**4)),
    ],
)
def test_fisheye_radius_is_the_models_formula(name, radius):
    """A direction at θ from the axis and azimuth φ lands at (cx + r cos φ, cy + r sin φ)."""
    from starnav.camera import MODELS

    coefficients = {"k1": 0.01, "k2": -0.002} if name == "kannala-brandt" else {}
    cam = MODELS[name](1200, 1000, 250.0, 610.0, 490.0, **coefficients)
    top = np.radians(89.0 if name == "orthographic" else 95.0)  # 95°: behind the image plane
    theta = np.linspace(0.01, top, 25)
    phi = np.linspace(-3.0, 3.0, 25)
    c = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    r = radius(250.0, theta)
    expected = np.column_stack([610.0 + r * np.cos(phi), 490.0 + r * np.sin(phi)])
    assert np.allclose(cam.bearings_to_pixels(c), expected, atol=1e-9)
    assert np.allclose(cam.pixels_to_bearings(expected), c, atol=1e-9)


def test_fisheye_sees_behind_the_image_plane_within_its_circle():
    from starnav.camera import Equidistant

    cam = Equidistant.from_fov(190.0, 1000, 1000).with_circle(190.0)
    assert np.isclose(np.degrees(cam.half_diagonal_rad), 95.0)
    theta = np.radians([10.0, 80.0, 94.0, 96.0, 120.0])
    c = np.column_stack([np.sin(theta), np.zeros(5), np.cos(theta)])
    assert cam.sees(c).tolist() == [True, True, True, False, False]
    assert np.isclose(cam.fov_deg, 190.0)


def test_fisheye_camera_files(tmp_path):
    from starnav.camera import KannalaBrandt, load_camera

    base = '"width": 1000, "height": 800, "focal_px": 300, "cx": 500, "cy": 400'
    cases = {
        '{"model": "kannala-brandt", ' + base + ', "k1": 0, "k2": 0, "k3": 0}': "lacks k4",
        '{"model": "kannala-brandt", ' + base + ', "k1": 0, "k2": 0, "k3": 0, "k4": "x"}': (
            "k4 must be a number"
        ),
        # r(θ) peaks near 60° (300 px x 0.6), well inside the 640 px corner
        '{"model": "kannala-brandt", ' + base + ', "k1": -0.3, "k2": 0, "k3": 0, "k4": 0}': (
            "stops increasing"
        ),
        '{"model": "equisolid", ' + base + ', "image_circle_deg": 400}': "image_circle_deg",
        '{"model": "Equidistant", ' + base + "}": "unknown camera model 'Equidistant'",
    }
    for text, needle in cases.items():
        path = tmp_path / "cam.json"
        path.write_text(text)
        with pytest.raises(CameraError, match=needle):
            load_camera(path)
    path.write_text('{"model": "equidistant", ' + base + ', "image_circle_deg": 185}')
    cam = load_camera(path)
    assert cam.model == "equidistant" and cam.image_circle_deg == 185.0
    kb = KannalaBrandt(1000, 800, 300.0, k1=0.01)
    path.write_text(json.dumps(kb.to_dict()))
    assert load_camera(path) == kb
