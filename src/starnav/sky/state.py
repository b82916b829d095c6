"""The sky's state over a solved frame: which catalog stars should be seen and are, turned into
clear / cloudy sky over the frame and per altitude-azimuth cell, with the limiting magnitude
reached per region (the product of a cloud monitor).

Every catalog star the solution puts inside the sky area (the image circle of a circular
fisheye, above ``min_alt_deg`` when the site and time are known, away from the Moon's glare)
is tested where it is predicted: aperture photometry in the zones of the frame's PSF above a
plane fitted to the surrounding annulus (``starnav.detect.photometry.local_photometry``). A
star is *seen* when its flux is above ``snr_seen`` times the annulus noise in the aperture,
so a star below the detection list's cut counts. A star with a brighter catalog star within
two aperture radii is not tested (the brighter one's light would answer for it).

Which stars a clear sky would show is read from the frame itself: the limiting magnitude
(below) of each altitude-azimuth cell, the best cells' (the 75th percentile over the cells
that reach one, at least a quarter of them and 3) less ``LIMIT_MARGIN`` is the clear-sky
limit, and the stars to it are *expected*. With a site, magnitudes are first dimmed by the
extinction of their airmass (``extinction_mag`` per airmass above the zenith's), so a clear
horizon is not taken for cloud. With too few cells reaching a limit (an overcast frame), or
when ``mag_limit`` is given (the camera's clear-sky limit, known from clear nights), the stars
to ``mag_limit`` are expected (default ``FALLBACK_MAG``, what any all-sky camera records). On
a thinly covered frame the best cells set a brighter limit than a clear night's, so the cloud
is seen only where it is thicker than the rest: give ``mag_limit`` to judge against the clear
sky.

Regions are judged by the fraction of their expected stars seen, each star weighted by how
much brighter than the limit it is (0.5 + the margin in magnitudes, up to 2: a bright star
missing is a cloud, a star at the limit missing is noise): clear from ``CLEAR_FRACTION``,
cloudy below ``CLOUDY_FRACTION``, partly in between, "no data" with fewer than
``MIN_CELL_STARS`` expected. The map over the frame is that fraction smoothed with a Gaussian
of ``map_sigma_deg`` on the sky. A region's limiting magnitude is where the seen fraction of
its tested stars, in half-magnitude bins from the brightest, first falls below one half (the
upper edge of the last bin above).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.catalog.sky import Site as GroundSite
from starnav.detect.circle import ImageCircle
from starnav.detect.photometry import local_photometry, zones
from starnav.errors import StarnavError, shown
from starnav.geometry import radec_to_unit

SNR_SEEN = 3.0
LIMIT_PERCENTILE = 75.0
LIMIT_MARGIN = 0.75
MIN_LIMIT_CELLS = 3
EXTINCTION_MAG = 0.2  # per airmass: a clear site's V band
FALLBACK_MAG = 3.5
CLEAR_FRACTION = 0.7
CLOUDY_FRACTION = 0.3
MIN_CELL_STARS = 3
MIN_ALT_DEG = 10.0
MOON_GLARE_DEG = 15.0
MAP_SIGMA_DEG = 8.0
MAP_NODES = 100  # map nodes across the image's long side
_MAP_CHUNK = 256
CIRCLE_MARGIN_PX = 8.0
BLEND_RADII = 2.0
MAG_BIN = 0.5
SHIFT_STARS = 600
SHIFT_SEARCH_PX = 12.0
SHIFT_MATCH_PX = 3.0
SHIFT_NEIGHBOURS = 9
AZIMUTH_SECTORS = 8
ALTITUDE_EDGES_DEG = (MIN_ALT_DEG, 30.0, 50.0, 70.0, 90.0)
_WEIGHT_RANGE = (0.5, 2.0)
STATES = ("clear", "partly", "cloudy", "no data")


@dataclass(frozen=True)
class Site(GroundSite):
    """Where and when the frame was taken: a ``catalog.sky.Site`` (geodetic WGS84 latitude,
    longitude, degrees, East positive, height, m: checked there) with the ``utc`` (ISO 8601)."""

    utc: str = ""


@dataclass(frozen=True)
class SkyCell:
    """One region of the sky: altitude ``alt_min_deg``..``alt_max_deg`` and azimuth
    ``az_min_deg``..``az_max_deg`` (from North through East; with no site, the angle from the
    boresight and the azimuth about it from the image's up through its right), the stars
    ``n_expected`` and ``n_seen`` of them, the weighted ``seen_fraction`` (None: no data),
    ``state`` (clear / partly / cloudy / no data) and ``limiting_mag`` (None: too few stars
    or not even the brightest bin reached)."""

    alt_min_deg: float
    alt_max_deg: float
    az_min_deg: float
    az_max_deg: float
    n_expected: int
    n_seen: int
    seen_fraction: float | None
    state: str
    limiting_mag: float | None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True, eq=False)
class SkyState:
    """The sky's state over one frame (see the module's docstring).

    Per tested star (arrays of one length): catalog ``ids``, ``mag``, predicted pixel ``xy``
    (n, 2, our convention), ``alt_deg``/``az_deg`` (altitude and azimuth, or with no site the
    boresight-relative angles of ``SkyCell``), ``snr`` at the prediction, ``seen`` and
    ``expected``; ``mag_limit``: the clear-sky limit the stars are expected to (extinction
    taken out); ``expected_by``: "clear cells" (the frame's best cells), "given" or
    "fallback" (``FALLBACK_MAG``); ``clear_fraction``: the weighted seen fraction of the
    expected stars over the whole sky (None: fewer than ``MIN_CELL_STARS`` expected);
    ``limiting_mag``: that of the clear cells' stars (None: no clear cell); ``cells``: the
    altitude-azimuth cells, zenith ring last; ``altaz``: True when the cells are altitude /
    azimuth (site and time known), False when boresight-relative; ``map_fraction``: the
    smoothed seen fraction on a grid (rows, cols; NaN outside the sky or with no data) whose
    node (i, j) is at pixel (``map_step_px`` * (j + 0.5), ``map_step_px`` * (i + 0.5));
    ``moon_altaz_deg``: the Moon's (alt, az) when known; ``site``; ``R_frame_from_icrs``: the
    rotation from ICRS to the cells' frame (East, North, Up; or the camera's, ``_frame_of``)."""

    ids: np.ndarray
    mag: np.ndarray
    xy: np.ndarray
    alt_deg: np.ndarray
    az_deg: np.ndarray
    snr: np.ndarray
    seen: np.ndarray
    expected: np.ndarray
    expected_by: str
    mag_limit: float | None
    clear_fraction: float | None
    limiting_mag: float | None
    cells: tuple[SkyCell, ...]
    altaz: bool
    map_fraction: np.ndarray
    map_step_px: int
    moon_altaz_deg: tuple[float, float] | None
    site: Site | None
    R_frame_from_icrs: np.ndarray

    @property
    def state(self) -> str:
        """The whole sky's state from ``clear_fraction``."""
        return _state(self.clear_fraction)

    def cell_counts(self) -> dict[str, int]:
        """How many cells are in each state."""
        return {s: sum(c.state == s for c in self.cells) for s in STATES}

    def to_dict(self) -> dict:
        """JSON: the summary, the cells, and the tested stars (id, mag, x, y, alt, az, snr,
        seen, expected)."""
        stars = [
            {
                "catalog_id": int(i),
                "mag": round(float(m), 3),
                "x": round(float(x), 2),
                "y": round(float(y), 2),
                "alt_deg": round(float(a), 3),
                "az_deg": round(float(z), 3),
                "snr": round(float(s), 2) if np.isfinite(s) else None,
                "seen": bool(v),
                "expected": bool(e),
            }
            for i, m, (x, y), a, z, s, v, e in zip(
                self.ids, self.mag, self.xy, self.alt_deg, self.az_deg, self.snr,
                self.seen, self.expected, strict=True,
            )
        ]  # fmt: skip
        return {
            "state": self.state,
            "clear_fraction": self.clear_fraction,
            "limiting_mag": self.limiting_mag,
            "expected_by": self.expected_by,
            "mag_limit": self.mag_limit,
            "n_tested": len(self.ids),
            "n_expected": int(self.expected.sum()),
            "n_seen": int(self.seen.sum()),
            "n_expected_seen": int((self.seen & self.expected).sum()),
            "cells_frame": "altaz" if self.altaz else "camera",
            "cell_counts": self.cell_counts(),
            "moon_alt_deg": None if self.moon_altaz_deg is None else self.moon_altaz_deg[0],
            "moon_az_deg": None if self.moon_altaz_deg is None else self.moon_altaz_deg[1],
            "site": None if self.site is None else dict(self.site.__dict__),
            "cells": [c.to_dict() for c in self.cells],
            "stars": stars,
        }


