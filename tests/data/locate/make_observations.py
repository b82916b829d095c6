"""Generator of the noise-free observation files for the tests of ``starnav locate``.

Committed next to the data it writes (``<name>.json`` + ``<name>.truth.json`` in this
directory); run it again to regenerate them::

    python tests/data/locate/make_observations.py

It is deliberately independent of ``starnav.navigation``: the sky comes from astropy's own
ICRS -> AltAz chain, the platform and camera geometry is written out below with plain numpy.
From starnav it uses only the Hipparcos catalog (``starnav.catalog.load_catalog``) and the
pinhole projection (``starnav.camera.Camera``).

Sky
---
- Catalog: Hipparcos, Hp <= 7, proper motion applied by ``load_catalog`` to ``epoch_year`` =
  the Julian epoch of the UTC (``Time.jyear``; the catalog counts years of 365.25 days from
  J2000). These RA/Dec are used as astrometric ICRS directions at the date: no further proper
  motion, no parallax (stars at infinity).
- ``SkyCoord(ra, dec, frame="icrs").transform_to(AltAz(obstime=Time(utc, scale="utc"),
  location=EarthLocation.from_geodetic(lon, lat, height)))`` (WGS84; astropy/ERFA: IAU 2006/2000A
  precession-nutation, ERA from UT1, polar motion, annual + diurnal aberration, light
  deflection by the Sun). UT1-UTC and polar motion come from the IERS table bundled in
  ``astropy-iers-data`` (nothing is downloaded: ``iers.conf.auto_download = False`` and
  ``astropy.utils.data.conf.allow_internet = False``); every date used is checked to lie in
  the part of the table holding final (IERS "B") values, so the output does not depend on
  predictions. The values used are written to each truth file.
- Refraction off: ``pressure=0``. The one refraction case uses pressure 1013.25 hPa,
  temperature 10 degC, relative humidity 0, obswl 0.55 um (astropy -> ``erfa.refco``).
- Only stars above the (apparent) horizon, alt > 0, are visible.

Frames (all rotations passive: ``v_b = R_b_from_a @ v_a``; angles in degrees at the interface)
------
- Local ENU at the site (astropy alt/az: azimuth from North through East):
  ``u_enu = (cos alt sin az, cos alt cos az, sin alt)`` in (East, North, Up).
- Local NED: ``u_ned = (u_N, u_E, -u_U)``.
- Body frame: x forward, y right, z down. Heading psi (azimuth of body x, clockwise from true
  North), pitch theta (nose up positive), roll phi (right side down positive), aerospace
  yaw-pitch-roll 3-2-1 from NED::

      R_body_from_ned = Rx(phi) @ Ry(theta) @ Rz(psi)
      Rz(a) = [[ cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]]
      Ry(a) = [[cos a, 0, -sin a], [0, 1, 0], [sin a, 0, cos a]]
      Rx(a) = [[1, 0, 0], [0, cos a, sin a], [0, -sin a, cos a]]

- ``gravity_body = R_body_from_ned @ (0, 0, 1)``
  = (-sin theta, sin phi cos theta, cos phi cos theta): unit vector of gravity (pointing
  down) in the body frame.
- Cameras (camera frame x right, y down, z boresight). Either ``azimuth_deg`` = az and
  ``elevation_deg`` = el, the mount direction in the BODY frame (az from body x towards body y,
  el up from the body x-y plane)::

      z = (cos el cos az, cos el sin az, -sin el)
      x = (-sin az, cos az, 0)
      y = z cross x
      R_cam_from_body = [x; y; z]          (rows = camera axes in body components)

  or an explicit ``R_cam_from_body`` (3x3 nested list, rows = camera axes in the body frame).
- A star is seen by a camera when ``c = R_cam_from_body @ R_body_from_ned @ u_ned`` has
  ``c_z > 0``, its pinhole pixel ``Camera.from_fov(fov_deg, width, height)
  .bearings_to_pixels(c)`` is inside the image (``Camera.contains``, edges included) and it is
  above the horizon. Pixels: origin at the top-left corner, x right, y down, principal point
  (W/2, H/2), focal_px = (W/2) / tan(fov_deg/2) (``fov_deg`` is the horizontal FOV).
  ``stars`` lists [x, y] rounded to 1e-4 px, brightest first.

Checks run every time (the script fails when one fails): the rotation matrices against scipy's
Euler angles; ``gravity_body`` against its closed form; each camera pixel (unrounded) turned
back into alt/az against astropy's alt/az of that star (< 1e-6 deg; the rounded pixels are
also checked, < 3e-6 deg, since 1e-4 px is ~2e-6 deg at these focal lengths); and the same
alt/az pushed back through astropy (AltAz -> ICRS) against the catalog star.
"""

