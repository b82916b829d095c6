import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from starnav.geometry import (
    angle_between,
    attitude_difference_deg,
    attitude_from_radec_roll,
    radec_roll_from_attitude,
    radec_to_unit,
)


@given(
    ra=st.floats(0.0, 359.999),
    dec=st.floats(-89.9, 89.9),
    roll=st.floats(0.0, 359.999),
    parity=st.sampled_from([1, -1]),
)
def test_attitude_round_trip(ra, dec, roll, parity):
    R = attitude_from_radec_roll(ra, dec, roll, parity)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), parity)
    ra2, dec2, roll2, parity2 = radec_roll_from_attitude(R)
    assert parity2 == parity
    assert abs((ra2 - ra + 180) % 360 - 180) < 1e-7
    assert abs(dec2 - dec) < 1e-7
    assert abs((roll2 - roll + 180) % 360 - 180) < 1e-6


def test_roll_zero_puts_north_up_and_east_left():
    R = attitude_from_radec_roll(30.0, 10.0, 0.0)
    north_of_boresight = radec_to_unit(np.radians(30.0), np.radians(10.5))
    east_of_boresight = radec_to_unit(np.radians(30.5), np.radians(10.0))
    c_north = R @ north_of_boresight
    c_east = R @ east_of_boresight
    assert c_north[1] < 0 and abs(c_north[0]) < 1e-3 * abs(c_north[1])  # up = -y
    assert c_east[0] < 0  # East to the left
    # roll 90: image up points East
    c = attitude_from_radec_roll(30.0, 10.0, 90.0) @ east_of_boresight
    assert c[1] < 0


def test_mirrored_image_flips_east():
    R = attitude_from_radec_roll(30.0, 10.0, 0.0, parity=-1)
    c_east = R @ radec_to_unit(np.radians(30.5), np.radians(10.0))
    assert c_east[0] > 0


def test_angle_between_small_and_opposite():
    a = radec_to_unit(0.0, 0.0)
    b = radec_to_unit(1e-9, 0.0)
    assert np.isclose(angle_between(a, b), 1e-9, rtol=1e-6)
    assert np.isclose(angle_between(a, -a), np.pi)


def test_attitude_difference():
    R1 = attitude_from_radec_roll(10.0, 0.0, 5.0)
    R2 = attitude_from_radec_roll(10.0, 1.0, 7.0)
    boresight, roll = attitude_difference_deg(R1, R2)
    assert np.isclose(boresight, 1.0, atol=1e-9)
    assert np.isclose(roll, 2.0, atol=0.05)


def test_roll_difference_is_stable_at_the_pole():
    """2 arcsec of tilt at Dec 89.9995° swings the position angle, not the roll error."""
    R1 = attitude_from_radec_roll(10.0, 89.9995, 30.0)
    tilt = np.radians(2.0 / 3600.0)
    c, s = np.cos(tilt), np.sin(tilt)
    R2 = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ R1
    boresight, roll = attitude_difference_deg(R1, R2)
    assert boresight == pytest.approx(2.0 / 3600.0, rel=1e-3)
    assert roll < 1e-6