def enu_from_icrs(site: Site) -> np.ndarray:
    """The rotation (3, 3) taking ICRS unit vectors to (East, North, Up) at the site and time
    (apparent places from astropy, ``navigation.frames.enu_directions``: aberration makes it
    a rotation only to ~20 arcsec, fitted to six directions)."""
    from starnav.navigation.frames import enu_directions, parse_utc

    ra = np.array([0.0, 90.0, 0.0, 180.0, 270.0, 0.0])
    dec = np.array([0.0, 0.0, 90.0, 0.0, 0.0, -90.0])
    enu = enu_directions(
        ra, dec, parse_utc(site.utc), lat_deg=site.lat_deg, lon_deg=site.lon_deg,
        height_m=site.height_m,
    )  # fmt: skip
    icrs = radec_to_unit(np.radians(ra), np.radians(dec))
    u, _, vt = np.linalg.svd(enu.T @ icrs)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def moon_altaz_deg(site: Site) -> tuple[float, float]:
    """The Moon's apparent (altitude, azimuth) in degrees at the site and time (astropy)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, get_body
    from astropy.utils import iers

    from starnav.navigation.frames import parse_utc

    t = parse_utc(site.utc)
    where = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                        site.height_m * u.m)  # fmt: skip
    with iers.conf.set_temp("auto_download", False):
        aa = get_body("moon", t, where).transform_to(AltAz(obstime=t, location=where))
    return float(aa.alt.deg), float(aa.az.deg % 360.0)


def _altaz(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Altitude and azimuth (degrees, azimuth 0..360) of (n, 3) vectors whose third axis is
    up and whose first two are (East, North)-like."""
    alt = np.degrees(np.arcsin(np.clip(v[:, 2], -1.0, 1.0)))
    az = np.degrees(np.arctan2(v[:, 0], v[:, 1])) % 360.0
    return alt, az


