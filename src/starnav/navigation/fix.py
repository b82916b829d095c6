"""Latitude, longitude and heading from identified stars, gravity and UTC.

Method (the reference work's, domain.md section 3): every camera's stars are identified by the
lost-in-space solver (with its lens model, or a pinhole of its field of view, or with the
field of view searched, as ``starnav solve`` does) and turned into directions in the body frame
through the lens model with the focal length the solve settled on; Wahba's problem (SVD, the
loss sum |b_i - R s_i|^2 over all cameras together) gives the body's orientation against the
stars' directions. Where that orientation puts gravity is the local vertical: the site is where
the WGS84 ellipsoid normal points along it. A first fix comes from geocentric directions in the
Earth-fixed frame (ITRS); it is refined in the local frame at the site (AltAz: diurnal
aberration and refraction), where the gravity vector's horizontal part is the remaining error of
the assumed position, until the correction is below a millimetre.

Error ellipse: the attitude covariance from the stars (sigma^2 (sum (I - b b^T))^-1, sigma from
the residuals, at least the centroid error told) mapped into north / east position through
the vertical. The gravity vector's own error is not known here; each arcsecond of tilt error
moves the fix by about 31 m (see docs/locate.md).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from starnav.attitude.wahba import wahba
from starnav.camera import Camera, CameraModel
from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.geometry import ARCSEC_PER_RAD
from starnav.navigation.frames import (
    enu_directions,
    itrs_directions,
    parse_utc,
    radii_of_curvature_m,
)
from starnav.navigation.observation import CameraView, Observation
from starnav.pipeline import Solver, SolveSettings
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.stars import solve_stars
from starnav.results import SolveResult
from starnav.starlist import check_star_list

_MAX_ITERATIONS = 8
_CONVERGED_RAD = 1e-10  # about 0.6 mm on the ground


class FixError(StarnavError):
    """No fix can be made from the observation (too few identified stars)."""


@dataclass(frozen=True)
class CameraReport:
    """What one camera contributed: ``stars_used`` identified stars (0 when ``reason`` says
    why not), and when it was solved its boresight RA/Dec (degrees) and the ``focal_px`` its
    bearings were made with (the searched one when its field of view was not given)."""

    name: str
    n_points: int
    stars_used: int
    reason: str
    ra_deg: float | None = None
    dec_deg: float | None = None
    focal_px: float | None = None


@dataclass(frozen=True, eq=False)
class Fix:
    """A position and heading fix.

    ``lat_deg``/``lon_deg``: geodetic WGS84 (east positive) of the point whose ellipsoid normal
    is the measured vertical; ``azimuth_deg``: heading of body x, clockwise from true North;
    ``ellipse_major_m``/``ellipse_minor_m``: 1-sigma semi-axes of the position error from the
    stars, ``ellipse_angle_deg``: direction of the major axis from North through East (0-180);
    ``sigma_azimuth_arcsec``: 1-sigma heading error; ``rms_arcsec``: residual of the star
    directions; ``R_body_from_enu``: rows = body axes in (East, North, Up); ``cameras``: one
    report each; ``time_ms``: identification and fix; ``gravity_sigma_deg``: the 1-sigma error
    of the gravity direction the observation states (a levelled camera's tolerance; 0: not
    stated), whose position error ``gravity_north_m`` / ``gravity_east_m`` give.
    """

    lat_deg: float
    lon_deg: float
    azimuth_deg: float
    ellipse_major_m: float
    ellipse_minor_m: float
    ellipse_angle_deg: float
    sigma_azimuth_arcsec: float
    rms_arcsec: float
    n_stars: int
    iterations: int
    R_body_from_enu: np.ndarray
    cameras: tuple[CameraReport, ...] = field(default=())
    time_ms: float = 0.0
    gravity_sigma_deg: float = 0.0

    @property
    def gravity_north_m(self) -> float:
        """1-sigma north position error (m) from ``gravity_sigma_deg``: a vertical tilted by an
        angle moves the fix by that angle of the meridian's arc."""
        return math.radians(self.gravity_sigma_deg) * radii_of_curvature_m(self.lat_deg)[0]

    @property
    def gravity_east_m(self) -> float:
        """1-sigma east position error (m) from ``gravity_sigma_deg`` (the prime vertical's
        arc)."""
        return math.radians(self.gravity_sigma_deg) * radii_of_curvature_m(self.lat_deg)[1]

    def to_dict(self) -> dict:
        out = {k: v for k, v in self.__dict__.items() if k not in ("R_body_from_enu", "cameras")}
        out["gravity_north_m"], out["gravity_east_m"] = self.gravity_north_m, self.gravity_east_m
        out["stars_used"] = {c.name: c.stars_used for c in self.cameras}
        out["R_body_from_enu"] = self.R_body_from_enu.tolist()
        out["cameras"] = [c.__dict__ for c in self.cameras]
        return out


