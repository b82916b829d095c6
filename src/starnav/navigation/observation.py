"""The observation file of a celestial fix: UTC, gravity in the body frame, the atmosphere, and
what each star camera saw.

Body frame: x forward, y right, z down. ``gravity_body`` is the unit vector of gravity (pointing
down) in it. A camera is mounted by ``R_cam_from_body`` (rows = the camera's x right, y down,
z boresight axes in body coordinates) or by ``azimuth_deg`` / ``elevation_deg`` of its boresight
in the body frame: z = (cos el cos az, cos el sin az, -sin el), x = (-sin az, cos az, 0),
y = z × x.

What it saw is either ``stars``, pixel centroids [x, y] (origin top-left, x right, y down), or
an ``image`` file (a path, relative ones from the observation file's folder) whose stars are
detected here (``navigation.images``) and from then on are that camera's star list. Its lens:
a ``camera`` (a camera file's path or the object of one: any model of ``starnav.camera``), or
a horizontal ``fov_deg`` (a pinhole), or neither (the field of view is searched, as ``starnav
solve`` does). The image size comes from the image, or the camera, or ``width``/``height``; where
two of them are given they must agree.

``utc`` may be left out when images are given: it is then the time the images record (FITS
DATE-OBS; EXIF DateTimeOriginal, local time, with ``utc_offset_hours`` of the camera entry or the
top level), which must agree within a second across images.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from astropy.time import Time, TimeDelta

from starnav.camera import CameraModel, camera_from_dict, load_camera
from starnav.detect.header import ImageTime, image_time
from starnav.errors import StarnavError, shown
from starnav.navigation.frames import parse_utc
from starnav.navigation.images import image_stars

STANDARD_PRESSURE_HPA = 1013.25
STANDARD_TEMPERATURE_C = 15.0
MAX_TIME_SPREAD_S = 1.0  # images whose times differ by more do not make one observation
_TOP_KEYS = {
    "utc",
    "utc_offset_hours",
    "gravity_body",
    "gravity_sigma_deg",
    "pressure_hpa",
    "temperature_c",
    "cameras",
}
_CAMERA_KEYS = {
    "name",
    "camera",
    "fov_deg",
    "width",
    "height",
    "R_cam_from_body",
    "azimuth_deg",
    "elevation_deg",
    "stars",
    "image",
    "utc_offset_hours",
}


class ObservationError(StarnavError):
    """An observation file that cannot be used, with what is wrong in it."""


@dataclass(frozen=True, eq=False)
class CameraView:
    """One star camera: ``name``, horizontal ``fov_deg`` (None: unknown, to be searched),
    image ``width``/``height`` (px), its mount ``R_cam_from_body`` (3, 3) and the star
    centroids ``xy`` (n, 2, px, brightest first). ``camera``: its lens model when one was given
    (then ``fov_deg`` is the model's); ``image``: the file the stars were detected in."""

    name: str
    fov_deg: float | None
    width: int
    height: int
    R_cam_from_body: np.ndarray
    xy: np.ndarray
    camera: CameraModel | None = None
    image: str | None = None


@dataclass(frozen=True, eq=False)
class Observation:
    """``utc`` (ISO 8601 string), ``gravity_body`` (unit vector, body frame), the air
    (``pressure_hpa``, 0 = no refraction; ``temperature_c``) and the ``cameras``;
    ``utc_source``: where the time came from ("file", or the images' header or tag);
    ``gravity_sigma_deg``: the gravity direction's stated 1-sigma error (degrees; 0: none)."""

    utc: str
    gravity_body: np.ndarray
    pressure_hpa: float
    temperature_c: float
    cameras: tuple[CameraView, ...]
    utc_source: str = "file"
    gravity_sigma_deg: float = 0.0


def mount_from_azimuth_elevation(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """``R_cam_from_body`` of a camera whose boresight has this azimuth (from body x towards
    body y) and elevation (above the body's x-y plane, i.e. towards -z), degrees."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    z = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    x = np.array([-np.sin(az), np.cos(az), 0.0])
    return np.vstack([x, np.cross(z, x), z])


def _number(value, what: str, *, low: float | None = None, high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ObservationError(f"{what} must be a number, got {shown(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ObservationError(f"{what} must be between {low:g} and {high:g}, got {shown(value)}")
    return float(value)


def _vector(value, what: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ObservationError(
            f"{what} must be numbers of shape {shape}, got {shown(value)}"
        ) from None
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise ObservationError(
            f"{what} must be finite numbers of shape {shape}, got {shown(value)}"
        )
    return array


def _mount(entry: dict, name: str) -> np.ndarray:
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
        return R
    if "azimuth_deg" in entry and "elevation_deg" in entry:
        return mount_from_azimuth_elevation(
            _number(entry["azimuth_deg"], f"{name}: azimuth_deg", low=-360, high=720),
            _number(entry["elevation_deg"], f"{name}: elevation_deg", low=-90, high=90),
        )
    raise ObservationError(
        f"{name}: the mount is missing: give R_cam_from_body or azimuth_deg and elevation_deg"
    )


def _lens(entry: dict, name: str, base_dir: Path) -> tuple[CameraModel | None, float | None]:
    """The camera model given (a file or an object) or the horizontal FOV (degrees); both
    None when the field of view is to be searched."""
    if "camera" in entry:
        if "fov_deg" in entry:
            raise ObservationError(f"{name}: give either 'camera' or 'fov_deg', not both")
        given = entry["camera"]
        if not isinstance(given, str | dict):
            raise ObservationError(
                f"{name}: 'camera' must be a camera file's path or a camera object, got {given!r}"
            )
        try:
            if isinstance(given, str):
                camera = load_camera(base_dir / given)
            else:
                camera = camera_from_dict(given, "its camera")
        except StarnavError as exc:
            raise ObservationError(f"{name}: {exc}") from None
        return camera, camera.fov_deg
    if "fov_deg" in entry:
        return None, _number(entry["fov_deg"], f"{name}: fov_deg", low=0.1, high=170.0)
    return None, None


def _size(entry: dict, name: str, known: tuple[int, int] | None, what: str) -> tuple[int, int]:
    """Width and height (px): those ``known`` (from ``what``), which a given ``width``/
    ``height`` must equal, or the given ones."""
    given = {}
    for key in ("width", "height"):
        if key in entry:
            given[key] = int(_number(entry[key], f"{name}: {key}", low=1, high=1e6))
        elif known is None:
            raise ObservationError(f"{name}: '{key}' is missing")
    if known is None:
        return given["width"], given["height"]
    for key, value in zip(("width", "height"), known, strict=True):
        if key in given and given[key] != value:
            raise ObservationError(f"{name}: {key} {given[key]} px, but {what} is {value} px")
    return known


def _camera(entry, n: int, base_dir: Path) -> CameraView:
    if not isinstance(entry, dict):
        raise ObservationError(f"camera {n}: expected an object, got {entry!r}")
    name = str(entry.get("name", f"camera {n}"))
    unknown = set(entry) - _CAMERA_KEYS
    if unknown:
        raise ObservationError(
            f"{name}: unknown keys {sorted(unknown)} (known: {', '.join(sorted(_CAMERA_KEYS))})"
        )
    if "stars" in entry and "image" in entry:
        raise ObservationError(f"{name}: give either 'stars' or 'image', not both")
    if "stars" not in entry and "image" not in entry:
        raise ObservationError(
            f"{name}: 'stars' (a list of [x, y] centroids) or 'image' (a file) is missing"
        )
    R = _mount(entry, name)
    camera, fov = _lens(entry, name, base_dir)
    if "image" in entry:
        path = entry["image"]
        if not isinstance(path, str) or not path:
            raise ObservationError(f"{name}: 'image' must be a file path, got {path!r}")
        file = base_dir / path
        try:
            found = image_stars(file, "pinhole" if camera is None else camera.model)
        except StarnavError as exc:
            raise ObservationError(f"{name}: {exc}") from None
        if camera is not None and (camera.width, camera.height) != (found.width, found.height):
            raise ObservationError(
                f"{name}: the camera is for {camera.width} x {camera.height} px images, "
                f"{path} is {found.width} x {found.height} px"
            )
        width, height = _size(entry, name, (found.width, found.height), f"the image {path}")
        return CameraView(name, fov, width, height, R, found.xy, camera, str(file))
    known = None if camera is None else (camera.width, camera.height)
    width, height = _size(entry, name, known, "the camera's")
    stars = entry["stars"]
    if not isinstance(stars, list):
        raise ObservationError(f"{name}: 'stars' must be a list of [x, y], got {stars!r}")
    xy = _vector(stars, f"{name}: stars", (len(stars), 2)) if stars else np.empty((0, 2))
    return CameraView(name, fov, width, height, R, xy, camera)


def _offset_hours(entry: dict, data: dict, name: str) -> float | None:
    """The camera's ``utc_offset_hours`` (local time minus UTC), else the top level's."""
    for where, holder in ((f"{name}: utc_offset_hours", entry), ("utc_offset_hours", data)):
        if "utc_offset_hours" in holder:
            return _number(holder["utc_offset_hours"], where, low=-14, high=14)
    return None


def _utc_from_images(data: dict, views: tuple[CameraView, ...]) -> tuple[str, str]:
    """The UTC (ISO 8601) the images record, and where it came from."""
    times: list[tuple[str, ImageTime, Time]] = []
    for entry, view in zip(data["cameras"], views, strict=True):
        if view.image is None:
            continue
        try:
            found = image_time(view.image)
        except StarnavError as exc:
            raise ObservationError(f"{view.name}: {exc}") from None
        if found is None:
            continue
        t = found.time
        if found.local:
            offset = _offset_hours(entry, data, view.name)
            if offset is None:
                raise ObservationError(
                    f"{view.name}: the {found.source} {found.text!r} of its image is local "
                    "time: give 'utc_offset_hours' (local minus UTC, e.g. 2 for UTC+2) in the "
                    "camera or at the top level, or give 'utc'"
                )
            t = t - TimeDelta(offset * 3600.0, format="sec")
        times.append((view.name, found, t))
    if not times:
        raise ObservationError(
            "'utc' is missing (ISO 8601, e.g. 2026-03-14T21:30:00Z) and no image records its "
            "time (FITS DATE-OBS, EXIF DateTimeOriginal)"
        )
    first = times[0][2]
    seconds = np.array([(t - first).sec for _, _, t in times])
    spread_s = float(np.ptp(seconds))
    if spread_s > MAX_TIME_SPREAD_S:
        early, late = times[int(np.argmin(seconds))], times[int(np.argmax(seconds))]
        raise ObservationError(
            f"the images' times differ by {spread_s:.1f} s ({early[0]}: {early[2].isot}Z, "
            f"{late[0]}: {late[2].isot}Z; at most {MAX_TIME_SPREAD_S:g} s): give 'utc'"
        )
    mean = first + TimeDelta(float(np.mean(seconds)), format="sec")
    sources = ", ".join(f"{name}: {found.source}" for name, found, _ in times)
    return f"{mean.utc.isot}Z", f"images ({sources})"


def parse_observation(data, base_dir: str | Path | None = None) -> Observation:
    """Check an observation (the parsed JSON) and return it as an ``Observation``; image
    files are read and their stars detected. ``base_dir``: where relative image and camera
    paths start (default: the working directory)."""
    if not isinstance(data, dict):
        raise ObservationError("the observation must be a JSON object")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ObservationError(
            f"unknown keys {sorted(unknown)} (known: {', '.join(sorted(_TOP_KEYS))})"
        )
    utc = data.get("utc")
    if utc is not None:
        if not isinstance(utc, str):
            raise ObservationError(f"'utc' must be an ISO 8601 string, got {utc!r}")
        try:
            parse_utc(utc)
        except StarnavError as exc:
            raise ObservationError(str(exc)) from None
    if "utc_offset_hours" in data:
        _number(data["utc_offset_hours"], "utc_offset_hours", low=-14, high=14)
    if "gravity_body" not in data:
        raise ObservationError("'gravity_body' is missing (unit vector of gravity, body frame)")
    g = _vector(data["gravity_body"], "gravity_body", (3,))
    norm = float(np.linalg.norm(g))
    if norm < 1e-6:
        raise ObservationError("gravity_body is the zero vector: it must give the down direction")
    gravity_sigma = _number(data.get("gravity_sigma_deg", 0.0), "gravity_sigma_deg", low=0, high=30)
    pressure = _number(
        data.get("pressure_hpa", STANDARD_PRESSURE_HPA), "pressure_hpa", low=0, high=1200
    )
    temperature = _number(
        data.get("temperature_c", STANDARD_TEMPERATURE_C), "temperature_c", low=-90, high=60
    )
    cameras = data.get("cameras")
    if not isinstance(cameras, list) or not cameras:
        raise ObservationError("'cameras' must be a non-empty list of camera objects")
    base = Path(".") if base_dir is None else Path(base_dir)
    views = tuple(_camera(entry, n, base) for n, entry in enumerate(cameras, start=1))
    names = [v.name for v in views]
    if len(set(names)) != len(names):
        raise ObservationError(f"camera names must differ, got {names}")
    source = "file"
    if utc is None:
        if not any(v.image for v in views):
            raise ObservationError("'utc' is missing (ISO 8601, e.g. 2026-03-14T21:30:00Z)")
        utc, source = _utc_from_images(data, views)
        try:
            parse_utc(utc)
        except StarnavError as exc:
            raise ObservationError(f"the images' time: {exc}") from None
    return Observation(utc, g / norm, pressure, temperature, views, source, gravity_sigma)


def read_observation(path: str | Path) -> Observation:
    """Read and check an observation JSON file (image and camera paths in it are relative to
    the file's folder)."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ObservationError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ObservationError(f"{str(path)!r} is not valid JSON: {exc}") from None
    return parse_observation(data, Path(path).parent)