def _frame_of(R_cam_from_icrs: np.ndarray, site: Site | None) -> np.ndarray:
    """The rotation from ICRS to the frame the cells are drawn in: ENU with a site; else the
    camera's own, re-axed so that "up" is the boresight (z), "North" the image's up (-y) and
    "East" the image's right (x)."""
    if site is not None:
        return enu_from_icrs(site)
    cam_to_local = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    return cam_to_local @ np.asarray(R_cam_from_icrs)


def airmass(alt_deg: np.ndarray) -> np.ndarray:
    """Relative airmass at altitudes (degrees), Kasten & Young (1989)."""
    h = np.maximum(np.asarray(alt_deg, dtype=float), 0.0)
    return 1.0 / (np.sin(np.radians(h)) + 0.50572 * (h + 6.07995) ** -1.6364)


def _state(fraction: float | None) -> str:
    if fraction is None:
        return "no data"
    if fraction >= CLEAR_FRACTION:
        return "clear"
    return "cloudy" if fraction < CLOUDY_FRACTION else "partly"


def limiting_magnitude(mag: np.ndarray, seen: np.ndarray, *, bin_mag: float = MAG_BIN):
    """The magnitude where the seen fraction of stars (``mag``, ``seen``), in bins of
    ``bin_mag`` from the brightest star, first falls below one half: the upper edge of the
    last bin at or above; bins of fewer than 3 stars are joined to the next. None when the
    first bin is already below one half or there are fewer than 3 stars."""
    if len(mag) < 3:
        return None
    order = np.argsort(mag)
    m, s = np.asarray(mag)[order], np.asarray(seen)[order]
    lo, last, start = float(m[0]), None, 0
    while start < len(m):
        hi = lo + bin_mag
        stop = int(np.searchsorted(m, hi, side="right"))
        while stop - start < 3 and stop < len(m):
            hi += bin_mag
            stop = int(np.searchsorted(m, hi, side="right"))
        if stop - start < 3:
            break
        if s[start:stop].mean() < 0.5:
            break
        last, lo, start = hi, hi, stop
    return None if last is None else round(last, 2)


