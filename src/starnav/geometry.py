"""Unit vectors, angles and attitudes. Pure functions; radians inside, degrees where named.

Attitude convention (docs/conventions.md): ``R_cam_from_icrs`` has the camera axes in ICRS as rows
(x right, y down, z boresight). A mirrored camera (parity -1) has the same rows, which then
form a left-handed set (determinant -1), so that ``c = R @ s`` and the pinhole projection hold
for both parities. Roll is the position angle of image "up" (-y) from North through East.
"""

from __future__ import annotations

import math

import numpy as np

ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0


def radec_to_unit(ra_rad: np.ndarray | float, dec_rad: np.ndarray | float) -> np.ndarray:
    """ICRS unit vectors (..., 3) from right ascension and declination in radians."""
    ra = np.asarray(ra_rad, dtype=float)
    dec = np.asarray(dec_rad, dtype=float)
    cos_dec = np.cos(dec)
    return np.stack([cos_dec * np.cos(ra), cos_dec * np.sin(ra), np.sin(dec)], axis=-1)


def unit_to_radec(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Right ascension in [0, 2pi) and declination (radians) of vectors (..., 3)."""
    v = np.asarray(v, dtype=float)
    ra = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2.0 * np.pi)
    dec = np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))
    return ra, dec


def north_east(boresight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit North and East directions on the sky at a boresight unit vector."""
    ra, dec = unit_to_radec(boresight)
    east = np.array([-np.sin(ra), np.cos(ra), 0.0])
    north = np.array([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)])
    return north, east


def attitude_from_radec_roll(
    ra_deg: float, dec_deg: float, roll_deg: float, parity: int = 1
) -> np.ndarray:
    """``R_cam_from_icrs`` for a boresight at (RA, Dec) and a roll, all in degrees.

    parity +1 is the sky as seen (roll 0: North up, East left); -1 is the mirrored image.
    """
    z = radec_to_unit(np.radians(ra_deg), np.radians(dec_deg))
    north, east = north_east(z)
    roll = np.radians(roll_deg)
    up = np.cos(roll) * north + np.sin(roll) * east
    y = -up
    x = np.cross(y, z) if parity > 0 else np.cross(z, y)
    return np.vstack([x, y, z])


def radec_roll_from_attitude(R_cam_from_icrs: np.ndarray) -> tuple[float, float, float, int]:
    """(ra_deg, dec_deg, roll_deg, parity) of an attitude matrix; roll in [0, 360)."""
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = np.asarray(R_cam_from_icrs, dtype=float).tolist()
    # as unit_to_radec and north_east, on scalars (this runs once per solve)
    ra = math.atan2(z1, z0) % (2.0 * math.pi)
    dec = math.atan2(z2, math.hypot(z0, z1))
    east = (-math.sin(ra), math.cos(ra))  # z component 0
    north = (-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec))
    up = (-y0, -y1, -y2)
    up_east = up[0] * east[0] + up[1] * east[1]
    up_north = up[0] * north[0] + up[1] * north[1] + up[2] * north[2]
    roll = math.degrees(math.atan2(up_east, up_north)) % 360.0
    det = x0 * (y1 * z2 - y2 * z1) - x1 * (y0 * z2 - y2 * z0) + x2 * (y0 * z1 - y1 * z0)
    return math.degrees(ra), math.degrees(dec), roll, 1 if det > 0 else -1


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians between unit vectors (broadcasting over leading axes), stable at 0."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def chord_from_angle(angle_rad: float) -> float:
    """Straight-line distance between two unit vectors separated by an angle (radians)."""
    return 2.0 * np.sin(0.5 * angle_rad)


def attitude_difference_deg(R_a: np.ndarray, R_b: np.ndarray) -> tuple[float, float]:
    """(boresight separation, |rotation about the boresight|) in degrees between two attitudes.

    The roll difference is taken from the relative rotation ``R_a R_b^T`` (not from the
    difference of position angles, which is unstable near the celestial poles).
    """
    R_a = np.asarray(R_a, dtype=float)
    R_b = np.asarray(R_b, dtype=float)
    boresight = float(np.degrees(angle_between(R_a[2], R_b[2])))
    D = R_a @ R_b.T
    droll = np.degrees(np.arctan2(D[1, 0] - D[0, 1], D[0, 0] + D[1, 1]))
    return boresight, float(abs(droll))


def triple_product(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """a · (b × c) along the last axis: the orientation of three bearings (its sign is the
    parity of the triangle they make)."""
    return np.einsum("...i,...i->...", a, np.cross(b, c))
