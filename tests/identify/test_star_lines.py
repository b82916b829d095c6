"""Star-line identification: the line angles and options. (Solve rates and safety:
test_identify_algorithms.py.)"""

import numpy as np
import pytest

from starnav.camera import Camera
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll
from starnav.identify import make_identifier
from starnav.identify.star_lines import StarLines, line_angles

ALGORITHM = "star-lines"
CAMERA = Camera.from_fov(12.0, 512)
MIRROR = np.diag([1.0, -1.0, 1.0])


def test_line_angles_turn_with_nothing_and_flip_in_a_mirror():
    rng = np.random.default_rng(3)
    bearings = CAMERA.pixels_to_bearings(rng.uniform(0, 512, (6, 2)))
    others = np.arange(2, 6)
    theta = line_angles(bearings, 0, 1, others)
    R = attitude_from_radec_roll(33.0, -47.0, 121.0)  # any rotation of the whole field
    np.testing.assert_allclose(line_angles(bearings @ R.T, 0, 1, others), theta, atol=1e-12)
    np.testing.assert_allclose(line_angles(bearings @ MIRROR, 0, 1, others), -theta, atol=1e-12)
    # on the image: a star at right angles to the reference arc, clockwise seen from the
    # camera (x right, y down) is +90°
    square = CAMERA.pixels_to_bearings(np.array([[256.0, 256], [356, 256], [256, 356]]))
    assert np.degrees(line_angles(square, 0, 1, np.array([2]))[0]) == pytest.approx(90, abs=0.1)


def test_bad_options_are_refused():
    for bad in ({"neighbors": 1}, {"neighbors": 2.5}, {"tests_per_star": 0}):
        with pytest.raises(StarnavError):
            StarLines(**bad)
    with pytest.raises(StarnavError, match="neighbors"):
        make_identifier(ALGORITHM, neighbors=0)