def sky_state(
    image: np.ndarray,
    *,
    R_cam_from_icrs: np.ndarray,
    camera: CameraModel,
    catalog: Catalog,
    psf_sigma_px: float,
    circle: ImageCircle | None = None,
    detected_xy: np.ndarray | None = None,
    site: Site | None = None,
    mag_limit: float | None = None,
    snr_seen: float = SNR_SEEN,
    extinction_mag: float = EXTINCTION_MAG,
    min_alt_deg: float = MIN_ALT_DEG,
    moon_glare_deg: float = MOON_GLARE_DEG,
    map_sigma_deg: float = MAP_SIGMA_DEG,
) -> SkyState:
    """The sky's state of ``image`` (2-D, row 0 at the top) solved as ``R_cam_from_icrs``
    with ``camera``: every star of ``catalog`` in the sky area tested at its predicted pixel
    (corrected by ``local_shift`` with ``detected_xy``, the frame's detections, (n, 2) px) in
    the zones of ``psf_sigma_px`` (px); ``circle``: the fisheye's image circle (the sky is
    inside it, less ``CIRCLE_MARGIN_PX``); ``site``: latitude, longitude, height and UTC
    (altitude cut ``min_alt_deg``, the Moon's glare ``moon_glare_deg`` masked, alt-az
    cells, extinction ``extinction_mag`` per airmass); ``mag_limit``: the clear-sky limiting
    magnitude to expect stars to (default: from the frame's best cells). See the module's
    docstring for the method."""
    data = np.asarray(image, dtype=np.float64)
    if data.ndim != 2 or data.shape != (camera.height, camera.width):
        raise StarnavError(
            f"image shape {data.shape} does not match the camera ({camera.height}, {camera.width})"
        )
    checks = (("snr_seen", snr_seen), ("psf_sigma_px", psf_sigma_px),
              ("map_sigma_deg", map_sigma_deg))  # fmt: skip
    for name, value in checks:
        if not (math.isfinite(value) and value > 0):
            raise StarnavError(f"{name} must be a positive number, got {shown(value)}")
    if mag_limit is not None and not math.isfinite(mag_limit):
        raise StarnavError(f"mag_limit must be a finite magnitude, got {shown(mag_limit)}")
    R = np.asarray(R_cam_from_icrs, dtype=np.float64)
    to_local = _frame_of(R, site)
    moon = moon_altaz_deg(site) if site is not None else None

    if not (math.isfinite(extinction_mag) and extinction_mag >= 0):
        raise StarnavError(f"extinction_mag must be >= 0, got {shown(extinction_mag)}")
    rows, xy, alt, az = _in_sky(catalog, R, camera, to_local, circle, site and min_alt_deg,
                                moon, moon_glare_deg, psf_sigma_px)  # fmt: skip
    mag = catalog.mag[rows]
    if detected_xy is not None:
        xy = local_shift(xy, mag, np.asarray(detected_xy, dtype=float).reshape(-1, 2))
    phot = local_photometry(data, None, xy[:, 0] - 0.5, xy[:, 1] - 0.5, psf_sigma_px)
    aperture_noise = phot.noise * np.sqrt(np.maximum(phot.n_aperture, 1))
    snr = np.where(aperture_noise > 0, phot.flux / aperture_noise, np.nan)
    seen = np.nan_to_num(snr, nan=0.0) >= snr_seen

    m_eff = mag
    if site is not None:
        m_eff = mag + extinction_mag * (airmass(alt) - 1.0)
    low = min_alt_deg if site else None
    expected_by, used_limit = _expected_limit(alt, az, m_eff, seen, low, camera, mag_limit)
    expected = m_eff <= used_limit
    weight = np.clip(0.5 + used_limit - m_eff, *_WEIGHT_RANGE) * expected

    cells = _cells(alt, az, m_eff, seen, expected, weight, low, camera)
    map_fraction = _map(camera, circle, R, xy, seen, weight, map_sigma_deg)
    total = float(weight.sum())
    clear = None if expected.sum() < MIN_CELL_STARS else float((weight * seen).sum() / total)
    return SkyState(
        ids=catalog.ids[rows],
        mag=mag,
        xy=xy,
        alt_deg=alt,
        az_deg=az,
        snr=snr,
        seen=seen,
        expected=expected,
        expected_by=expected_by,
        mag_limit=used_limit,
        clear_fraction=clear,
        limiting_mag=_clear_limit(cells, alt, az, m_eff, seen),
        cells=cells,
        altaz=site is not None,
        map_fraction=map_fraction,
        map_step_px=map_step_px(camera),
        moon_altaz_deg=moon,
        site=site,
        R_frame_from_icrs=to_local,
    )


