"""A source list in no brightness order: identified by the patterns of neighbouring points.

The FOV search (``pipeline.fov``) matches patterns of a field's brightest catalog stars to
patterns of the brightest points; a list with no brightness column (a source list in
detection order, nova's x/y lists) says nothing of which points those are, and four points
taken at random are almost never four of them. Here the catalog is cut as deep as the list is
dense (``density_mag_limit``: about ``CATALOG_SHARE`` of the list's points in the image, so
that most catalog stars there are among the points), and the patterns are local: each
catalog star with its nearest catalog neighbours (``build_pattern_table(local=True)``: one
table per depth, whatever the field of view), each point with its nearest points
(``neighbour_patterns``: more of them, as the list holds points fainter than the catalog).
Four points that are catalog stars and neighbours in both make a pattern found in the table;
every hypothesis goes through the FOV search's verification and the fit as any other
(``search_fov``, ``fit_first``), with no brightness weighed.
"""

from __future__ import annotations

import itertools
import math
import time
from pathlib import Path

import numpy as np

from starnav.camera import Camera, focal_px_from_fov
from starnav.catalog import GAIA, Catalog, is_embedded, load_catalog
from starnav.identify.database import catalog_only
from starnav.identify.pattern4 import build_pattern_table
from starnav.pipeline.fov import (
    band_source,
    fit_searched,
    hint_cone,
    range_grid,
    search_catalog,
    search_range,
    searched_ranges,
)
from starnav.pipeline.fov_search import Band
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.solver import SolveSettings, first_use
from starnav.results import SolveResult
from starnav.runtime.budget import Deadline, check_budget, default_budget_s, expired
from starnav.runtime.caches import process_cache
from starnav.starlist import check_star_list

CATALOG_SHARE = 0.5  # catalog stars in the image per point of the list
CATALOG_NEIGHBOURS = 6  # a catalog star's neighbourhood: it and its 5 nearest
POINT_NEIGHBOURS = 8  # a point's patterns: it and 3 of its 8 nearest points
MAG_STEP = 0.5  # depths are rounded to this (magnitudes): the tables are shared
MIN_MAG = 4.0  # no shallower catalog than this
LOOKUP_SIGMA_PX = 0.5  # the look-up's tolerances, when no centroid sigma is told: the
# patterns are small, and a 1 px centroid's tolerance proposes many times the hypotheses
SCREEN_POINTS = 200  # a hypothesis is verified on this many points spread over the image
MAX_HYPOTHESES = 10_000_000  # the time budget ends the search, not a count
_LOCAL_BANDS = process_cache("unordered-list bands", max_items=8)
_SORTED_MAGS = process_cache("catalog magnitudes, sorted")


def density_mag_limit(n_points: int, image_sr: float, mags: np.ndarray) -> float:
    """The magnitude limit (rounded to ``MAG_STEP``, within ``MIN_MAG`` and the deepest of
    ``mags``, sorted) at which ``CATALOG_SHARE`` times ``n_points`` catalog stars fall in an
    image of ``image_sr`` steradians on average."""
    wanted = CATALOG_SHARE * n_points * 4.0 * math.pi / image_sr
    mag = float(mags[min(int(wanted), len(mags) - 1)])
    mag = math.floor(mag / MAG_STEP + 0.5) * MAG_STEP
    return min(max(mag, MIN_MAG), float(mags[-1]))


def image_sr(fov_deg: float, width: int, height: int) -> float:
    """Solid angle (sr) of a pinhole image ``fov_deg`` wide (horizontal) of ``width`` x
    ``height`` px."""
    f = focal_px_from_fov(fov_deg, width)
    half_w, half_h = math.atan(width / (2.0 * f)), math.atan(height / (2.0 * f))
    return 4.0 * math.asin(math.sin(half_w) * math.sin(half_h))


def uniform_order(xy: np.ndarray, width: float, height: float, boxes: int = 10) -> np.ndarray:
    """The rows of a list whose order says nothing of brightness, spread over the image: about
    ``boxes`` cells (astrometry.net's ``--uniformize``), their points taken in turn, one
    from each cell, in the list's order within a cell, so the first points solved cover
    the image rather than a strip of it."""
    nx = max(1, round(math.sqrt(boxes * width / height)))
    ny = max(1, round(boxes / nx))
    col = np.clip((xy[:, 0] / width * nx).astype(int), 0, nx - 1)
    row = np.clip((xy[:, 1] / height * ny).astype(int), 0, ny - 1)
    cell = row * nx + col
    turn = np.empty(len(xy), dtype=np.int64)
    for c in np.unique(cell):
        members = np.flatnonzero(cell == c)
        turn[members] = np.arange(len(members))
    return np.lexsort((cell, turn))