def fix_from_directions(
    body: np.ndarray,
    ra_deg: np.ndarray,
    dec_deg: np.ndarray,
    utc: str,
    gravity_body: np.ndarray,
    *,
    pressure_hpa: float = 0.0,
    temperature_c: float = 15.0,
    sigma_rad: float = 0.0,
) -> Fix:
    """The fix from star directions ``body`` (n, 3, unit vectors in the body frame) of the
    catalog stars at ``ra_deg``/``dec_deg`` (ICRS at the observation's epoch), gravity and UTC.
    ``sigma_rad``: the smallest 1-sigma direction error assumed for the ellipse."""
    if len(body) < 2:
        raise FixError(f"{len(body)} identified stars: at least 2 are needed for a fix")
    t = parse_utc(utc)
    g = np.asarray(gravity_body, dtype=float)
    g = g / np.linalg.norm(g)
    # first fix: geocentric directions in the Earth-fixed frame
    R_itrs = wahba(body, itrs_directions(ra_deg, dec_deg, t), parity=1)
    up = -R_itrs.T @ g
    lat = float(np.degrees(np.arcsin(np.clip(up[2], -1.0, 1.0))))
    lon = float(np.degrees(np.arctan2(up[1], up[0])))
    # refine in the local frame: diurnal aberration, refraction; the measured vertical's
    # horizontal part is the error of the assumed site
    iterations = 0
    for iterations in range(1, _MAX_ITERATIONS + 1):  # noqa: B007 (reported below)
        enu = enu_directions(
            ra_deg,
            dec_deg,
            t,
            lat_deg=lat,
            lon_deg=lon,
            pressure_hpa=pressure_hpa,
            temperature_c=temperature_c,
        )
        R = wahba(body, enu, parity=1)
        down = R.T @ g  # gravity in (East, North, Up): (0, 0, -1) at the right site
        dlat, dlon_cos = -down[1], -down[0]
        lat += float(np.degrees(dlat))
        lon += float(np.degrees(dlon_cos / np.cos(np.radians(lat))))
        if max(abs(dlat), abs(dlon_cos)) < _CONVERGED_RAD:
            break
    lon = (lon + 180.0) % 360.0 - 180.0
    residual = body - enu @ R.T
    rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    n = len(body)
    sigma2 = max(float(np.sum(residual**2)) / max(2 * n - 3, 1), sigma_rad**2)
    info = np.sum(np.eye(3)[None] - body[:, :, None] * body[:, None, :], axis=0)
    cov_body = sigma2 * np.linalg.pinv(info)
    cov_enu = R.T @ cov_body @ R  # small rotations about East, North, Up
    # the vertical moves north by the rotation about East, east by minus that about North
    m_north, m_east = radii_of_curvature_m(lat)
    J = np.array([[m_north, 0.0, 0.0], [0.0, -m_east, 0.0]])  # (north, east) m from theta_ENU
    cov_ne = J @ cov_enu @ J.T
    values, vectors = np.linalg.eigh(cov_ne)
    major = vectors[:, 1]
    angle = float(np.degrees(np.arctan2(major[1], major[0])) % 180.0)
    x_enu = R.T @ np.array([1.0, 0.0, 0.0])
    azimuth = float(np.degrees(np.arctan2(x_enu[0], x_enu[1])) % 360.0)
    return Fix(
        lat_deg=lat,
        lon_deg=lon,
        azimuth_deg=azimuth,
        ellipse_major_m=float(np.sqrt(max(values[1], 0.0))),
        ellipse_minor_m=float(np.sqrt(max(values[0], 0.0))),
        ellipse_angle_deg=angle,
        sigma_azimuth_arcsec=float(np.sqrt(max(cov_enu[2, 2], 0.0)) * ARCSEC_PER_RAD),
        rms_arcsec=rms * ARCSEC_PER_RAD,
        n_stars=n,
        iterations=iterations,
        R_body_from_enu=R,
    )


