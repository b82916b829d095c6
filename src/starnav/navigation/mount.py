"""A fixed camera's mount: its orientation relative to the local horizon of its site, which
turns a UTC into the attitude the camera has then (an all-sky camera on a roof).

The orientation is ``R_cam_from_enu``: camera-frame vectors from (East, North, Up) ones at
the site (geodetic WGS84). ``fit_mount`` finds it from solved frames (their attitudes and UTCs)
by Wahba's problem between the apparent topocentric directions of reference points of the sky
(astropy, ``navigation.frames``; no refraction) and the same points through each frame's
attitude; a mirrored camera keeps its parity (a determinant of -1). ``predict_attitude`` goes
the other way: ``R_cam_from_icrs`` at a UTC. The camera file holds it under ``"mount"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.catalog.sky import Site
from starnav.errors import StarnavError
from starnav.navigation.frames import enu_directions, parse_utc

# reference points of the sky (RA, Dec degrees): the rotation ICRS -> ENU at a time is the
# one that carries them, spread over the sphere so it is well determined
_REFERENCE_RADEC_DEG = np.array(
    [(0.0, 0.0), (90.0, 0.0), (180.0, 0.0), (270.0, 0.0), (0.0, 89.0), (0.0, -89.0)]
)


@dataclass(frozen=True)
class Mount:
    """``R_cam_from_enu`` (3x3; determinant -1 for a mirrored camera) of a camera at
    ``lat_deg``, ``lon_deg`` (degrees, geodetic WGS84), ``height_m`` (metres);
    ``spread_deg``: the largest angle between one frame's orientation and the fitted one
    (0 for one frame)."""

    R_cam_from_enu: np.ndarray
    lat_deg: float
    lon_deg: float
    height_m: float = 0.0
    spread_deg: float = 0.0

    @property
    def zenith_cam(self) -> np.ndarray:
        """The zenith as a unit vector in the camera frame."""
        return self.R_cam_from_enu[:, 2].copy()

    def to_dict(self) -> dict:
        """The camera file's ``"mount"`` object."""
        z = self.zenith_cam
        return {
            "R_cam_from_enu": self.R_cam_from_enu.tolist(),
            "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg,
            "height_m": self.height_m,
            "spread_deg": self.spread_deg,
            "zenith_from_axis_deg": math.degrees(math.acos(max(-1.0, min(1.0, z[2])))),
        }

    @classmethod
    def from_dict(cls, data: object, where: str = "mount") -> Mount:
        """The mount of a camera file's ``"mount"`` object (one-line errors)."""
        if not isinstance(data, dict):
            raise StarnavError(f"{where} must be a JSON object")
        try:
            R = np.array(data["R_cam_from_enu"], dtype=float)
            lat, lon = float(data["lat_deg"]), float(data["lon_deg"])
            height = float(data.get("height_m", 0.0))
        except (KeyError, TypeError, ValueError) as exc:
            raise StarnavError(f"{where}: needs R_cam_from_enu, lat_deg, lon_deg ({exc})") from None
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise StarnavError(f"{where}: R_cam_from_enu is not a 3x3 rotation")
        if not (-90.0 <= lat <= 90.0 and np.isfinite(lon) and np.isfinite(height)):
            raise StarnavError(f"{where}: lat_deg {lat} / lon_deg {lon} is not a site")
        return cls(R, lat, lon, height, float(data.get("spread_deg", 0.0)))


def check_site(lat_deg: float, lon_deg: float, height_m: float = 0.0) -> None:
    """A one-line error for a site that cannot be (``catalog.sky.Site`` checks it)."""
    Site(lat_deg, lon_deg, height_m)


def R_enu_from_icrs(time, lat_deg: float, lon_deg: float, height_m: float = 0.0) -> np.ndarray:
    """The rotation (3x3) from ICRS to the site's (East, North, Up) at ``time`` (an astropy
    ``Time`` or an ISO 8601 UTC string): the apparent places of the reference points (with
    aberration; no refraction) fitted by a rotation (residual below 30″)."""
    if isinstance(time, str):
        time = parse_utc(time)
    ra, dec = _REFERENCE_RADEC_DEG.T
    enu = enu_directions(ra, dec, time, lat_deg=lat_deg, lon_deg=lon_deg, height_m=height_m)
    icrs = np.column_stack(
        [
            np.cos(np.radians(dec)) * np.cos(np.radians(ra)),
            np.cos(np.radians(dec)) * np.sin(np.radians(ra)),
            np.sin(np.radians(dec)),
        ]
    )
    return _rotation(enu, icrs, parity=1)