from __future__ import annotations

import json
import re
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from astropy import units as u
from astropy.coordinates import AltAz, EarthLocation, SkyCoord, get_body
from astropy.time import Time
from astropy.utils import iers
from astropy.utils.data import conf as data_conf
from scipy.spatial.transform import Rotation

from starnav.camera import Camera
from starnav.catalog import load_catalog

HERE = Path(__file__).resolve().parent
MAG_LIMIT = 7.0
MIN_STARS = 8
PIXEL_DECIMALS = 4

# refraction parameters of the one refraction case (relative humidity 0, 0.55 um: not part of
# the observation format, so the locate command must assume them)
REFRACTION = {"pressure_hpa": 1013.25, "temperature_c": 10.0, "rh": 0.0, "obswl_um": 0.55}


# --------------------------------------------------------------------------- frames


def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def body_from_ned(psi_deg: float, theta_deg: float, phi_deg: float) -> np.ndarray:
    psi, theta, phi = np.radians([psi_deg, theta_deg, phi_deg])
    return rot_x(phi) @ rot_y(theta) @ rot_z(psi)


def cam_from_body_azel(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = np.radians([az_deg, el_deg])
    z = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    x = np.array([-np.sin(az), np.cos(az), 0.0])
    y = np.cross(z, x)
    return np.vstack([x, y, z])


def ned_from_altaz(alt_deg, az_deg) -> np.ndarray:
    alt, az = np.radians(alt_deg), np.radians(az_deg)
    east, north, up = np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)
    return np.column_stack([north, east, -up])


