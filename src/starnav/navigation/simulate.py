"""Simulated celestial-fix observations: a platform at a known site, heading and tilt, with star
cameras on it, at a UTC.

Body frame x forward, y right, z down; its attitude is heading (azimuth of x from true North,
clockwise), pitch and roll, applied in that order from the local North-East-Down frame:
``R_body_from_ned = Rx(roll) Ry(pitch) Rz(heading)`` (passive rotations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.camera import Camera, CameraModel
from starnav.catalog import Catalog, load_catalog
from starnav.navigation.frames import enu_directions, parse_utc
from starnav.navigation.observation import (
    CameraView,
    Observation,
    mount_from_azimuth_elevation,
)
from starnav.simulate.render import RenderSettings, render_stars

ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def body_from_enu(heading_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """``R_body_from_enu`` of a platform with this heading, pitch and roll (degrees)."""
    h, p, r = np.radians([heading_deg, pitch_deg, roll_deg])
    return _rx(r) @ _ry(p) @ _rz(h) @ ENU_TO_NED


@dataclass(frozen=True, eq=False)
class SimulatedSky:
    """The stars of a simulated observation: per camera, the catalog rows seen and their exact
    directions in the body frame (unit vectors), beside the ``observation`` built from them."""

    observation: Observation
    catalog: Catalog
    rows: tuple[np.ndarray, ...]
    body: tuple[np.ndarray, ...]


def simulate_observation(
    *,
    lat_deg: float,
    lon_deg: float,
    utc: str,
    heading_deg: float,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    mounts: tuple[tuple[float, float], ...] = ((0.0, 45.0), (120.0, 45.0), (240.0, 45.0)),
    fov_deg: float = 20.0,
    width: int = 1024,
    camera: CameraModel | None = None,
    mag_limit: float = 7.0,
    noise_px: float = 0.0,
    pressure_hpa: float = 0.0,
    temperature_c: float = 15.0,
    catalog: Catalog | None = None,
    seed: int | np.random.Generator | None = None,
) -> SimulatedSky:
    """Cameras at ``mounts`` ((azimuth, elevation) in the body frame, degrees) see the Hipparcos
    stars to ``mag_limit`` as they stand at the site (apparent place, refracted when
    ``pressure_hpa`` > 0); centroids get Gaussian noise of ``noise_px``. Every camera is a
    pinhole of ``fov_deg`` across ``width`` x ``width`` px, or the lens model ``camera``
    (then carried in the views)."""
    rng = np.random.default_rng(seed)
    t = parse_utc(utc)
    cat = catalog or load_catalog(None, mag_limit=mag_limit, epoch_year=float(t.decimalyear))
    R_body = body_from_enu(heading_deg, pitch_deg, roll_deg)
    up_body = R_body @ np.array([0.0, 0.0, 1.0])
    # AltAz of the whole catalog at once; only stars above the horizon can be seen
    above = np.arange(len(cat))
    enu = enu_directions(
        cat.ra_deg[above],
        cat.dec_deg[above],
        t,
        lat_deg=lat_deg,
        lon_deg=lon_deg,
        pressure_hpa=pressure_hpa,
        temperature_c=temperature_c,
    )
    visible = enu[:, 2] > 0.0
    above, enu = above[visible], enu[visible]
    body_all = enu @ R_body.T
    lens = camera or Camera.from_fov(fov_deg, width)
    views, rows, body = [], [], []
    for n, (az, el) in enumerate(mounts, start=1):
        R_cam = mount_from_azimuth_elevation(az, el)
        c = body_all @ R_cam.T
        seen = np.flatnonzero(lens.sees(c))
        keep = seen[np.argsort(cat.mag[above[seen]], kind="stable")]
        xy = lens.bearings_to_pixels(c[keep])
        if noise_px:
            xy = xy + rng.normal(0.0, noise_px, xy.shape)
        views.append(
            CameraView(
                f"camera {n}", lens.fov_deg, lens.width, lens.height, R_cam, xy, camera=camera
            )
        )
        rows.append(above[keep])
        body.append(body_all[keep])
    observation = Observation(utc, -up_body, pressure_hpa, temperature_c, tuple(views))
    return SimulatedSky(observation, cat, tuple(rows), tuple(body))


def render_views(
    sky: SimulatedSky, settings: RenderSettings | None = None, *, seed: int | None = None
) -> tuple[np.ndarray, ...]:
    """Images (uint16 / uint8 ADU, height x width) of every camera of a simulated observation:
    its stars drawn where the simulation put them, with the renderer's pixel-integrated
    Gaussian PSF, sky, photon and read noise (``simulate.render.render_stars``), each as bright
    as ``settings`` makes its catalog magnitude. Only the stars centred inside an image are
    drawn (the simulation lists no others). ``seed``: camera k's noise uses ``seed + k``."""
    settings = RenderSettings() if settings is None else settings
    images = []
    for k, (view, rows) in enumerate(zip(sky.observation.cameras, sky.rows, strict=True)):
        mag = sky.catalog.mag[rows]
        keep = np.ones(len(rows), dtype=bool)
        if settings.mag_limit is not None:
            keep = mag <= settings.mag_limit
        rng = None if seed is None else seed + k
        images.append(
            render_stars(
                view.xy[keep], settings.flux_e(mag[keep]), view.width, view.height, settings, rng
            )
        )
    return tuple(images)