def _in_sky(catalog, R, camera, to_local, circle, min_alt_deg, moon, moon_glare_deg, psf_sigma_px):
    """The catalog rows judged, their pixels and (alt, az): in the camera's view, off the
    image's edge by the photometry's annulus, inside the image circle, above ``min_alt_deg``
    (None: no cut) and away from the Moon, with no brighter star within ``BLEND_RADII``
    apertures."""
    c = catalog.vectors @ R.T
    rows = np.flatnonzero(camera.sees(c))
    xy = camera.bearings_to_pixels(c[rows])
    local = catalog.vectors[rows] @ to_local.T
    alt, az = _altaz(local)
    keep = np.isfinite(xy).all(axis=1)
    r_ap, _, r_out = zones(psf_sigma_px)
    edge = r_out + 1.0
    keep &= (xy[:, 0] > edge) & (xy[:, 0] < camera.width - edge)
    keep &= (xy[:, 1] > edge) & (xy[:, 1] < camera.height - edge)
    if circle is not None:
        keep &= np.hypot(xy[:, 0] - circle.cx, xy[:, 1] - circle.cy) < (
            circle.radius_px - CIRCLE_MARGIN_PX
        )
    if min_alt_deg is not None:
        keep &= alt >= min_alt_deg
    if moon is not None and moon[0] > -1.0:
        # (East, North, Up) of the Moon: radec_to_unit(lon, lat) with lon measured from East,
        # which is 90 deg - azimuth
        m = radec_to_unit(np.radians(90.0 - moon[1]), np.radians(moon[0]))
        keep &= np.degrees(np.arccos(np.clip(local @ m, -1.0, 1.0))) > moon_glare_deg
    rows, xy, alt, az = rows[keep], xy[keep], alt[keep], az[keep]
    tested = _unblended(xy, catalog.mag[rows], BLEND_RADII * r_ap)
    return rows[tested], xy[tested], alt[tested], az[tested]


def _expected_limit(alt, az, m_eff, seen, low, camera, mag_limit) -> tuple[str, float]:
    """How the stars are expected and to which magnitude: ("given", ``mag_limit``), else
    ("clear cells", the best cells' limit less ``LIMIT_MARGIN``), else ("fallback",
    ``FALLBACK_MAG``) when too few cells reach a limit."""
    if mag_limit is not None:
        return "given", float(mag_limit)
    none = np.zeros(len(seen))
    trial = _cells(alt, az, m_eff, seen, none.astype(bool), none, low, camera)
    limits = [c.limiting_mag for c in trial if c.limiting_mag is not None]
    if len(limits) >= max(MIN_LIMIT_CELLS, len(trial) / 4):
        return "clear cells", round(
            float(np.percentile(limits, LIMIT_PERCENTILE)) - LIMIT_MARGIN, 2
        )
    return "fallback", FALLBACK_MAG


def camera_half_fov_deg(camera: CameraModel) -> float:
    """Half the angle the camera sees across its image diagonal, at most 90 degrees (degrees):
    with no site, the stars within it of the boresight are kept."""
    return min(90.0, math.degrees(camera.half_diagonal_rad))


