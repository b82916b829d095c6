"""The sky over a place at a time: the catalog's stars above the horizon, and the planets.

An all-sky camera sees half the sky, and among its brightest points are often planets
(Jupiter, Saturn and Mars were 3 of the 15 brightest on one real frame), which no star
catalog holds and which then defeat a pattern search. When the site and the time are known,
``sky_at`` gives the catalog a camera on the ground can see: its stars above
``MIN_ALTITUDE_DEG`` (a hemisphere instead of the whole sphere: half the false candidates) and
the five naked-eye planets above it, at their directions seen from the site in the ICRS axes
(astropy's ``get_body``, the built-in ephemeris: GCRS with the site's parallax, aberration
included: 20″ is nothing at an all-sky camera's scale) with ids ``PLANET_IDS`` (negative:
never a Hipparcos number) and typical magnitudes (``PLANET_MAG``: the pattern search ranks by
brightness; a planet's true magnitude varies by a few tenths to two magnitudes (Mars), which
the ranking tolerates). The Moon is left out: it is a disc, not a point, and its glare is
masked by detection. Refraction is ignored: it lifts a star by at most 0.6° at the horizon.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from starnav.catalog.load import Catalog
from starnav.errors import StarnavError, shown

MIN_ALTITUDE_DEG = -2.0  # stars this far below the horizon still kept (a mountain site's dip)
PLANET_IDS = {"mercury": -1, "venus": -2, "mars": -4, "jupiter": -5, "saturn": -6}
PLANET_MAG = {"mercury": 0.0, "venus": -4.2, "mars": 0.5, "jupiter": -2.3, "saturn": 0.6}


@dataclass(frozen=True)
class Site:
    """Where a camera stands: geodetic ``lat_deg`` (north positive), ``lon_deg`` (east
    positive), ``height_m`` above the WGS84 ellipsoid."""

    lat_deg: float
    lon_deg: float
    height_m: float = 0.0

    def __post_init__(self) -> None:
        for name, value, lo, hi in (
            ("latitude", self.lat_deg, -90.0, 90.0),
            ("longitude", self.lon_deg, -180.0, 360.0),
            ("height", self.height_m, -500.0, 1e5),
        ):
            if isinstance(value, bool) or not (
                isinstance(value, int | float) and math.isfinite(value) and lo <= value <= hi
            ):
                raise StarnavError(
                    f"the site's {name} must be in [{lo:g}, {hi:g}], got {shown(value)}"
                )

    def location(self):
        """The astropy ``EarthLocation``."""
        import astropy.units as u
        from astropy.coordinates import EarthLocation

        return EarthLocation.from_geodetic(
            self.lon_deg * u.deg, self.lat_deg * u.deg, self.height_m * u.m
        )


def parse_utc(utc):
    """An astropy ``Time`` from an ISO 8601 UTC string (a trailing Z is accepted; a ``Time``
    is returned as it is); a one-line error for another format or a year outside 1900-2200.
    (Here, below the pipeline and navigation, which both read times.)"""
    from astropy.time import Time

    if isinstance(utc, Time):
        return utc
    text = utc.strip()
    if text.endswith(("Z", "z")):
        text = text[:-1]
    try:
        t = Time(text, format="isot", scale="utc")
    except ValueError:
        raise StarnavError(
            f"utc {utc!r} is not an ISO 8601 time (e.g. 2026-03-14T21:30:00Z)"
        ) from None
    if not 1900 <= t.decimalyear <= 2200:
        raise StarnavError(f"utc {utc!r} is outside 1900-2200")
    return t


def offline_iers():
    """A context in which astropy never downloads Earth-orientation tables (the IERS tables
    the astropy-iers-data package ships are used)."""
    from astropy.utils import iers

    return iers.conf.set_temp("auto_download", False)


def altitudes_deg(catalog: Catalog, site: Site, utc) -> np.ndarray:
    """The altitude (degrees, no refraction) of each catalog star at ``site`` and ``utc``."""
    return np.degrees(np.arcsin(np.clip(enu_vectors(catalog, site, utc)[:, 2], -1.0, 1.0)))


def enu_vectors(catalog: Catalog, site: Site, utc) -> np.ndarray:
    """Each catalog star's direction (n, 3 unit vectors: East, North, Up; no refraction) at
    ``site`` and ``utc`` (astropy's ICRS to AltAz)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, SkyCoord

    stars = SkyCoord(ra=catalog.ra_deg * u.deg, dec=catalog.dec_deg * u.deg, frame="icrs")
    frame = AltAz(obstime=parse_utc(utc), location=site.location())
    with offline_iers(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "tried to get polar motions for times after IERS data"
        seen = stars.transform_to(frame)
        alt, az = np.asarray(seen.alt.rad), np.asarray(seen.az.rad)
    return np.column_stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)])


def planets(site: Site, utc) -> Catalog:
    """The five naked-eye planets seen from ``site`` at ``utc``: RA/Dec in the ICRS axes
    (GCRS: light time, the site's parallax), ids ``PLANET_IDS``, magnitudes ``PLANET_MAG``."""
    from astropy.coordinates import get_body

    when = parse_utc(utc)
    where = site.location()
    ra, dec = [], []
    for name in PLANET_IDS:
        # GCRS (ICRS axes, seen from the site): not .icrs, which moves the origin to the
        # solar system's barycentre and the planet by up to 11° (Jupiter)
        with offline_iers(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            seen = get_body(name, when, where)
        ra.append(float(seen.ra.deg))
        dec.append(float(seen.dec.deg))
    return Catalog(
        np.array(list(PLANET_IDS.values())),
        np.array(ra),
        np.array(dec),
        np.array([PLANET_MAG[n] for n in PLANET_IDS]),
        "planets",
    )


def planet_name(catalog_id: int) -> str | None:
    """The planet of a catalog id from ``sky_at``, None for a star."""
    return next((n.capitalize() for n, i in PLANET_IDS.items() if i == catalog_id), None)


def sky_at(catalog: Catalog, site: Site, utc) -> Catalog:
    """``catalog``'s stars and the planets above ``MIN_ALTITUDE_DEG`` at ``site`` and ``utc``,
    by magnitude (its name says so)."""
    both = planets(site, utc)
    ids = np.concatenate([catalog.ids, both.ids])
    ra = np.concatenate([catalog.ra_deg, both.ra_deg])
    dec = np.concatenate([catalog.dec_deg, both.dec_deg])
    mag = np.concatenate([catalog.mag, both.mag])
    joined = Catalog(ids, ra, dec, mag, catalog.name)
    up = altitudes_deg(joined, site, utc) >= MIN_ALTITUDE_DEG
    order = np.argsort(mag[up], kind="stable")
    rows = np.flatnonzero(up)[order]
    name = f"{catalog.name} and planets above the horizon at {parse_utc(utc).isot[:19]} UTC"
    return Catalog(ids[rows], ra[rows], dec[rows], mag[rows], name)
