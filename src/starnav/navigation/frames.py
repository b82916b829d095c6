"""Star directions at a UTC in the Earth-fixed and local frames, with astropy / ERFA.

Catalog positions (ICRS at the epoch of the observation, proper motion already applied) go to
``ITRS`` (precession-nutation, annual aberration, Earth rotation with UT1, polar motion) or to
the local ``AltAz`` frame of a site (adding diurnal aberration and, with a pressure, refraction).
Earth-orientation data come from the IERS tables that the astropy-iers-data package ships: a
download is never attempted (``auto_download`` off while these run).
"""

from __future__ import annotations

import warnings

import numpy as np
from astropy import units as u
from astropy.coordinates import ITRS, AltAz, EarthLocation, SkyCoord
from astropy.time import Time

from starnav.catalog.sky import offline_iers, parse_utc

__all__ = ["enu_directions", "itrs_directions", "parse_utc", "radii_of_curvature_m"]

# WGS84
_A_M = 6378137.0
_F = 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)


def itrs_directions(ra_deg: np.ndarray, dec_deg: np.ndarray, time: Time) -> np.ndarray:
    """Geocentric apparent directions (n, 3) of stars in the ITRS (Earth-fixed) frame."""
    with offline_iers(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "tried to get polar motions for times after IERS data"
        c = SkyCoord(ra=ra_deg * u.deg, dec=dec_deg * u.deg, frame="icrs")
        v = c.transform_to(ITRS(obstime=time)).cartesian.xyz.value.T
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def enu_directions(
    ra_deg: np.ndarray,
    dec_deg: np.ndarray,
    time: Time,
    *,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
    pressure_hpa: float = 0.0,
    temperature_c: float = 15.0,
) -> np.ndarray:
    """Topocentric apparent directions (n, 3) as (East, North, Up) at a site (geodetic WGS84),
    refracted when ``pressure_hpa`` > 0 (astropy's model at 0.55 µm, dry air)."""
    site = EarthLocation.from_geodetic(lon_deg * u.deg, lat_deg * u.deg, height_m * u.m)
    frame = AltAz(
        obstime=time,
        location=site,
        pressure=pressure_hpa * u.hPa,
        temperature=temperature_c * u.deg_C,
        relative_humidity=0.0,
        obswl=0.55 * u.micron,
    )
    with offline_iers(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        aa = SkyCoord(ra=ra_deg * u.deg, dec=dec_deg * u.deg, frame="icrs").transform_to(frame)
    alt, az = aa.alt.rad, aa.az.rad
    return np.column_stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)])


def radii_of_curvature_m(lat_deg: float) -> tuple[float, float]:
    """WGS84 meridian (north-south) and prime-vertical (east-west) radii of curvature, metres:
    a small angle on the ground times these is a distance."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    w = np.sqrt(1.0 - _E2 * s2)
    return float(_A_M * (1.0 - _E2) / w**3), float(_A_M / w)