def local_shift(xy: np.ndarray, mag: np.ndarray, detected_xy: np.ndarray) -> np.ndarray:
    """The predicted pixels ``xy`` moved by the local error of the solution: a lens model
    that fits a real fisheye to a pixel on average can be off by several pixels in places.
    The ``SHIFT_STARS`` brightest predictions are paired with their nearest detection within
    ``SHIFT_SEARCH_PX`` (then, after a first correction, within ``SHIFT_MATCH_PX``); each
    prediction moves by the median offset of its ``SHIFT_NEIGHBOURS`` nearest pairs. Fewer
    than ``SHIFT_NEIGHBOURS`` pairs: unchanged."""
    from scipy.spatial import cKDTree

    if len(detected_xy) < SHIFT_NEIGHBOURS or len(xy) < SHIFT_NEIGHBOURS:
        return xy
    tree = cKDTree(detected_xy)
    bright = np.argsort(mag, kind="stable")[:SHIFT_STARS]
    shift = np.zeros_like(xy)
    for radius in (SHIFT_SEARCH_PX, SHIFT_MATCH_PX):
        d, j = tree.query(xy[bright] + shift[bright], distance_upper_bound=radius)
        ok = np.isfinite(d)
        if ok.sum() < SHIFT_NEIGHBOURS:
            return xy + shift
        at = xy[bright[ok]]
        offset = detected_xy[j[ok]] - at
        _, near = cKDTree(at).query(xy, k=SHIFT_NEIGHBOURS)
        shift = np.median(offset[near], axis=1)
    return xy + shift


def _clear_limit(cells, alt, az, mag, seen) -> float | None:
    """The limiting magnitude of the stars in the clear cells (None: no clear cell)."""
    clear = [c for c in cells if c.state == "clear"]
    if not clear:
        return None
    inside = np.zeros(len(mag), dtype=bool)
    for c in clear:
        inside |= (
            (alt >= c.alt_min_deg)
            & (alt <= c.alt_max_deg)
            & (az >= c.az_min_deg)
            & (az < c.az_max_deg + (1e-9 if c.az_max_deg >= 360 else 0.0))
        )
    return limiting_magnitude(mag[inside], seen[inside])


def _unblended(xy: np.ndarray, mag: np.ndarray, radius_px: float) -> np.ndarray:
    """True for stars with no brighter star within ``radius_px``."""
    from scipy.spatial import cKDTree

    keep = np.ones(len(xy), dtype=bool)
    if len(xy) < 2:
        return keep
    for i, j in cKDTree(xy).query_pairs(radius_px):
        keep[j if mag[j] >= mag[i] else i] = False
    return keep


def _cells(alt, az, mag, seen, expected, weight, min_alt_deg, camera) -> tuple[SkyCell, ...]:
    """The altitude rings (``ALTITUDE_EDGES_DEG``; with no site: rings of the same width from
    the edge of the camera's view to the boresight) times ``AZIMUTH_SECTORS`` sectors, the
    last ring (the zenith's) one cell."""
    if min_alt_deg is None:
        low = 90.0 - camera_half_fov_deg(camera)
        edges = np.linspace(low, 90.0, len(ALTITUDE_EDGES_DEG))
    else:
        edges = np.array(ALTITUDE_EDGES_DEG, dtype=float)
    sector = 360.0 / AZIMUTH_SECTORS
    out = []
    for k, (a0, a1) in enumerate(itertools.pairwise(edges)):
        top = k == len(edges) - 2
        for s in range(1 if top else AZIMUTH_SECTORS):
            z0, z1 = (0.0, 360.0) if top else (s * sector, (s + 1) * sector)
            inside = (alt >= a0) & (alt < a1 + (1e-9 if top else 0.0))
            inside &= (az >= z0) & (az < z1)
            exp = inside & expected
            n_exp = int(exp.sum())
            fraction = None
            if n_exp >= MIN_CELL_STARS:
                fraction = round(float((weight[exp] * seen[exp]).sum() / weight[exp].sum()), 3)
            out.append(
                SkyCell(
                    alt_min_deg=round(float(a0), 2),
                    alt_max_deg=round(float(a1), 2),
                    az_min_deg=z0,
                    az_max_deg=z1,
                    n_expected=n_exp,
                    n_seen=int((exp & seen).sum()),
                    seen_fraction=fraction,
                    state=_state(fraction),
                    limiting_mag=limiting_magnitude(mag[inside], seen[inside]),
                )
            )
    return tuple(out)


def map_step_px(camera: CameraModel) -> int:
    """The map's grid step (px): ``MAP_NODES`` nodes across the long side."""
    return max(1, math.ceil(max(camera.width, camera.height) / MAP_NODES))


