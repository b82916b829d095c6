"""The observation file of a celestial fix: UTC, gravity in the body frame, the atmosphere, and
what each star camera saw.

Body frame: x forward, y right, z down. ``gravity_body`` is the unit vector of gravity (pointing
down) in it. A camera is mounted by ``R_cam_from_body`` (rows = the camera's x right, y down,
z boresight axes in body coordinates) or by ``azimuth_deg`` / ``elevation_deg`` of its boresight
in the body frame: z = (cos el cos az, cos el sin az, -sin el), x = (-sin az, cos az, 0),
y = z × x. Its ``stars`` are pixel centroids [x, y] (origin top-left, x right, y down).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.errors import StarnavError
from starnav.navigation.frames import parse_utc

STANDARD_PRESSURE_HPA = 1013.25
STANDARD_TEMPERATURE_C = 15.0
_TOP_KEYS = {"utc", "gravity_body", "pressure_hpa", "temperature_c", "cameras"}
_CAMERA_KEYS = {
    "name",
    "fov_deg",
    "width",
    "height",
    "R_cam_from_body",
    "azimuth_deg",
    "elevation_deg",
    "stars",
    "image",
}


class ObservationError(StarnavError):
    """An observation file that cannot be used, with what is wrong in it."""


@dataclass(frozen=True, eq=False)
class CameraView:
    """One star camera: ``name``, horizontal ``fov_deg``, image ``width``/``height`` (px),
    its mount ``R_cam_from_body`` (3, 3) and the star centroids ``xy`` (n, 2, px)."""

    name: str
    fov_deg: float
    width: int
    height: int
    R_cam_from_body: np.ndarray
    xy: np.ndarray


@dataclass(frozen=True, eq=False)
class Observation:
    """``utc`` (ISO 8601 string), ``gravity_body`` (unit vector, body frame), the air
    (``pressure_hpa``, 0 = no refraction; ``temperature_c``) and the ``cameras``."""

    utc: str
    gravity_body: np.ndarray
    pressure_hpa: float
    temperature_c: float
    cameras: tuple[CameraView, ...]


def mount_from_azimuth_elevation(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """``R_cam_from_body`` of a camera whose boresight has this azimuth (from body x towards
    body y) and elevation (above the body's x-y plane, i.e. towards -z), degrees."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    z = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    x = np.array([-np.sin(az), np.cos(az), 0.0])
    return np.vstack([x, np.cross(z, x), z])


def _number(value, what: str, *, low: float | None = None, high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ObservationError(f"{what} must be a number, got {value!r}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ObservationError(f"{what} must be between {low:g} and {high:g}, got {value!r}")
    return float(value)


def _vector(value, what: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ObservationError(f"{what} must be numbers of shape {shape}, got {value!r}") from None
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise ObservationError(f"{what} must be finite numbers of shape {shape}, got {value!r}")
    return array


def _camera(entry, n: int) -> CameraView:
    if not isinstance(entry, dict):
        raise ObservationError(f"camera {n}: expected an object, got {entry!r}")
    name = str(entry.get("name", f"camera {n}"))
    unknown = set(entry) - _CAMERA_KEYS
    if unknown:
        raise ObservationError(
            f"{name}: unknown keys {sorted(unknown)} (known: {', '.join(sorted(_CAMERA_KEYS))})"
        )
    for key in ("fov_deg", "width", "height"):
        if key not in entry:
            raise ObservationError(f"{name}: '{key}' is missing")
    fov = _number(entry["fov_deg"], f"{name}: fov_deg", low=0.1, high=170.0)
    width = _number(entry["width"], f"{name}: width", low=1, high=1e6)
    height = _number(entry["height"], f"{name}: height", low=1, high=1e6)
    if "R_cam_from_body" in entry:
        if "azimuth_deg" in entry or "elevation_deg" in entry:
            raise ObservationError(
                f"{name}: give either R_cam_from_body or azimuth_deg/elevation_deg, not both"
            )
        R = _vector(entry["R_cam_from_body"], f"{name}: R_cam_from_body", (3, 3))
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise ObservationError(f"{name}: R_cam_from_body is not a rotation (R R^T != I)")
        if np.linalg.det(R) < 0:
            raise ObservationError(f"{name}: R_cam_from_body has determinant -1 (a mirror)")
    elif "azimuth_deg" in entry and "elevation_deg" in entry:
        R = mount_from_azimuth_elevation(
            _number(entry["azimuth_deg"], f"{name}: azimuth_deg", low=-360, high=720),
            _number(entry["elevation_deg"], f"{name}: elevation_deg", low=-90, high=90),
        )
    else:
        raise ObservationError(
            f"{name}: the mount is missing: give R_cam_from_body or azimuth_deg and elevation_deg"
        )
    if "image" in entry:
        raise ObservationError(
            f"{name}: starnav locate takes star lists, not images: give 'stars' as [x, y] "
            "pixel centroids (starnav solve detects the stars of an image)"
        )
    if "stars" not in entry:
        raise ObservationError(f"{name}: 'stars' is missing (a list of [x, y] centroids)")
    stars = entry["stars"]
    if not isinstance(stars, list):
        raise ObservationError(f"{name}: 'stars' must be a list of [x, y], got {stars!r}")
    xy = _vector(stars, f"{name}: stars", (len(stars), 2)) if stars else np.empty((0, 2))
    return CameraView(name, fov, int(width), int(height), R, xy)


def parse_observation(data) -> Observation:
    """Check an observation (the parsed JSON) and return it as an ``Observation``."""
    if not isinstance(data, dict):
        raise ObservationError("the observation must be a JSON object")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ObservationError(
            f"unknown keys {sorted(unknown)} (known: {', '.join(sorted(_TOP_KEYS))})"
        )
    if "utc" not in data:
        raise ObservationError("'utc' is missing (ISO 8601, e.g. 2026-03-14T21:30:00Z)")
    utc = data["utc"]
    if not isinstance(utc, str):
        raise ObservationError(f"'utc' must be an ISO 8601 string, got {utc!r}")
    try:
        parse_utc(utc)
    except StarnavError as exc:
        raise ObservationError(str(exc)) from None
    if "gravity_body" not in data:
        raise ObservationError("'gravity_body' is missing (unit vector of gravity, body frame)")
    g = _vector(data["gravity_body"], "gravity_body", (3,))
    norm = float(np.linalg.norm(g))
    if norm < 1e-6:
        raise ObservationError("gravity_body is the zero vector: it must give the down direction")
    pressure = _number(
        data.get("pressure_hpa", STANDARD_PRESSURE_HPA), "pressure_hpa", low=0, high=1200
    )
    temperature = _number(
        data.get("temperature_c", STANDARD_TEMPERATURE_C), "temperature_c", low=-90, high=60
    )
    cameras = data.get("cameras")
    if not isinstance(cameras, list) or not cameras:
        raise ObservationError("'cameras' must be a non-empty list of camera objects")
    views = tuple(_camera(entry, n) for n, entry in enumerate(cameras, start=1))
    names = [v.name for v in views]
    if len(set(names)) != len(names):
        raise ObservationError(f"camera names must differ, got {names}")
    return Observation(utc, g / norm, pressure, temperature, views)


def read_observation(path: str | Path) -> Observation:
    """Read and check an observation JSON file."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ObservationError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ObservationError(f"{str(path)!r} is not valid JSON: {exc}") from None
    return parse_observation(data)