def _rotation(b: np.ndarray, a: np.ndarray, parity: int) -> np.ndarray:
    """The rotation (``parity`` -1: a rotation times a mirror) R minimising Σ|b_i - R a_i|²."""
    U, _, Vt = np.linalg.svd(b.T @ a)
    d = np.linalg.det(U @ Vt)
    D = np.diag([1.0, 1.0, d * parity])
    return U @ D @ Vt


def fit_mount(
    attitudes: Sequence[np.ndarray],
    times: Sequence,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
) -> Mount:
    """The fixed orientation of a camera whose frames have ``attitudes`` (``R_cam_from_icrs``)
    at ``times`` (astropy ``Time`` or ISO 8601 UTC strings), at the site."""
    check_site(lat_deg, lon_deg, height_m)
    if not attitudes or len(attitudes) != len(times):
        raise StarnavError("a mount needs one time per solved frame")
    parity = 1 if np.linalg.det(attitudes[0]) > 0 else -1
    each = [
        R @ R_enu_from_icrs(t, lat_deg, lon_deg, height_m).T
        for R, t in zip(attitudes, times, strict=True)
    ]  # R_cam_from_enu of each frame
    # the mean orientation: the rotation carrying the ENU axes to the frames' mean images
    axes = np.eye(3)
    mean = _rotation(np.vstack([(R @ axes).T for R in each]), np.vstack([axes] * len(each)), parity)
    spread = max(_angle_deg(R, mean) for R in each)
    return Mount(mean, float(lat_deg), float(lon_deg), float(height_m), spread)


def _angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle (degrees) of the rotation between two orientations of the same parity, from
    the chord ``|A - B|_F = 2 sqrt(2) sin(angle / 2)`` (the trace's acos loses small angles:
    its floor is ~1e-6°, which numpy and BLAS builds cross)."""
    chord = float(np.linalg.norm(A - B)) / (2.0 * math.sqrt(2.0))
    return math.degrees(2.0 * math.asin(min(1.0, chord)))


def predict_attitude(mount: Mount, time) -> np.ndarray:
    """``R_cam_from_icrs`` of the mounted camera at ``time`` (astropy ``Time`` or UTC text)."""
    return mount.R_cam_from_enu @ R_enu_from_icrs(
        time, mount.lat_deg, mount.lon_deg, mount.height_m
    )


@dataclass(frozen=True, eq=False)
class MountPrior:
    """The attitude a camera file's mount predicts (``R_cam_from_icrs``) at ``utc`` (ISO
    8601, from ``utc_source``: "command line" or the file's tag), computed in ``predict_ms``."""

    R_cam_from_icrs: np.ndarray
    utc: str
    utc_source: str
    predict_ms: float

    def to_dict(self, solved_R: np.ndarray | None = None) -> dict:
        """The JSON of the prediction; with the solved attitude, how far off it was."""
        out = {"utc": self.utc, "utc_source": self.utc_source, "predict_ms": self.predict_ms}
        if solved_R is not None:
            out["off_deg"] = _angle_deg(solved_R, self.R_cam_from_icrs)
        return out


def read_mount(camera_path: str | Path) -> Mount | None:
    """The ``"mount"`` of a camera file (None when it has none; the file itself is read and
    checked by ``starnav.camera.load_camera``)."""
    import json

    try:
        data = json.loads(Path(camera_path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None  # load_camera says what is wrong with it
    if not isinstance(data, dict) or data.get("mount") is None:
        return None
    return Mount.from_dict(data["mount"], f"camera file {camera_path}: mount")


def mount_prior(
    camera_path: str | Path, image_path: str | Path | None, utc: str | None
) -> MountPrior | None:
    """The attitude predicted for an image by its camera file's mount at the image's UTC
    (``utc``, else the file's DATE-OBS / EXIF UTC tag): None without a mount or a time."""
    import time as clock

    from starnav.detect.header import image_time

    mount = read_mount(camera_path)
    if mount is None:
        return None
    t0 = clock.perf_counter()
    if utc is not None:
        when, source = parse_utc(utc), "command line"
    else:
        found = None if image_path is None else image_time(image_path)
        if found is None or found.local:
            return None
        when, source = found.time, found.source
    R = predict_attitude(mount, when)
    return MountPrior(R, when.isot, source, (clock.perf_counter() - t0) * 1e3)
