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