def altaz_from_ned(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    north, east, down = v.T
    alt = np.degrees(np.arcsin(np.clip(-down, -1.0, 1.0)))
    az = np.degrees(np.arctan2(east, north)) % 360.0
    return alt, az


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between rows of two arrays of vectors (robust for tiny angles)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(
        2.0 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
    )


# --------------------------------------------------------------------------- cases


def _azel(az, el, fov=20, width=1024, height=1024):
    return {"fov_deg": fov, "width": width, "height": height, "az": az, "el": el}


def _matrix(az, el, spin, fov=20, width=1024, height=1024):
    """A camera given by R_cam_from_body: the az/el mount, then turned by ``spin`` degrees
    about its own boresight (which the az/el form cannot express)."""
    r = rot_z(np.radians(spin)) @ cam_from_body_azel(az, el)
    return {"fov_deg": fov, "width": width, "height": height, "R": r}


CASES = [
    {
        "name": "reference_level",
        "notes": "reference set-up: three cameras 120 deg apart in azimuth at 45 deg elevation, "
        "20 deg FOV, 1024x1024, Hp <= 7; mid-latitude site, level platform, heading 30 deg",
        "utc": "2026-03-14T21:30:00Z",
        "lat": 47.37,
        "lon": 8.54,
        "height": 400.0,
        "psi": 30.0,
        "theta": 0.0,
        "phi": 0.0,
        "refraction": False,
        "cameras": [_azel(0, 45), _azel(120, 45), _azel(240, 45)],
    },
    {
        "name": "tilted_south",
        "notes": "southern-hemisphere site, tilted platform (pitch 2, roll -1.5 deg), heading "
        "250 deg; third camera given by R_cam_from_body (az 240, el 45 mount turned 15 deg "
        "about its boresight)",
        "utc": "2025-07-20T03:15:00Z",
        "lat": -24.6272,
        "lon": -70.4042,
        "height": 2635.0,
        "psi": 250.0,
        "theta": 2.0,
        "phi": -1.5,
        "refraction": False,
        "cameras": [_azel(0, 45), _azel(120, 45), _matrix(240, 45, 15.0)],
    },
    {
        "name": "single_camera",
        "notes": "one camera at 60 deg elevation, 20 deg horizontal FOV on a 1280x960 sensor; "
        "slightly tilted platform, heading 75 deg",
        "utc": "2025-11-05T05:00:00Z",
        "lat": 35.08,
        "lon": -106.65,
        "height": 1600.0,
        "psi": 75.0,
        "theta": 0.8,
        "phi": 1.2,
        "refraction": False,
        "cameras": [_azel(90, 60, width=1280, height=960)],
    },
    {
        "name": "ground_camera",
        "notes": "second camera points at the ground (elevation -30 deg): no stars, the fix "
        "must come from the other two; high-latitude site, heading 123.4 deg",
        "utc": "2026-01-20T19:45:00Z",
        "lat": 60.17,
        "lon": 24.94,
        "height": 20.0,
        "psi": 123.4,
        "theta": -0.7,
        "phi": 1.1,
        "refraction": False,
        "cameras": [_azel(0, 45), _azel(120, -30), _azel(240, 45)],
    },
    {
        "name": "refraction",
        "notes": "refraction on: pressure 1013.25 hPa, temperature 10 degC, relative humidity "
        "0, wavelength 0.55 um (astropy AltAz -> erfa.refco); three cameras 120 deg apart at "
        "40 deg elevation, heading 310 deg, slightly tilted platform",
        "utc": "2025-12-10T22:00:00Z",
        "lat": 40.4168,
        "lon": -3.7038,
        "height": 650.0,
        "psi": 310.0,
        "theta": 0.5,
        "phi": -0.3,
        "refraction": True,
        "cameras": [_azel(0, 40), _azel(120, 40), _azel(240, 40)],
    },
]


# --------------------------------------------------------------------------- IERS / time


def configure_offline() -> None:
    iers.conf.auto_download = False
    data_conf.allow_internet = False


def parse_utc(utc: str) -> Time:
    return Time(utc.removesuffix("Z"), format="isot", scale="utc")


def earth_orientation(t: Time) -> dict:
    """UT1-UTC and polar motion used by astropy at ``t``; fails unless they are final values."""
    table = iers.earth_orientation_table.get()
    ut1_utc, status = table.ut1_utc(t, return_status=True)
    xp, yp, pm_status = table.pm_xy(t, return_status=True)
    if status != iers.FROM_IERS_B or pm_status != iers.FROM_IERS_B:
        raise SystemExit(
            f"{t.isot}: the bundled IERS table has no final (B) values there "
            f"(status {status}, {pm_status}); choose an earlier date"
        )
    # the UT1 scale itself must work offline
    _ = t.ut1.isot
    return {
        "ut1_utc_s": round(float(ut1_utc.to_value(u.s)), 7),
        "polar_motion_arcsec": [
            round(float(xp.to_value(u.arcsec)), 6),
            round(float(yp.to_value(u.arcsec)), 6),
        ],
        "iers_table": Path(table.meta.get("data_path", "?")).name,
    }


def altaz_frame(t: Time, location: EarthLocation, refraction: bool) -> AltAz:
    if not refraction:
        return AltAz(obstime=t, location=location, pressure=0 * u.hPa)
    return AltAz(
        obstime=t,
        location=location,
        pressure=REFRACTION["pressure_hpa"] * u.hPa,
        temperature=REFRACTION["temperature_c"] * u.deg_C,
        relative_humidity=REFRACTION["rh"],
        obswl=REFRACTION["obswl_um"] * u.micron,
    )


# --------------------------------------------------------------------------- one case


def make_case(case: dict) -> tuple[dict, dict, dict]:
    t = parse_utc(case["utc"])
    eop = earth_orientation(t)
    epoch_year = float(t.jyear)
    catalog = load_catalog(None, mag_limit=MAG_LIMIT, epoch_year=epoch_year)
    location = EarthLocation.from_geodetic(
        lon=case["lon"] * u.deg, lat=case["lat"] * u.deg, height=case["height"] * u.m
    )
    frame = altaz_frame(t, location, case["refraction"])
    stars = SkyCoord(ra=catalog.ra_deg * u.deg, dec=catalog.dec_deg * u.deg, frame="icrs")
    altaz = stars.transform_to(frame)
    alt, az = altaz.alt.to_value(u.deg), altaz.az.to_value(u.deg)
    u_ned = ned_from_altaz(alt, az)
    sun = get_body("sun", t, location).transform_to(altaz_frame(t, location, False))
    sun_alt = float(sun.alt.to_value(u.deg))
    if sun_alt > -12.0:
        raise SystemExit(f"{case['name']}: the Sun is at {sun_alt:.1f} deg, not night")

    r_bn = body_from_ned(case["psi"], case["theta"], case["phi"])
    check_body_rotation(r_bn, case)
    gravity = r_bn @ np.array([0.0, 0.0, 1.0])

    order = np.argsort(catalog.mag, kind="stable")  # brightest first
    cameras_out, ids_out, boresights, worst = [], [], [], {}
    for k, cam in enumerate(case["cameras"]):
        r_cb = cam["R"] if "R" in cam else cam_from_body_azel(cam["az"], cam["el"])
        check_camera_rotation(r_cb)
        camera = Camera.from_fov(cam["fov_deg"], cam["width"], cam["height"])
        c = u_ned[order] @ (r_cb @ r_bn).T
        front = (c[:, 2] > 0) & (alt[order] > 0.0)
        xy = np.full((len(c), 2), np.nan)
        xy[front] = camera.bearings_to_pixels(c[front])
        seen = np.zeros(len(c), dtype=bool)
        seen[front] = camera.contains(xy[front])
        rows = order[seen]
        xy = xy[seen]
        xy_round = np.round(xy, PIXEL_DECIMALS)
        sees_sky = cam.get("el", 90.0) > 0
        if sees_sky and len(rows) < MIN_STARS:
            raise SystemExit(f"{case['name']} camera {k}: only {len(rows)} stars")
        if not sees_sky and len(rows):
            raise SystemExit(f"{case['name']} camera {k}: sees stars below the horizon")
        if len(rows):
            worst[k] = check_pixels(
                camera, r_cb, r_bn, xy, xy_round, alt[rows], az[rows], frame, catalog, rows
            )
        b_alt, b_az = altaz_from_ned((r_cb @ r_bn).T[:, 2][None, :])
        boresights.append([round(float(b_alt[0]), 6), round(float(b_az[0]), 6)])

        out = {"fov_deg": cam["fov_deg"], "width": cam["width"], "height": cam["height"]}
        if "R" in cam:
            out["R_cam_from_body"] = [[float(v) for v in row] for row in r_cb]
        else:
            out["azimuth_deg"] = cam["az"]
            out["elevation_deg"] = cam["el"]
        out["stars"] = [[float(x), float(y)] for x, y in xy_round]
        cameras_out.append(out)
        ids_out.append([int(i) for i in catalog.ids[rows]])

    obs = {"utc": case["utc"], "gravity_body": [float(g) for g in gravity]}
    if case["refraction"]:
        obs["pressure_hpa"] = REFRACTION["pressure_hpa"]
        obs["temperature_c"] = REFRACTION["temperature_c"]
    else:
        obs["pressure_hpa"] = 0
    obs["cameras"] = cameras_out

    truth = {
        "lat_deg": case["lat"],
        "lon_deg": case["lon"],
        "height_m": case["height"],
        "azimuth_deg": case["psi"],
        "pitch_deg": case["theta"],
        "roll_deg": case["phi"],
        "utc": case["utc"],
        "refraction": case["refraction"],
        "notes": case["notes"]
        + (
            "; refraction: relative humidity 0 and obswl 0.55 um are not in the observation format"
            if case["refraction"]
            else ""
        ),
        "stars_per_camera": [len(ids) for ids in ids_out],
        "hip_ids_per_camera": ids_out,
        "boresight_alt_az_deg": boresights,
        "epoch_year": round(epoch_year, 6),
        "mag_limit": MAG_LIMIT,
        "sun_alt_deg": round(sun_alt, 2),
        **eop,
    }
    return obs, truth, worst


def check_body_rotation(r_bn: np.ndarray, case: dict) -> None:
    # scipy: intrinsic Z-Y'-X'' active rotation = R_ned_from_body; ours is its transpose
    scipy_r = Rotation.from_euler(
        "ZYX", [case["psi"], case["theta"], case["phi"]], degrees=True
    ).as_matrix()
    assert np.allclose(r_bn, scipy_r.T, atol=1e-14), "R_body_from_ned disagrees with scipy"
    th, ph = np.radians([case["theta"], case["phi"]])
    g = np.array([-np.sin(th), np.sin(ph) * np.cos(th), np.cos(ph) * np.cos(th)])
    assert np.allclose(r_bn @ [0.0, 0.0, 1.0], g, atol=1e-15), "gravity_body closed form"
    # heading: body x projected on the horizontal plane points at azimuth psi
    x_ned = r_bn[0]
    assert abs((np.degrees(np.arctan2(x_ned[1], x_ned[0])) - case["psi"] + 180) % 360 - 180) < 1e-9


def check_camera_rotation(r_cb: np.ndarray) -> None:
    assert np.allclose(r_cb @ r_cb.T, np.eye(3), atol=1e-14), "R_cam_from_body not orthonormal"
    assert abs(np.linalg.det(r_cb) - 1.0) < 1e-14, "R_cam_from_body not a proper rotation"


def check_pixels(camera, r_cb, r_bn, xy, xy_round, alt, az, frame, catalog, rows) -> dict:
    """Re-derive alt/az from the pixels and compare with astropy (degrees)."""
    truth_ned = ned_from_altaz(alt, az)
    result = {}
    for label, pix in (("exact", xy), ("rounded", xy_round)):
        c = camera.pixels_to_bearings(pix)
        v_ned = c @ r_cb @ r_bn  # = (R_body_from_ned^T R_cam_from_body^T c^T)^T
        p_alt, p_az = altaz_from_ned(v_ned)
        result[label] = float(angle_deg(v_ned, truth_ned).max())
        if label == "exact":
            d_alt = np.abs(p_alt - alt).max()
            d_az = np.abs((p_az - az + 180.0) % 360.0 - 180.0) * np.cos(np.radians(alt))
            assert max(d_alt, d_az.max(), result[label]) < 1e-6, "pixel -> alt/az mismatch"
            # back through astropy: AltAz -> ICRS lands on the catalog star
            back = SkyCoord(alt=p_alt * u.deg, az=p_az * u.deg, frame=frame).icrs
            cat = SkyCoord(catalog.ra_deg[rows] * u.deg, catalog.dec_deg[rows] * u.deg)
            result["astropy_round_trip"] = float(back.separation(cat).to_value(u.deg).max())
            assert result["astropy_round_trip"] < 1e-6, "astropy AltAz -> ICRS round trip"
    assert result["rounded"] < 3e-6, "rounded pixels too far from the truth"
    return result


# --------------------------------------------------------------------------- output


def dumps(obj: dict) -> str:
    """JSON with indentation, but every innermost list of numbers on one line."""
    text = json.dumps(obj, indent=2)
    text = re.sub(
        r"\[\s*([-+0-9.eE,\s]+?)\s*\]",
        lambda m: "[" + ", ".join(p.strip() for p in m.group(1).split(",")) + "]",
        text,
    )
    assert json.loads(text) == obj
    return text + "\n"


def main() -> int:
    start = time.perf_counter()
    configure_offline()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an IERS / leap-second warning must not pass silently
        for case in CASES:
            obs, truth, worst = make_case(case)
            (HERE / f"{case['name']}.json").write_text(dumps(obs))
            (HERE / f"{case['name']}.truth.json").write_text(dumps(truth))
            err = ", ".join(
                f"cam{k}: exact {w['exact']:.1e} rounded {w['rounded']:.1e} "
                f"astropy {w['astropy_round_trip']:.1e}"
                for k, w in worst.items()
            )
            print(f"{case['name']}: stars {truth['stars_per_camera']}; max deg error {err}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
