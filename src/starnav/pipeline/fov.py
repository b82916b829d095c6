"""Solving a star list whose field of view is unknown (or known only roughly).

The FOV range is searched with 4-star patterns matched up to a scale
(``starnav.pipeline.fov_search``); the identification then goes through the same attitude
fit and refusals as every solve, with the focal length (and, on request, the radial
distortion) fitted. Bands sit on one fixed grid of the diagonal field of view, 40° x
sqrt(2)^k, so every range and image shape shares the same cached tables.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from starnav.camera import Camera, CameraModel, Fisheye, focal_px_from_fov, model_class
from starnav.catalog import (
    DEFAULT_MAG_LIMIT,
    GAIA,
    Catalog,
    hipparcos_mags,
    is_embedded,
    load_catalog,
)
from starnav.catalog.sky import sky_at
from starnav.errors import CatalogError, StarnavError, shown
from starnav.geometry import radec_to_unit
from starnav.identify.base import SEARCH_SIGMA_PX, MatchSettings
from starnav.identify.database import build_database, catalog_only
from starnav.identify.pattern4 import FIELD_RADIUS_FRACTION, build_pattern_table
from starnav.pipeline.conclude import elapsed_ms
from starnav.pipeline.deep import DEEP_CHANCE, DEEP_MAG_LIMIT, MATCH_SIGMAS
from starnav.pipeline.fov_search import BAND_FACTOR, Band, FovMatch, search_fov
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.solver import Candidate, Solver, SolveSettings, first_use, fit_first
from starnav.pipeline.upward import enu_from_icrs, zenith_guesses
from starnav.results import SolveResult
from starnav.runtime.budget import (
    SEARCH_BUDGET_S,
    Deadline,
    check_budget,
    default_budget_s,
    expired,
    sooner,
)
from starnav.runtime.caches import process_cache
from starnav.starlist import StarList, check_star_list

if TYPE_CHECKING:  # the detection stack (sep) is not loaded for a star list's solve
    from starnav.detect.circle import ImageCircle

# the narrowest field searched: 0.625° along the image's longer side, the foot of the grid's
# 0.884° table (docs/narrow_fields.md); the whole-sky pattern tables of narrower bands would
# take 2x more lattice fields per grid step
FOV_LIMITS_DEG = Camera.fov_limits_deg  # (the lens classes hold the limits: these name them)
# before an image is read, its field is checked as if it were twice as tall as wide (the
# narrowest a portrait image may be across); the search checks it again on the image's shape
UNREAD_SHAPE = (1.0, 2.0)
LENS_FOV_LIMITS_DEG = Fisheye.fov_limits_deg  # the focal scan of a fisheye model
SCAN_STARS = 60  # the focal scan identifies the brightest this many stars,
SCAN_HYPOTHESES = 2000  # testing at most this many hypotheses per trial focal length
SCAN_TRIAL_S = 1.0  # and for at most this many seconds
GIVEN_FOV_TOLERANCE = 0.05  # a given FOV is searched within +-5 %
CAMERA_FOV_TOLERANCE = 0.01  # a calibrated camera's within +-1 %
_STARS_PER_FIELD = 40.0  # catalog depth of a band: mean stars in one of its pattern fields
FIELD_STARS = 15  # a known field's catalog: at least this many stars in an average image
# the deepest band catalog: Hipparcos is complete to Hp 7.3-9 (by galactic latitude), and
# its 56863 stars to Hp 8.5 keep a table's catalog rows 16-bit (below 65536)
_MAX_MAG = 8.5
_PATTERN_STARS_PER_FIELD = 10  # brightest stars of a lattice field making its patterns,
_FEWER_STARS_BELOW_DEG = 10.0  # one fewer per grid step below a 10° table (9, 8, 7, 6),
_MIN_PATTERN_STARS_PER_FIELD = 5  # and never fewer than 5 (5 patterns a field)
NEAR_STARS_PER_FIELD = 12  # a position hint's own table (``near_bands``): 495 patterns a
NEAR_OVERSAMPLING = 25.0  # field, on a lattice 4x coarser than a whole-sky table's,
NEAR_PATTERN_STARS = 25  # searched with patterns of the brightest 25 points (not 15)
# bands whose tables are built for diagonals under this are cut from the embedded Gaia DR3
# (G <= 10) instead of Hipparcos: the grid's 5° band and narrower (fields under ~4°), where
# Hipparcos to Hp 8.5 holds 20 stars per pattern field or fewer, half the depth rule's 40
# (at 7.07°: 39), and a telescope's frame shows many stars it lacks
GAIA_BELOW_DEG = 5.1
MAX_DIAGONAL_FOV_DEG = 150.0
# the fields an all-sky camera's image circle spans (degrees): a 180° lens's, a wider one's
# (to 230°), and a horizon of trees or domes found as a smaller disc (to 140°)
CIRCLE_FOV_RANGE_DEG = (140.0, 230.0)
NO_CIRCLE_DISC_DEG = 190.0  # a frame without image circle: its disc may be this wide across
LIT_DISC_FIELD_DEG = 100.0  # the narrowest field a lit disc (the sky inside trees) spans
MODEL_MATCH_DEG = 45.0  # models compared at the focal lengths that agree this far out
SCAN_INNER_DEG = 60.0  # a fisheye scan's trial identifies stars this close to the axis
SCAN_PRIOR_SIGMA_DEG = 1.0  # the whole list is matched near a trial's attitude, good to this
GUESS_CHECK_S = 0.3  # an upward camera's zenith guess is tracked (then searched) this long,
GUESS_SIGMA_DEG = 3.0  # taken as good to this (the votes' fit is good to ~0.1-0.5°)
CENTRE_FIT_STARS = 8  # a trial's principal point is fitted from this many matched stars on
CIRCLE_CENTRE_PX = 5.0  # an image circle's centre this far from the image's: both are tried
HINT_BUDGET_SHARE = 0.25  # of the time budget, for the search near a position hint
_SLIVER = 0.05  # a band narrower than this (relative) is merged into the next wider one
_DATABASES = process_cache("FOV-search catalogs")  # catalog vectors and KD-tree
_BANDS = process_cache("FOV-search bands")  # of a catalog, range and image shape


def band_grid(fov_lo_deg: float, fov_hi_deg: float) -> list[tuple[float, float, float]]:
    """The bands of the fixed grid 40° x sqrt(2)^k that overlap the range, widest first:
    (lo, hi) clipped to the range, and the grid band's upper angle (which its tables are
    built for). The grid is on the diagonal field of view (see ``diagonal_fov_deg``)."""
    k_hi = math.ceil(math.log(fov_hi_deg / 40.0) / math.log(BAND_FACTOR) - 1e-9)
    out = []
    top = 40.0 * BAND_FACTOR**k_hi
    while top > fov_lo_deg * (1.0 + 1e-9):
        bottom = top / BAND_FACTOR
        if bottom < fov_lo_deg * (1.0 + _SLIVER):  # the rest is a sliver: this band takes it
            bottom = fov_lo_deg
        out.append((max(bottom, fov_lo_deg), min(top, fov_hi_deg), top))
        top = bottom
    return out


def diagonal_fov_deg(fov_deg: float, width: int, height: int) -> float:
    """The field of view across the image diagonal (degrees) of a horizontal ``fov_deg``:
    the bands are cut on it, so images of every shape share the same tables."""
    return math.degrees(
        2.0 * math.atan(math.tan(math.radians(fov_deg) / 2.0) * math.hypot(width, height) / width)
    )


def horizontal_fov_deg(diagonal_deg: float, width: int, height: int) -> float:
    """The horizontal field of view (degrees) of a diagonal one (``diagonal_fov_deg``)."""
    return math.degrees(
        2.0
        * math.atan(math.tan(math.radians(diagonal_deg) / 2.0) * width / math.hypot(width, height))
    )


def band_mag_limit(diagonal_deg: float, sorted_mags: np.ndarray) -> float:
    """Magnitude limit of a band's catalog: about ``_STARS_PER_FIELD`` stars on average in
    a pattern field of the band's widest diagonal FOV, counted in the catalog's own sorted
    magnitudes (rounded up to 0.25 mag; the whole catalog when it is sparser: the embedded
    Hipparcos comes cut at ``_MAX_MAG``, Hp 8.5, by ``search_catalog``)."""
    radius = FIELD_RADIUS_FRACTION * math.radians(diagonal_deg) / 2.0
    needed = _STARS_PER_FIELD * 2.0 / (1.0 - math.cos(radius))  # 4 pi / field solid angle
    mag = sorted_mags[min(int(needed), len(sorted_mags) - 1)]
    return float(math.ceil(mag * 4.0) / 4.0)


@functools.lru_cache(maxsize=64)
def _hipparcos_depth(
    image_sr: float, diagonal_deg: float, circle_rad: float
) -> tuple[float, float | None]:
    mags = hipparcos_mags()
    band = band_mag_limit(diagonal_deg, mags[: np.searchsorted(mags, _MAX_MAG, "right")])
    in_image = np.searchsorted(mags, DEFAULT_MAG_LIMIT, "right") * image_sr / (4.0 * math.pi)
    mag_limit = DEFAULT_MAG_LIMIT if in_image >= FIELD_STARS else max(band, DEFAULT_MAG_LIMIT)
    deep_density = np.searchsorted(mags, DEEP_MAG_LIMIT, "right") / (4.0 * math.pi)  # per sr
    chance = deep_density * 2.0 * math.pi * (1.0 - math.cos(circle_rad))
    narrow = mag_limit > DEFAULT_MAG_LIMIT  # a field Hp 6 is too sparse for
    return mag_limit, DEEP_MAG_LIMIT if narrow and chance < DEEP_CHANCE else None


def known_field_depth(
    camera: CameraModel, options: SolveOptions
) -> tuple[float | None, float | str | None]:
    """The catalog depths of a solve through a known ``camera``: (the identification
    catalog's magnitude limit, the deep stage's). Each as ``options`` gives it; unset, for
    the embedded Hipparcos, they follow the field. The identification: Hp 6
    (``DEFAULT_MAG_LIMIT``) where that catalog holds ``FIELD_STARS`` stars in an average
    image (fields of 12° and wider: there a deeper catalog than the camera sees would make
    chance agreement likelier and refuse more few-star frames), else as deep as the FOV
    search's band of the field (``band_mag_limit``: Hp 8.5 at 6°). On such a narrow field,
    the deep stage (``pipeline.deep``) to ``DEEP_MAG_LIMIT`` where its match circle
    (``MATCH_SIGMAS`` of the told centroid sigma, else of ``SEARCH_SIGMA_PX``, 1 px) holds a
    chance catalog star for fewer than ``DEEP_CHANCE`` of the points: fine pixels, as a 6°
    star tracker's (it sees stars the identification catalog does not hold, and a false
    star rarely lands on one). A CSV or ``Catalog`` is used whole, with no deep stage unless
    told."""
    mag_limit, deep = options.mag_limit, options.deep_mag_limit
    if is_embedded(options.catalog):
        sigma_px = SEARCH_SIGMA_PX if options.sigma_px is None else options.sigma_px
        circle_rad = MATCH_SIGMAS * sigma_px / camera.scale_px_per_rad
        half_w = math.atan(camera.width / (2.0 * camera.focal_px))
        half_h = math.atan(camera.height / (2.0 * camera.focal_px))
        image_sr = 4.0 * math.asin(math.sin(half_w) * math.sin(half_h))  # a pinhole's
        field_mag, field_deep = _hipparcos_depth(
            round(image_sr, 9), round(camera.diagonal_deg, 6), circle_rad
        )
        mag_limit = field_mag if mag_limit is None else mag_limit
        deep = field_deep if deep is None else deep
    return mag_limit, deep


def band_stars_per_field(diagonal_deg: float) -> int:
    """Catalog stars per lattice field whose 4-subsets make the patterns of a table built
    for a ``diagonal_deg`` field: 10 down to the 10° table, one fewer per grid step below
    (9 at 7.07°, 8 at 5°, 7 at 3.54°, 6 at 2.5°), at least ``_MIN_PATTERN_STARS_PER_FIELD``
    (5 at 1.77° and 1.25°). Each step halves a field's area and so doubles the fields; C(k, 4)
    patterns per field falls about as fast (210, 126, 70, 35, 15, 5), which keeps a narrow
    band's table within 30-70 MB, and its patterns are of the brightest stars, those the
    catalogs hold most completely."""
    steps = math.log(_FEWER_STARS_BELOW_DEG / diagonal_deg) / math.log(BAND_FACTOR)
    fewer = max(0, math.ceil(steps - 1e-3))  # grid tops: whole steps
    return max(_PATTERN_STARS_PER_FIELD - fewer, _MIN_PATTERN_STARS_PER_FIELD)


def load_band(table_diagonal_deg: float, lo: float, hi: float, catalog: Catalog) -> Band | None:
    """One band (horizontal FOV ``lo``..``hi`` degrees of the image searched) with the
    catalog, KD-tree (in memory) and pattern table (in memory and on disk) of its grid band,
    built for a square field whose diagonal is ``table_diagonal_deg``; None when the catalog
    holds no 4-star pattern for it."""
    cat = catalog.brighter_than(band_mag_limit(table_diagonal_deg, _sorted_mags(catalog)))
    if len(cat) < 4:
        return None
    key = (cat.fingerprint, round(table_diagonal_deg, 6))
    if key not in _DATABASES:  # the search verifies only: no pair table
        _DATABASES[key] = catalog_only(cat, math.radians(table_diagonal_deg))
    database = _DATABASES[key]
    table = build_pattern_table(
        database,
        stars_per_field=band_stars_per_field(table_diagonal_deg),
        field_radius_fraction=FIELD_RADIUS_FRACTION,
    )
    # the database's catalog, not ``cat``: one copy of each band's catalog however many
    # ranges and image shapes share it
    return Band(lo, hi, database.catalog, database, table) if len(table) else None


def search_catalog(catalog: Catalog | str | Path | None, epoch_year: float | None) -> Catalog:
    """The catalog the bands are cut from: Hipparcos to Hp 8.5 (``_MAX_MAG``: Hipparcos is
    complete to Hp 7.3-9), or the whole CSV / ``Catalog`` given."""
    if is_embedded(catalog):
        return load_catalog(None, mag_limit=_MAX_MAG, epoch_year=epoch_year)
    return load_catalog(catalog, epoch_year=epoch_year)


def range_grid(lo: float, hi: float, width: int, height: int) -> list[tuple[float, float, float]]:
    """The grid bands (``band_grid``) of a horizontal FOV of ``lo``..``hi`` degrees across an
    image of ``width`` x ``height`` px: (horizontal lo, horizontal hi, the table's diagonal)."""
    return [
        (horizontal_fov_deg(a, width, height), horizontal_fov_deg(b, width, height), top)
        for a, b, top in band_grid(
            diagonal_fov_deg(lo, width, height), diagonal_fov_deg(hi, width, height)
        )
    ]


def band_source(
    table_diagonal_deg: float, catalog: Catalog | str | Path | None, full: Catalog
) -> Catalog:
    """The catalog a band is cut from: ``full`` (``search_catalog``'s), except for the
    embedded catalog's bands under ``GAIA_BELOW_DEG``, which take the embedded Gaia DR3."""
    return load_catalog(GAIA) if from_gaia(table_diagonal_deg, catalog) else full


def from_gaia(diagonal_deg: float, catalog: Catalog | str | Path | None) -> bool:
    """Whether a field of this diagonal (degrees) is cut from the embedded Gaia DR3: the
    embedded catalog's, under ``GAIA_BELOW_DEG``."""
    return is_embedded(catalog) and diagonal_deg < GAIA_BELOW_DEG


@functools.lru_cache(maxsize=8)
def _sorted_mags(catalog: Catalog) -> np.ndarray:
    return np.sort(catalog.mag)


def load_bands(
    lo: float,
    hi: float,
    width: int,
    height: int,
    catalog: Catalog | str | Path | None,
    epoch_year: float | None,
) -> list[Band]:
    """The bands searched for a horizontal FOV of ``lo``..``hi`` degrees across an image of
    ``width`` x ``height`` px."""
    diag_hi = diagonal_fov_deg(hi, width, height)
    if diag_hi > MAX_DIAGONAL_FOV_DEG:
        raise StarnavError(
            f"a {hi:g}° horizontal FOV on {width} x {height} px is {diag_hi:.0f}° across the "
            f"diagonal; the FOV search handles up to {MAX_DIAGONAL_FOV_DEG:g}°"
        )
    full = search_catalog(catalog, epoch_year)
    key = (full.fingerprint, round(lo, 9), round(hi, 9), width, height)
    if key in _BANDS:
        return _BANDS[key]
    bands = [
        load_band(top, a, b, band_source(top, catalog, full))
        for a, b, top in range_grid(lo, hi, width, height)
    ]
    bands = [band for band in bands if band is not None]
    if not bands:
        raise CatalogError(
            f"catalog {full.name!r} ({len(full)} stars) holds no 4-star pattern for a "
            f"{lo:g}-{hi:g}° field"
        )
    _BANDS[key] = bands
    return bands


def near_bands(
    lo: float,
    hi: float,
    width: int,
    height: int,
    catalog: Catalog | str | Path | None,
    epoch_year: float | None,
    near: tuple[np.ndarray, float],
) -> list[Band] | None:
    """The bands of a horizontal FOV of ``lo``..``hi`` degrees searched first near a position
    hint (``near``: unit vector, radius in rad), when the range reaches fields cut from the
    embedded Gaia (``GAIA_BELOW_DEG``; else None: the whole-sky bands are searched near the
    hint as they are). Each such band gets a table of the sky near the hint only (lattice
    fields centred within the hint's radius plus half the band's diagonal, the stars within
    its radius plus the whole diagonal) of the brightest ``NEAR_STARS_PER_FIELD`` (12) stars
    of each field, not the 5-7 of its whole-sky table: built in well under a second, never
    cached, it finds the telescope fields whose brightest points are not the catalog's
    brightest (saturated stars, colour), and the whole-sky tables (a minute each to build)
    are not needed when it does. The range's wider bands are loaded as ``load_bands`` does."""
    grid = range_grid(lo, hi, width, height)
    if not any(from_gaia(top, catalog) for _, _, top in grid):
        return None
    full = search_catalog(catalog, epoch_year)
    gaia = load_catalog(GAIA)
    widest = max(top for _, _, top in grid)
    cone = gaia.within(near[0], near[1] + math.radians(widest), gaia.name)  # once for every band
    out = []
    for a, b, top in grid:
        if not from_gaia(top, catalog):
            band = load_band(top, a, b, full)
            out += [] if band is None else [band]
            continue
        top_rad = math.radians(top)
        reach = near[1] + top_rad
        local = cone.within(
            near[0], reach, f"{gaia.name}, within {math.degrees(reach):.3g}° of the position hint"
        )
        if len(local) < 4:
            continue
        database = catalog_only(local, top_rad)
        table = build_pattern_table(
            database,
            stars_per_field=NEAR_STARS_PER_FIELD,
            field_radius_fraction=FIELD_RADIUS_FRACTION,
            oversampling=NEAR_OVERSAMPLING,
            region=(near[0], near[1] + 0.5 * top_rad),
        )
        if len(table):
            out.append(Band(a, b, local, database, table))
    return out or None


def check_fov_range(
    fov_range_deg: tuple[float, float], limits_deg: tuple[float, float], lens: str = "pinhole"
) -> tuple[float, float]:
    """The range as two floats within ``limits_deg`` (the ``lens`` model's), or a one-line
    error."""
    try:
        lo, hi = (float(v) for v in fov_range_deg)
    except (TypeError, ValueError):
        raise StarnavError(
            f"fov_range_deg must be two numbers (degrees), got {shown(fov_range_deg)}"
        ) from None
    a, b = limits_deg
    if not (a <= lo < hi <= b):
        a, b = model_class(lens).fov_limits_deg  # as the model states them: _narrower_why
        raise StarnavError(
            f"fov range must satisfy {a:g} <= low < high <= {b:g} degrees, got {lo:g} {hi:g}"
            + _narrower_why(lo, lens)
        )
    return lo, hi


def _narrower_why(fov_deg: float, lens: str) -> str:
    """Why the pinhole search stops where it does (the limits the errors state are the
    model's: a portrait image's is narrower across), for an error about a ``fov_deg``
    (degrees) under the model's; empty otherwise."""
    lo = model_class(lens).fov_limits_deg[0]
    if model_class(lens).kind != "pinhole" or not fov_deg < lo:
        return ""
    return (
        f" (the narrowest field searched is {lo:g}° along the image's longer side: the "
        "embedded Gaia DR3 catalog, G <= 10, holds about 3 stars in such a field away from "
        "clusters and the Milky Way, and whole-sky pattern tables of narrower fields would "
        "take 2x the lattice fields per grid step)"
    )


def fov_limits_deg(
    lens: str = "pinhole", shape: tuple[float, float] | None = None
) -> tuple[float, float]:
    """The horizontal fields of view (degrees) a given or searched FOV may take with the
    ``lens`` model: ``FOV_LIMITS_DEG`` for the pinhole (its FOV search),
    ``LENS_FOV_LIMITS_DEG`` for the fisheye models (their focal scan). The one definition
    ``search_range`` (images, plates, unknown-FOV lists) and the commands that take
    ``--fov-deg`` / ``--fov-range`` (``solve``, ``identify``, ``calibrate``) check against.

    The pinhole's narrowest field is along its image's longer side: a portrait image
    (``shape``: width, height in px; taller than wide) may be narrower across, as a Seestar
    S50's 1080 x 1920 px frames are (0.71° x 1.27°), since the tables are cut on the
    diagonal. No ``shape``: the limits the model states (a landscape image's); a check made
    before the image is read passes ``UNREAD_SHAPE``."""
    lo, hi = model_class(lens).fov_limits_deg
    if model_class(lens).kind != "pinhole" or shape is None:
        return lo, hi
    tall = max(1.0, shape[1] / shape[0])
    across = math.degrees(2.0 * math.atan(math.tan(math.radians(lo) / 2.0) / tall))
    return across, hi


def check_fov_deg(
    fov_deg: float, lens: str = "pinhole", shape: tuple[float, float] | None = None
) -> float:
    """``fov_deg`` (horizontal, degrees) as a float when the ``lens`` model takes it
    (``fov_limits_deg``; ``shape``: the image's width, height in px, when known), else a
    one-line error saying the range (and, below the pinhole's narrowest, why)."""
    lo, hi = fov_limits_deg(lens, shape)
    if not (np.isfinite(fov_deg) and lo <= fov_deg <= hi):
        lo, hi = model_class(lens).fov_limits_deg  # as the model states them: _narrower_why
        raise StarnavError(
            f"fov_deg must be within {lo:g}..{hi:g} degrees for the {lens} lens model, got "
            f"{shown(fov_deg)}" + _narrower_why(fov_deg, lens)
        )
    return float(fov_deg)


def search_range(
    fov_deg: float | None,
    fov_range_deg: tuple[float, float],
    camera: CameraModel | None,
    lens: str = "pinhole",
    shape: tuple[float, float] | None = None,
) -> tuple[float, float]:
    """The horizontal FOV range searched (degrees): within 1 % of a calibrated ``camera``,
    5 % of ``fov_deg``, or ``fov_range_deg``, each within ``fov_limits_deg(lens, shape)``
    (``shape``: the image's width, height in px, when known); a one-line error for a bad
    one."""
    if camera is not None:
        f = camera.fov_deg
        return f * (1 - CAMERA_FOV_TOLERANCE), f * (1 + CAMERA_FOV_TOLERANCE)
    if fov_deg is not None:
        check_fov_deg(fov_deg, lens, shape)
        return fov_deg * (1 - GIVEN_FOV_TOLERANCE), fov_deg * (1 + GIVEN_FOV_TOLERANCE)
    return check_fov_range(fov_range_deg, fov_limits_deg(lens, shape), lens)


def solve_unknown_field(
    xy: np.ndarray,
    options: SolveOptions,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: np.ndarray | None = None,
    labels: list[str] | tuple[str, ...] | None = None,
    prior: np.ndarray | None = None,
    position_hint_deg: tuple[float, float] | None = None,
    image_circle: ImageCircle | None = None,
) -> SolveResult:
    """Identify stars at ``xy`` (n, 2, px) in an image ``width`` x ``height`` px whose field
    of view is unknown: searched within ``options.search_range_deg`` (horizontal, degrees),
    or within 5 % of ``options.fov_deg``, or within 1 % of a calibrated ``options.camera``
    (whose principal point and distortion are then used). The solution's ``fov_deg`` /
    ``focal_px`` are fitted; ``fit_distortion`` fits k1, k2 as well (with at least 12 matched
    stars). A fisheye lens model, or a fisheye camera, is solved by ``scan_focal``
    (``mag_limit``: its catalog's, default Hp <= 6; the pinhole search picks a depth per band
    and takes none). ``prior``: the attitude of the previous frame of a sequence
    (``R_cam_from_icrs``, checked), with a camera (the previous frame's fitted one):
    tracking, falling back to lost in space with that camera (``tracking_solver``).
    ``position_hint_deg``: (RA, Dec) of the boresight, roughly (e.g. a FITS header's): the
    catalog within ``options.position_radius_deg`` of it is searched first, then the whole
    sky (the pinhole search). ``image_circle``: a circular fisheye's image circle found in
    the image (``detect.circle``), where the scan starts (``scan_starts``). The time budget
    counts once the tables are loaded."""
    camera = options.camera
    if camera is not None:
        width, height = camera.width, camera.height
    lens = options.lens_model
    height = width if height is None else height
    shape = None if width is None else (width, height)
    lo, hi = search_range(options.fov_deg, options.search_range_deg, camera, lens, shape)
    if camera is not None:
        base = camera
    elif not options.scans_focal:
        base = Camera.from_fov(0.5 * (lo + hi), width, height)
    else:  # the scan sets the focal length
        base = options.lens_class(int(width), int(height), 1.0)
    default_s = default_budget_s(
        known=options.field_known, scan=options.scans_focal, field_deg=base.diagonal_deg
    )
    budget_s = check_budget(options.time_budget_s, default_s)
    stars = check_star_list(
        xy, width=base.width, height=base.height, brightness=brightness, labels=labels
    )
    settings = SolveSettings.from_options(options, fit_focal=True)
    catalog, epoch_year, mag_limit = options.catalog, options.epoch_year, options.mag_limit
    if prior is not None:
        if camera is None:
            raise StarnavError("tracking (a prior) needs the camera, e.g. the previous frame's")
        reach = math.radians(camera.diagonal_deg / 2.0 + 5.0 * options.prior_sigma_deg)
        near_prior = (np.asarray(prior)[2], reach)  # the boresight, in ICRS
        solver = tracking_solver(camera, catalog, epoch_year, mag_limit, settings, near_prior)
        deadline = Deadline.after(budget_s)
        return solver.solve(
            stars, prior=prior, prior_sigma_deg=options.prior_sigma_deg, deadline=deadline
        )
    if options.scans_focal:
        starts = _scan_plan(base, camera, (lo, hi), options, image_circle)
        return _scan(stars, starts, options, settings, budget_s)
    near = hint_cone(position_hint_deg, options.position_radius_deg)
    known = options.fov_deg is not None or camera is not None
    ranges = [(lo, hi)] if known else searched_ranges(options, (lo, hi), shape)
    results, left_s = [], budget_s
    for k, (a, b) in enumerate(ranges):
        # the budget counts once the range's tables are loaded (built on first use); the
        # first range takes what it needs, the others share what it left equally
        share_s = left_s / max(1, len(ranges) - k) if k else left_s
        bands_near = None
        if near is not None:
            bands_near = near_bands(a, b, base.width, base.height, catalog, epoch_year, near)
        if bands_near is not None:  # a narrow field near a hint: its own tables first
            deadline = Deadline.after(HINT_BUDGET_SHARE * share_s)
            with first_use("solve"):
                result = _search_and_fit(
                    stars, base, bands_near, settings, (a, b),
                    max(options.pattern_stars, NEAR_PATTERN_STARS), deadline, None,
                )  # fmt: skip
            share_s -= result.time_ms / 1e3
            left_s -= result.time_ms / 1e3
            if result.solution is not None or share_s <= 0:
                results.append(result)
                break
        bands = load_bands(a, b, base.width, base.height, catalog, epoch_year)
        deadline = Deadline.after(share_s)
        with first_use("solve"):
            result = _search_and_fit(
                stars, base, bands, settings, (a, b), options.pattern_stars, deadline, near
            )
        results.append(result)
        left_s -= result.time_ms / 1e3
        if result.solution is not None or left_s <= 0:
            break
    result = _searched(results, ranges)
    if result.solution is None and near is not None and is_embedded(catalog):
        result = replace(result, reason=result.reason + _sparse_near(near, base, lo, hi))
    return result


def searched_ranges(
    options: SolveOptions, first: tuple[float, float], shape
) -> list[tuple[float, float]]:
    """The horizontal FOV ranges (degrees) searched in turn for a field not given: ``first``,
    then the lens model's extended ones, the narrowest reaching the image's own limit
    (``fov_limits_deg`` of its ``shape``: a portrait image's is lower)."""
    floor = fov_limits_deg(options.lens_model, shape)[0]
    stated = options.lens_class.fov_limits_deg[0]
    extended = [(floor if a == stated else a, b) for a, b in options.searched_ranges_deg[1:]]
    return [first] + [r for r in extended if r != first]


def _sparse_near(near: tuple[np.ndarray, float], base: Camera, lo: float, hi: float) -> str:
    """Why an unsolved field near a position hint may be beyond the embedded catalogs, or ""
    when they hold ``FIELD_STARS`` stars in such a field there: the Gaia DR3 stars within the
    hint's radius, scaled to the image's solid angle at the middle of the FOV range."""
    if not from_gaia(diagonal_fov_deg(lo, base.width, base.height), None):
        return ""
    n = len(load_catalog(GAIA).within(*near, "near the hint"))
    fov = 0.5 * (lo + hi)
    height = fov * base.height / base.width
    image_sr = math.radians(fov) * math.radians(height)
    stars = n * image_sr / (2.0 * math.pi * (1.0 - math.cos(near[1])))
    if stars >= FIELD_STARS:
        return ""
    return (
        f"; the embedded Gaia DR3 holds about {stars:.0f} stars (G <= 10) in a {fov:.2g}° x "
        f"{height:.2g}° field near the position hint, too few to identify surely: give a deeper "
        "catalog (--catalog FILE: a CSV or FITS table of RA, Dec and magnitude, such as a Gaia "
        "or Tycho-2 extract)"
    )


def _searched(results: list[SolveResult], ranges: list[tuple[float, float]]) -> SolveResult:
    """The outcome of the searches of one or more FOV ranges in turn: the last (solved, or
    the last tried), its reason naming each range's when more than one was searched, the
    times and hypotheses added up."""
    last = results[-1]
    if len(results) == 1:
        return last
    ms = sum(r.time_ms for r in results)
    hypotheses = sum(r.hypotheses for r in results)
    if last.solution is not None:
        return replace(last, time_ms=ms, hypotheses=hypotheses)
    reason = "; ".join(
        f"{a:g}-{b:g}°: {r.reason}" for (a, b), r in zip(ranges, results, strict=False)
    )
    return replace(last, reason=reason, time_ms=ms, hypotheses=hypotheses)


def hint_cone(
    position_hint_deg: tuple[float, float] | None, radius_deg: float
) -> tuple[np.ndarray, float] | None:
    """(unit vector, radius in rad) of a position hint (RA, Dec in degrees), or None."""
    if position_hint_deg is None:
        return None
    ra, dec = (math.radians(float(v)) for v in position_hint_deg)
    return radec_to_unit(ra, dec), math.radians(radius_deg)


_TRACKING = process_cache("tracking solvers", max_items=8)  # of the cameras tracked


def tracking_solver(
    camera: CameraModel,
    catalog: Catalog | str | Path | None,
    epoch_year: float | None,
    mag_limit: float | None,
    settings: SolveSettings,
    near: tuple[np.ndarray, float] | None = None,
) -> Solver:
    """The solver of a sequence's frames once a frame is solved: ``camera`` known, the catalog
    as deep as the FOV search's band of that field, from the same source (``band_source``)
    (a pinhole; a fisheye's: ``mag_limit``, default Hp <= 6), its pair database built on
    first use, kept per process. A pinhole field cut from the embedded Gaia DR3 (a diagonal
    under ``GAIA_BELOW_DEG``, whose whole-sky pair database would take ~0.5 GB) is tracked
    on the Gaia stars ``near`` the prior only (unit vector, radius in rad), their pairs
    built for that frame (milliseconds, never cached)."""
    searched = not camera.scans_focal and mag_limit is None
    if searched and near is not None and from_gaia(camera.diagonal_deg, catalog):
        gaia = load_catalog(GAIA)
        local = gaia.within(*near, f"{gaia.name}, within {math.degrees(near[1]):.3g}° of the prior")
        local = local.brighter_than(band_mag_limit(camera.diagonal_deg, _sorted_mags(gaia)))
        pairs = build_database(local, camera.diagonal_deg, use_cache=False)
        return Solver(camera, local, settings=settings, database=pairs)
    cat_key = catalog.fingerprint if isinstance(catalog, Catalog) else str(catalog)
    key = (camera, cat_key, epoch_year, mag_limit, settings)
    if key not in _TRACKING:
        if searched:
            full = search_catalog(catalog, epoch_year)
            cat = full.brighter_than(band_mag_limit(camera.diagonal_deg, _sorted_mags(full)))
        else:
            cat = load_catalog(catalog, mag_limit=mag_limit, epoch_year=epoch_year)
        _TRACKING[key] = Solver(camera, cat, settings=settings)
    return _TRACKING[key]


def lens_focal_range(
    base: CameraModel, camera: CameraModel | None, fov_range_deg: tuple[float, float]
) -> tuple[float, float]:
    """The focal lengths (px) a fisheye's scan tries: within ``CAMERA_FOV_TOLERANCE`` of a
    calibrated ``camera``'s, else those of the horizontal ``fov_range_deg`` through the lens
    model of ``base`` (with its coefficients), the range cut at the widest field the model
    maps."""
    if camera is not None:
        f = camera.focal_px
        return f / (1 + CAMERA_FOV_TOLERANCE), f * (1 + CAMERA_FOV_TOLERANCE)
    widest = math.degrees(2.0 * base.model_theta_max_rad)
    lo, hi = (min(v, widest) for v in fov_range_deg)
    coefficients = {name: getattr(base, name) for name in base.coefficients}
    f_lo, f_hi = (
        type(base).from_fov(v, base.width, base.height, **coefficients).focal_px for v in (hi, lo)
    )
    return f_lo, f_hi


def _scan(
    stars: StarList,
    starts: list[ScanStart],
    options: SolveOptions,
    settings: SolveSettings,
    budget_s: float,
) -> SolveResult:
    """The focal scan of ``starts`` on ``options``' catalog (``mag_limit``, default Hp <= 6),
    or, with a site and time, on its stars and the planets above the horizon
    (``catalog.sky.sky_at``), a camera of unknown lens first guessed looking up
    (``pipeline.upward``)."""
    cat = load_catalog(options.catalog, mag_limit=options.mag_limit, epoch_year=options.epoch_year)
    upward = None
    if options.site is not None and options.utc is not None:
        cat = sky_at(cat, options.site, options.utc)
        if options.camera is None:  # a camera of unknown lens: it may look up
            upward = enu_from_icrs(cat, options.site, options.utc)
    middle = math.sqrt(starts[0].focal_range_px[0] * starts[0].focal_range_px[1])
    solver = Solver(starts[0].base.with_focal(middle), cat, settings=settings)
    return scan_focal(stars, starts, solver, Deadline.after(budget_s), upward)


def _scan_plan(
    base: CameraModel,
    camera: CameraModel | None,
    fov_range_deg: tuple[float, float],
    options: SolveOptions,
    circle: ImageCircle | None,
) -> list[ScanStart]:
    """Every lens a focal scan tries (``scan_starts``): of each model of
    ``options.lens_models`` (a camera's only), each principal point's models in turn, the
    image circle's first."""
    bases = [base]
    if camera is None:
        size = (base.width, base.height)
        bases += [model_class(m)(*size, 1.0) for m in options.lens_models[1:]]
    per_model = [scan_starts(b, camera, fov_range_deg, options, circle) for b in bases]
    return [s for row in itertools.zip_longest(*per_model) for s in row if s is not None]


def scan_starts(
    base: CameraModel,
    camera: CameraModel | None,
    fov_range_deg: tuple[float, float],
    options: SolveOptions,
    circle: ImageCircle | None,
) -> list[ScanStart]:
    """The lenses a fisheye's focal scan tries: ``base`` over the focal lengths of the
    horizontal ``fov_range_deg`` (``lens_focal_range``; a calibrated ``camera``'s within 1 %);
    without an image circle the default range reaches a ``NO_CIRCLE_DISC_DEG`` sky disc as
    wide as the image's shorter side (a circular fisheye whose rim the trees hide: 235°
    across a 4:3 frame's width); with an image ``circle`` and no camera, first the circle's
    centre as principal point,
    the focal lengths that make the circle span ``CIRCLE_FOV_RANGE_DEG`` (those of the field
    when ``options`` give one; ±5 % of ``options.circle_fov_deg`` or ``options.focal_px``)
    from a 180° circle (or the one given) outward, then the image centre's, when the
    two lie more than ``CIRCLE_CENTRE_PX`` apart (a disc cut by the frame or by trees is
    found off its centre). A lit disc (``SkyMask.lit_disc``: sky inside a black surround,
    no edge seen, ``contrast`` 0) is a centre, and a radius short of the horizon's: its
    lens's 180° circle is scanned from as wide as the shorter side (``NO_CIRCLE_DISC_DEG``)
    to as narrow as makes the lit disc span ``LIT_DISC_FIELD_DEG``."""
    focal_range = lens_focal_range(base, camera, fov_range_deg)
    if camera is None and options.focal_px is not None:
        focal_range = _given_focal_range(options.focal_px)
    if camera is not None:
        return [ScanStart(base, focal_range)]
    unsaid = options.focal_px is None and options.fov_deg is None and options.fov_range_deg is None
    f_disc = base.focal_for_radius(0.5 * min(base.width, base.height), NO_CIRCLE_DISC_DEG)
    if circle is not None and circle.contrast <= 0.0:  # a lit disc, no lens's circle
        if unsaid and options.circle_fov_deg is None:
            at_lit = base.with_centre(circle.cx, circle.cy)
            f_far = at_lit.focal_for_radius(circle.radius_px, LIT_DISC_FIELD_DEG)
            return _at_and_centre(at_lit, base, (f_disc, max(f_disc, f_far)), f_disc)
        circle = None
    if circle is None:  # the disc perhaps cut by trees
        if unsaid:
            focal_range = (min(focal_range[0], f_disc), focal_range[1])
        return [ScanStart(base, focal_range)]
    at_circle = base.with_centre(circle.cx, circle.cy)
    field = 180.0 if options.circle_fov_deg is None else options.circle_fov_deg
    if options.fov_deg is None and options.fov_range_deg is None:
        wide, narrow = CIRCLE_FOV_RANGE_DEG[1], CIRCLE_FOV_RANGE_DEG[0]
        if options.circle_fov_deg is not None:
            wide, narrow = field * (1 + GIVEN_FOV_TOLERANCE), field / (1 + GIVEN_FOV_TOLERANCE)
        focal_range = tuple(at_circle.focal_for_radius(circle.radius_px, v) for v in (wide, narrow))
    if options.focal_px is not None:
        focal_range = _given_focal_range(options.focal_px)
        field = None
    lo, hi = focal_range
    first = options.focal_px
    if field is not None:
        first = min(max(at_circle.focal_for_radius(circle.radius_px, field), lo), hi)
    return _at_and_centre(at_circle, base, focal_range, first)


def _at_and_centre(
    at: CameraModel, base: CameraModel, focal_range: tuple[float, float], first: float | None
) -> list[ScanStart]:
    """A rough start at ``at``'s principal point, then at the image centre's (``base``'s)
    when the two lie more than ``CIRCLE_CENTRE_PX`` apart."""
    starts = [ScanStart(at, focal_range, first, rough=True)]
    if math.hypot(at.cx - base.cx, at.cy - base.cy) > CIRCLE_CENTRE_PX:
        starts.append(ScanStart(base, focal_range, first, rough=True))
    return starts


@dataclass(frozen=True)
class ScanStart:
    """One lens a focal scan tries: ``base`` (a model at a principal point), its focal lengths
    ``focal_range_px`` (px) and the one tried first, ``first_px`` (None: the middle);
    ``rough``: the principal point and the model are guesses (from an image circle), so the
    trials identify the stars near the axis only (``_scan_stars``)."""

    base: CameraModel
    focal_range_px: tuple[float, float]
    first_px: float | None = None
    rough: bool = False

    def focals(self, step: float) -> list[float]:
        """The trial focal lengths (px), ``step`` apart in log, from the first outward."""
        f_lo, f_hi = sorted(self.focal_range_px)
        start = math.sqrt(f_lo * f_hi) if self.first_px is None else self.first_px
        below = math.ceil(math.log(start / f_lo) / step - 1e-9)
        above = math.ceil(math.log(f_hi / start) / step - 1e-9)
        return [start * math.exp(step * k) for k in sorted(range(-below, above + 1), key=abs)]


def _given_focal_range(focal_px: float) -> tuple[float, float]:
    """The focal lengths (px) searched about a given one: within ``GIVEN_FOV_TOLERANCE``."""
    return focal_px / (1 + GIVEN_FOV_TOLERANCE), focal_px * (1 + GIVEN_FOV_TOLERANCE)


def scan_focal(
    stars: StarList,
    starts: Sequence[ScanStart],
    solver: Solver,
    deadline: Deadline | None = None,
    upward: np.ndarray | None = None,
) -> SolveResult:
    """Lenses of known model but unknown focal length: the ``solver``'s (focal length fitted)
    identification of the brightest ``SCAN_STARS`` (at most ``SCAN_HYPOTHESES`` each) at
    trial focal lengths of each of the ``starts`` (a model at a principal point, e.g. the
    image circle's centre and the image's), taken in turn, each from its first focal length
    outward, in steps small enough that the longest triangle side keeps within half the pair
    tolerance; the first verified one's fitted camera then solves the whole list (focal
    length free). ``deadline``: the scan stops when it passes (looked at in and between
    trials). (Triangles of sides up to 20° would cover 3x the range per trial but take ~10x
    the hypotheses to find, and missed a distorted lens seen as equidistant; 500 hypotheses
    per trial missed an equisolid sky at a 1 px tolerance.) ``upward``: ``R_enu_from_icrs``
    at the site and time of a camera that may look up, whose ``solver`` holds the sky above
    the horizon: each start's zenith guess (``pipeline.upward``) is tracked first."""
    t0 = time.perf_counter()
    result = None if upward is None else _upward_first(stars, starts, solver, upward, deadline)
    reason = ""
    if result is None:
        result, reason = _trials(stars, starts, solver, deadline)
    if result.solution is not None:
        result = _best_model(result, stars, starts, solver, deadline)
        if any(s.rough for s in starts):  # the principal point again, from every star matched
            fitted = _with_fitted_centre(result.solution, solver.database.catalog)
            R = result.solution.R_cam_from_icrs
            again = _matched_near(solver, fitted, stars, R, deadline)
            if again.solution is not None and again.solution.n_matched >= result.solution.n_matched:
                result = again
    ms = elapsed_ms(t0)
    if result.solution is not None:
        return replace(result, solution=replace(result.solution, time_ms=ms), time_ms=ms)
    return replace(result, reason=reason, time_ms=ms)


def _trials(
    stars: StarList, starts: Sequence[ScanStart], solver: Solver, deadline: Deadline | None
) -> tuple[SolveResult, str]:
    """``scan_focal``'s trials: the first whole-list solve of a trial that identifies, or
    the last trial's result, and the reason to give when unsolved."""
    f_hi = max(max(s.focal_range_px) for s in starts)
    tol_px = solver.match_settings.pair_tol_rad * solver.camera.scale_px_per_rad
    # a trial covers the focal lengths whose error on the longest side takes at most half the
    # pair tolerance (the centroid noise takes the rest), at the longest focal length
    step = 2.0 * math.log1p(0.5 * tol_px / (solver.database.max_angle_rad * f_hi))
    lists = [[(s.base.with_focal(f), s.rough) for f in s.focals(step)] for s in starts]
    trials = [c for row in itertools.zip_longest(*lists) for c in row if c is not None]
    lenses = ", ".join(sorted({s.base.model for s in starts}))
    ranges = f"{min(starts[0].focal_range_px):.1f}-{max(starts[0].focal_range_px):.1f} px"
    for tried, (camera, rough) in enumerate(trials, 1):
        few = _scan_stars(stars, camera, inner=rough)
        # a trial at a wrong focal length (or model) can draw thousands of catalog triangles
        # for each of its own: it stops after SCAN_TRIAL_S (one that identifies takes ~0.3 s)
        trial_deadline = sooner(SCAN_TRIAL_S, deadline)
        trial = solver.with_camera(camera, SCAN_HYPOTHESES).solve(few, deadline=trial_deadline)
        if trial.solution is not None:
            fitted = _with_fitted_centre(trial.solution, solver.database.catalog)
            result = _matched_near(solver, fitted, stars, trial.solution.R_cam_from_icrs, deadline)
            return result, (
                f"the brightest {len(few.xy)} stars identified at a focal length of "
                f"{trial.solution.focal_px:.1f} px, the whole list refused: {result.reason}"
            )
        if expired(deadline):
            return trial, deadline.reason(
                f"{tried} of {len(trials)} trial focal lengths over {ranges} tried ({lenses} lens)"
            )
    return trial, (
        f"no identification at {len(trials)} trial focal lengths over {ranges} ({lenses} "
        f"lens; last: {trial.reason})"
    )


def _upward_first(
    stars: StarList, starts: Sequence[ScanStart], solver: Solver, R_enu_from_icrs, deadline
) -> SolveResult | None:
    """The whole list tracked from the first zenith guess (``upward.zenith_guesses``) of the
    ``starts`` that verifies (each given ``GUESS_CHECK_S``), or None."""
    sky = solver.database.catalog
    for start in starts:
        for camera, R in zenith_guesses(
            stars.xy, stars.order, start.base, start.focal_range_px, sky, R_enu_from_icrs
        ):
            check = sooner(GUESS_CHECK_S, deadline)
            result = _matched_near(solver, camera, stars, R, check, GUESS_SIGMA_DEG)
            if result.solution is not None:
                return result
            if expired(deadline):
                return None
    return None


def _matched_near(
    solver: Solver,
    camera: CameraModel,
    stars: StarList,
    near,
    deadline,
    sigma_deg: float = SCAN_PRIOR_SIGMA_DEG,
):
    """The whole list solved through ``camera`` by tracking from the attitude ``near``
    (``R_cam_from_icrs``, good to ``sigma_deg``), falling back to lost in space."""
    return solver.with_camera(camera).solve(
        stars,
        prior=near,
        prior_sigma_deg=sigma_deg,
        deadline=deadline,
    )


def _best_model(result, stars: StarList, starts, solver: Solver, deadline) -> SolveResult:
    """With several models scanned, the solution of the one that fits ``stars`` best: each
    other model, at the solution's principal point with the focal length that puts a star
    ``MODEL_MATCH_DEG`` from the axis at the same radius, matches the whole list near the
    solution's attitude; the most stars matched, then the smallest rms, wins (a lens near
    one model also passes as its neighbour, with its stars far out falling short)."""
    found = result.solution
    camera = found.camera
    best = result
    field_deg = 2.0 * MODEL_MATCH_DEG
    radius_px = camera.focal_px / camera.focal_for_radius(1.0, field_deg)  # where 45° lands
    for other in {type(s.base): s.base for s in starts if s.base.model != camera.model}.values():
        trial = other.with_centre(camera.cx, camera.cy)
        trial = trial.with_focal(trial.focal_for_radius(radius_px, field_deg))
        r = _matched_near(solver, trial, stars, found.R_cam_from_icrs, deadline)
        s, b = r.solution, best.solution
        if s is not None and (s.n_matched, -s.rms_px) > (b.n_matched, -b.rms_px):
            best = r
    return best


def _scan_stars(stars: StarList, camera: CameraModel, *, inner: bool) -> StarList:
    """The brightest ``SCAN_STARS`` of ``stars``; ``inner``: those within ``SCAN_INNER_DEG``
    of ``camera``'s axis at its focal length, when there are at least half as many: near the
    axis a principal point a few percent of the radius off, or a lens between two models,
    changes the angles between stars least. (Not with a known centre: an unknown distortion
    grows outward, and the stars far out, left out of the trial, then miss the whole list's
    match.)"""
    rows = stars.order[:SCAN_STARS]
    if inner:
        theta = np.arccos(np.clip(camera.pixels_to_bearings(stars.xy)[:, 2], -1.0, 1.0))
        near = stars.order[theta[stars.order] <= math.radians(SCAN_INNER_DEG)][:SCAN_STARS]
        rows = near if len(near) >= SCAN_STARS // 2 else rows
    return StarList(stars.xy[rows], tuple(stars.labels[i] for i in rows), None)


def _with_fitted_centre(solution, catalog: Catalog) -> CameraModel:
    """The camera of a scan trial's ``solution`` with its principal point, focal length and
    attitude fitted by least squares to the trial's matched stars (scipy), so that the stars
    far from the axis, which the trial left out, fall where the whole list's solve looks for
    them; the trial's camera when fewer than ``CENTRE_FIT_STARS`` matched."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    table, camera = solution.star_table, solution.camera
    matched = table.catalog_id >= 0
    if matched.sum() < CENTRE_FIT_STARS:
        return camera
    xy = table.xy[matched]
    stars_icrs = catalog.vectors[catalog.rows(table.catalog_id[matched])]
    R0 = solution.R_cam_from_icrs

    def model(p):
        return camera.with_centre(p[4], p[5]).with_focal(camera.focal_px * math.exp(p[3]))

    def residuals(p):
        R = Rotation.from_rotvec(p[:3]).as_matrix() @ R0
        return (model(p).bearings_to_pixels(stars_icrs @ R.T) - xy).ravel()

    start = np.array([0.0, 0.0, 0.0, 0.0, camera.cx, camera.cy])
    fit = least_squares(residuals, start, loss="soft_l1", f_scale=2.0)
    return model(fit.x) if fit.success else camera


def fit_searched(
    xy: np.ndarray,
    stars: StarList,
    order: np.ndarray,
    bands: list[Band],
    base: Camera,
    settings: SolveSettings,
    fov_range: tuple[float, float],
    deadline: Deadline | None,
    near,
    t0: float,
    **search,
) -> SolveResult:
    """The FOV search (``search_fov``) of ``bands`` over a horizontal ``fov_range`` (degrees)
    for the points ``xy`` (px, the pinhole's: the ``stars`` in ``order``), each identification
    fitted (``fit_first``) until one is accepted or the ``deadline`` passes; with a position
    hint (``near``: its cone) the catalog near it is searched first, in at most
    ``HINT_BUDGET_SHARE`` of the budget (of the default one when there is none), then the
    whole sky. ``search``: ``search_fov``'s other keywords."""
    lo, hi = fov_range
    for where in [near, None] if near is not None else [None]:
        share = deadline
        if where is not None:
            whole = deadline or Deadline.after(SEARCH_BUDGET_S)
            share = replace(whole, budget_s=HINT_BUDGET_SHARE * whole.budget_s)
        result = fit_first(
            _candidates(
                search_fov(
                    xy,
                    bands,
                    width=base.width,
                    height=base.height,
                    cx=base.cx,
                    cy=base.cy,
                    sigma_px=settings.sigma_px,
                    focal_range_px=(
                        focal_px_from_fov(hi, base.width),
                        focal_px_from_fov(lo, base.width),
                    ),
                    parity=settings.parity,
                    max_false_match_probability=settings.max_false_match_probability,
                    deadline=share,
                    near=where,
                    **search,
                ),
                order,
                base,
            ),
            stars,
            settings,
            bands[0].database.catalog,
            t0=t0,
        )
        if result.solution is not None or expired(deadline):
            break
    return result


def _search_and_fit(
    stars, base: Camera, bands, settings: SolveSettings, fov_range, pattern_stars, deadline, near
):
    """The FOV search's identifications, each fitted by the solver until one is accepted or
    the ``deadline`` passes; with a position hint (``near``: unit vector, radius in rad) the
    catalog near it is searched first, then the whole sky."""
    t0 = time.perf_counter()
    order = stars.order
    xy_sorted = stars.xy[order]
    point_mag = stars.magnitudes
    if point_mag is not None:
        point_mag = point_mag[order][: MatchSettings.max_screen_stars]
    if base.distorted:  # take the known distortion out: the search assumes a pinhole
        pinhole = Camera(base.width, base.height, base.focal_px, base.cx, base.cy)
        xy_sorted = pinhole.bearings_to_pixels(base.pixels_to_bearings(xy_sorted))
    return fit_searched(
        xy_sorted[: MatchSettings.max_screen_stars], stars, order, bands, base, settings,
        fov_range, deadline, near, t0, pattern_stars=pattern_stars, point_mag=point_mag,
    )  # fmt: skip


def _candidates(
    found_matches: Iterator[FovMatch], order: np.ndarray, base: Camera
) -> Iterator[Candidate]:
    """The FOV search's matches as the fit's candidates (their stars' rows back in the
    list's order, the camera at the focal length each was found at)."""
    for found in found_matches:
        if found.final:
            yield Candidate(
                None, reason=found.reason, hypotheses=found.hypotheses, ambiguous=found.ambiguous
            )
            return
        ident = replace(found.identification, obs_index=order[found.identification.obs_index])
        camera = base.with_focal(found.focal_px)
        yield Candidate(ident, camera, found.band.database, "fov-search")
