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

    examples = {"pinhole": [Camera(640, 480, 900.0, 321.5, 238.25, -0.05, 0.01)]}
    return [(name, cam) for name in MODELS for cam in examples[name]]


@pytest.mark.parametrize(("name", "cam"), _model_examples())
def test_model_jacobians_match_finite_differences(name, cam):
    """d(pixel)/d(direction) and d(pixel)/d(intrinsics) of ``project_with_jacobian`` against
    central differences (the intrinsics through the model's own update rule)."""
    from starnav.camera import kernels as k

    rng = np.random.default_rng(4)
    c = cam.pixels_to_bearings(rng.uniform([0, 0], [cam.width, cam.height], (20, 2)))
    xy, J_c, J_p = cam.project_with_jacobian(c)
    assert np.allclose(xy, cam.bearings_to_pixels(c))
    h = 1e-7
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        numeric = (cam.bearings_to_pixels(c + e) - cam.bearings_to_pixels(c - e)) / (2 * h)
        assert np.allclose(J_c[:, :, i], numeric, rtol=1e-5, atol=1e-3)
    free = np.ones(J_p.shape[2], dtype=bool)
    for i in range(J_p.shape[2]):
        step = np.zeros(J_p.shape[2])
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