def locate(
    observation: Observation,
    *,
    catalog: Catalog | str | None = None,
    mag_limit: float | None = None,
    sigma_px: float = 1.0,
) -> Fix:
    """Identify every camera's stars and fix the position and heading.

    ``catalog``/``mag_limit``: as for ``starnav.solve`` (default: the embedded Hipparcos, its
    proper motion applied to the observation's date); ``sigma_px``: 1-sigma centroid error.
    A camera whose stars cannot be identified is reported and left out. Raises ``FixError``
    when fewer than 2 stars are identified in all.
    """
    t0 = _time.perf_counter()
    t = parse_utc(observation.utc)
    if catalog is None:
        # identification at the year's epoch (its pair database is then built once a year);
        # the fix with positions at the observation's own date
        cat = load_catalog(None, mag_limit=mag_limit, epoch_year=float(round(t.decimalyear)))
        cat_fix = load_catalog(None, mag_limit=mag_limit, epoch_year=float(t.decimalyear))
    else:
        cat = cat_fix = load_catalog(catalog, mag_limit=mag_limit)
    reports, body, rows, scales = [], [], [], []
    for view in observation.cameras:
        if len(view.xy) < 3:
            reports.append(CameraReport(view.name, len(view.xy), 0, "fewer than 3 stars"))
            continue
        result, camera = identify_view(view, cat, sigma_px=sigma_px)
        s = result.solution
        if s is None:
            reports.append(CameraReport(view.name, len(view.xy), 0, result.reason))
            continue
        matched = [m for m in s.stars if m.catalog_id is not None]
        c = camera.pixels_to_bearings(np.array([[m.x, m.y] for m in matched]))
        body.append(c @ view.R_cam_from_body)  # b = R^T c, row-wise
        rows.append(cat_fix.rows([m.catalog_id for m in matched]))
        scales.append(camera.scale_px_per_rad)  # px per rad where the lens is coarsest
        reports.append(
            CameraReport(
                view.name, len(view.xy), len(matched), "", s.ra_deg, s.dec_deg, camera.focal_px
            )
        )
    if not body:
        raise FixError(
            "no camera's stars could be identified: "
            + "; ".join(f"{r.name}: {r.reason}" for r in reports)
        )
    rows_all = np.concatenate(rows)
    fix = fix_from_directions(
        np.vstack(body),
        cat_fix.ra_deg[rows_all],
        cat_fix.dec_deg[rows_all],
        observation.utc,
        observation.gravity_body,
        pressure_hpa=observation.pressure_hpa,
        temperature_c=observation.temperature_c,
        sigma_rad=sigma_px / min(scales),
    )
    return Fix(
        **{
            **fix.__dict__,
            "cameras": tuple(reports),
            "time_ms": (_time.perf_counter() - t0) * 1e3,
            "gravity_sigma_deg": observation.gravity_sigma_deg,
        }
    )


def identify_view(
    view: CameraView, catalog: Catalog, *, sigma_px: float = 1.0
) -> tuple[SolveResult, CameraModel]:
    """Identify one camera's stars in ``catalog``: with its lens model, or a pinhole of its
    ``fov_deg``, or (neither given) with the field of view searched in ``starnav solve``'s
    default range, among the same catalog's stars. Returns the solve and the camera model
    with the focal length the solution settled on (the searched one, or the model's own)."""
    stars = check_star_list(view.xy, width=view.width, height=view.height)
    if view.camera is None and view.fov_deg is None:
        options = SolveOptions(catalog=catalog, sigma_px=sigma_px)
        result = solve_stars(stars, options, width=view.width, height=view.height)
        base: CameraModel = Camera(view.width, view.height, 1.0)
    else:
        base = view.camera
        if base is None:
            base = Camera.from_fov(view.fov_deg, view.width, view.height)
        settings = SolveSettings(sigma_px=sigma_px)
        result = Solver(base, catalog, settings=settings).solve(stars)
    s = result.solution
    return result, base if s is None else base.with_focal(s.focal_px)