def _map(camera, circle, R, xy, seen, weight, sigma_deg) -> np.ndarray:
    """The seen fraction smoothed over the sky (Gaussian of ``sigma_deg`` in angle) on a grid
    of ``map_step_px`` px; NaN outside the sky area and where the expected stars' weight
    within the kernel is below 1 (less than one bright star's worth: no data)."""
    step = map_step_px(camera)
    rows = math.ceil(camera.height / step)
    cols = math.ceil(camera.width / step)
    gx, gy = np.meshgrid((np.arange(cols) + 0.5) * step, (np.arange(rows) + 0.5) * step)
    nodes = np.column_stack([gx.ravel(), gy.ravel()])
    out = np.full(len(nodes), np.nan)
    inside = np.ones(len(nodes), dtype=bool)
    if circle is not None:
        inside &= np.hypot(nodes[:, 0] - circle.cx, nodes[:, 1] - circle.cy) < circle.radius_px
    use = weight > 0
    if use.sum() and inside.any():
        node_v = camera.pixels_to_bearings(nodes[inside])
        star_v = camera.pixels_to_bearings(xy[use])
        w, s = weight[use], seen[use].astype(float)
        frac = np.full(len(node_v), np.nan)
        for i in range(0, len(node_v), _MAP_CHUNK):
            cos = np.clip(node_v[i : i + _MAP_CHUNK] @ star_v.T, -1.0, 1.0)
            k = np.exp(-0.5 * (np.degrees(np.arccos(cos)) / sigma_deg) ** 2) * w
            total = k.sum(axis=1)
            frac[i : i + _MAP_CHUNK] = np.where(
                total >= 1.0, (k @ s) / np.maximum(total, 1e-12), np.nan
            )
        ok = np.isfinite(node_v).all(axis=1)
        out[np.flatnonzero(inside)[ok]] = frac[ok]
    return out.reshape(rows, cols)


def read_mount(path: str | Path) -> tuple[np.ndarray, float | None]:
    """A fixed camera's mount from a JSON file: ``R_cam_from_enu`` (3, 3: the camera axes in
    East, North, Up) and the clear-sky limiting magnitude (None when the file has none). The
    file: the object ``starnav sky --json`` prints for a solved frame with a site (its "sky"
    holds both: a clear night's frame gives the camera's clear-sky limit), or one with
    "R_cam_from_enu" (and optionally "mag_limit") at the top; one-line errors."""
    import json

    try:
        data = json.loads(Path(path).read_text())
    except OSError as exc:
        raise StarnavError(f"cannot read the mount file {str(path)!r}: {exc.strerror}") from None
    except ValueError:
        raise StarnavError(f"the mount file {str(path)!r} is not JSON") from None
    if isinstance(data, dict) and isinstance(data.get("sky"), dict):
        data = data["sky"]
    if not isinstance(data, dict):
        data = {}
    try:
        R = np.array(data.get("R_cam_from_enu"), dtype=float)
    except (TypeError, ValueError):
        R = np.zeros(0)
    if (
        R.shape != (3, 3)
        or not np.isfinite(R).all()
        or not np.allclose(R @ R.T, np.eye(3), atol=1e-4)
    ):
        raise StarnavError(
            f"the mount file {str(path)!r} has no R_cam_from_enu rotation (a 3x3 orthonormal "
            "matrix; 'starnav sky --json' prints it for a frame solved with a site)"
        )
    limit = data.get("mag_limit")
    if limit is not None and not (isinstance(limit, int | float) and math.isfinite(limit)):
        raise StarnavError(f"the mount file {str(path)!r} has a mag_limit that is not a number")
    return R, None if limit is None else float(limit)


def mount_of(R_cam_from_icrs: np.ndarray, site: Site) -> np.ndarray:
    """The camera's mount ``R_cam_from_enu`` at the site and time from its solved attitude."""
    return np.asarray(R_cam_from_icrs) @ enu_from_icrs(site).T


def attitude_of(R_cam_from_enu: np.ndarray, site: Site) -> np.ndarray:
    """``R_cam_from_icrs`` of a camera fixed to the ground (its mount) at the site and time."""
    return np.asarray(R_cam_from_enu) @ enu_from_icrs(site)