def neighbour_patterns(xy: np.ndarray, order: np.ndarray, neighbours: int) -> np.ndarray:
    """4-star patterns (m, 4: rows of ``xy``) of each point, in ``order``, with 3 of its
    ``neighbours`` nearest points, the closest first; each set of four once."""
    from scipy.spatial import cKDTree

    n = len(xy)
    k = min(neighbours, n - 1)
    if k < 3:
        return np.empty((0, 4), dtype=np.intp)
    _, near = cKDTree(xy).query(xy, k=k + 1)
    triples = np.array(list(itertools.combinations(range(1, k + 1), 3)), dtype=np.intp)
    triples = triples[np.lexsort((triples[:, 0], triples[:, 1], triples[:, 2]))]
    centre = np.asarray(order, dtype=np.intp)
    rows = np.concatenate(
        [np.repeat(centre, len(triples))[:, None], near[centre][:, triples].reshape(-1, 3)],
        axis=1,
    )
    _, first = np.unique(np.sort(rows, axis=1), axis=0, return_index=True)
    return rows[np.sort(first)]


def local_bands(
    lo: float,
    hi: float,
    width: int,
    height: int,
    n_points: int,
    catalog: Catalog | str | Path | None,
    epoch_year: float | None,
) -> list[Band]:
    """The bands of a horizontal FOV of ``lo``..``hi`` degrees for a list of ``n_points``:
    each grid band's catalog (``band_source``; the embedded Gaia DR3 also where the list is
    denser than Hipparcos to Hp 8.5 can match) cut at its density depth
    (``density_mag_limit`` at the band's middle), with the local pattern table of that
    depth."""
    full = search_catalog(catalog, epoch_year)
    bands = []
    for a, b, top in range_grid(lo, hi, width, height):
        sr = image_sr(math.sqrt(a * b), width, height)
        source = band_source(top, catalog, full)
        if is_embedded(catalog) and CATALOG_SHARE * n_points * 4.0 * math.pi / sr > len(source):
            source = load_catalog(GAIA)
        if source.fingerprint not in _SORTED_MAGS:
            _SORTED_MAGS[source.fingerprint] = np.sort(source.mag)
        mag = density_mag_limit(n_points, sr, _SORTED_MAGS[source.fingerprint])
        key = (source.fingerprint, mag, round(top, 6))
        if key not in _LOCAL_BANDS:
            database = catalog_only(source.brighter_than(mag), math.radians(top))
            table = build_pattern_table(database, stars_per_field=CATALOG_NEIGHBOURS, local=True)
            _LOCAL_BANDS[key] = (database, table)
        database, table = _LOCAL_BANDS[key]
        bands.append(Band(a, b, database.catalog, database, table))
    return bands


def solve_unordered(
    xy: np.ndarray,
    options: SolveOptions,
    *,
    width: float | None,
    height: float | None = None,
    position_hint_deg: tuple[float, float] | None = None,
) -> SolveResult:
    """Identify the points ``xy`` (n, 2, px; in no brightness order) of an image ``width`` x
    ``height`` px whose field of view lies in ``options``' range (as ``solve_unknown_field``
    takes it), by local patterns; the whole list is fitted and verified as the FOV search's
    answers are."""
    if options.camera is not None:
        width, height = options.camera.width, options.camera.height
    height = width if height is None else height
    shape = (width, height)  # a portrait list's narrowest field is its height's, as an image's
    lo, hi = search_range(
        options.fov_deg, options.search_range_deg, options.camera, options.lens_model, shape
    )
    base = Camera.from_fov(0.5 * (lo + hi), width, height)
    budget_s = check_budget(
        options.time_budget_s,
        default_budget_s(known=options.field_known, scan=False, field_deg=base.diagonal_deg),
    )
    stars = check_star_list(xy, width=width, height=height)
    settings = SolveSettings.from_options(options, fit_focal=True)
    known = options.fov_deg is not None or options.camera is not None
    ranges = [(lo, hi)] if known else searched_ranges(options, (lo, hi), shape)
    near = hint_cone(position_hint_deg, options.position_radius_deg)
    t0 = time.perf_counter()
    order = uniform_order(stars.xy, width, height)  # the first points verified: spread
    xy_spread = stars.xy[order]
    patterns = neighbour_patterns(xy_spread, np.arange(len(order)), POINT_NEIGHBOURS)
    result, deadline = None, None
    for a, b in ranges:
        bands = local_bands(a, b, width, height, len(stars.xy), options.catalog,
                            options.epoch_year)  # fmt: skip
        deadline = deadline or Deadline.after(budget_s)  # once the first tables are loaded
        with first_use("solve"):
            result = fit_searched(
                xy_spread, stars, order, bands, base, settings, (a, b), deadline, near, t0,
                max_hypotheses=MAX_HYPOTHESES, patterns=patterns, screen=SCREEN_POINTS,
                lookup_sigma_px=settings.sigma_px or LOOKUP_SIGMA_PX,
            )  # fmt: skip
        if result.solution is not None or expired(deadline):
            return result
    return result
