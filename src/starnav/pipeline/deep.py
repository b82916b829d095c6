"""Faint stars: every measured point matched to a deep catalog with the fitted attitude.

A pair table of a catalog to Hp 12 is too large for a 6° field (``solver.MAX_PAIRS``), so a
solve identifies on a bright catalog and this stage, run after the fit, pairs the points
the bright identification left without an id with the deep catalog stars near them: a
cone search on the deep catalog's sky grid and the one-to-one least-squares pairing of
``identify.kernels.pair_catalog`` (no pair table of the deep catalog is ever built).

The rules (``deep_match``):

- The stars of the bright identification are the deep catalog's too (the same ids); they
  are not paired again, so a faint star is never given to a point the verified
  identification explained, and two points never swap stars.
- An unresolved double: a point whose match circle (``MATCH_SIGMAS`` sigma) holds two or
  more deep-catalog stars that no other point was paired with. Its centroid is their
  photocentre, which lies nearer the brighter star, so it gets the **brightest** of them,
  unless another of them explains the centroid clearly better (its Gaussian likelihood at
  the centroid sigma is more than ``DOUBLE_LIKELIHOOD_RATIO`` times the brightest's: e.g. a
  point on a faint star whose brighter neighbour 2 px away was not detected). Either way it
  is flagged ``double``. Only stars no other point holds are ever taken, so the rule never
  swaps ids between two measured points. The same rule applies to the points of the bright
  identification (the bright star is the brightest candidate, so it keeps its id unless a
  free deep star explains the point that much better).
- ``match_probability``: P(the id is right) = f / (f + rho), f the Gaussian density of the
  residual at the centroid sigma (per px^2) and rho the density of chance neighbours: deep
  catalog stars per px^2 over the field plus false points per px^2 (the points left
  without an id, at least one per image). This is the likelihood ratio of "the point is
  this star" to "the star is a chance neighbour inside the match circle" (whose prior,
  rho x the circle's area, spread uniformly over it, gives the density rho).

The centroid sigma: the fitted one (the bright fit's residual rms per axis, corrected for
the 3 fitted angles) when at least ``MIN_FIT_STARS`` stars were fitted, else the told
``sigma_px``; the match circle's radius uses the larger of the two.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.identify.database import sky_grid
from starnav.results import Solution, StarTable
from starnav.starlist import StarList

MATCH_SIGMAS = 4.0  # a point's match circle: this many centroid sigmas (misses 0.03 %)
DOUBLE_LIKELIHOOD_RATIO = 20.0  # a double's nearer star beats the brighter by this factor
MIN_FIT_STARS = 8  # the fitted sigma is used from this many fitted stars on
MIN_SIGMA_PX = 0.05  # the centroid sigma is never taken below this (px)


MAX_DEEP_MAG = 16.0  # deep_mag_limit is a magnitude up to this (Hipparcos ends near Hp 14)


def deep_catalog(
    catalog: Catalog | str | Path | None, deep_mag_limit: float | None, epoch_year: float | None
) -> Catalog | None:
    """The deep stage's catalog: ``catalog`` (a ``Catalog``, a CSV path or None for the
    embedded Hipparcos, as ``load_catalog``) to ``deep_mag_limit``, at ``epoch_year``; None
    when ``deep_mag_limit`` is None (no deep stage). A one-line error for a bad limit."""
    if deep_mag_limit is None:
        return None
    m = deep_mag_limit
    if isinstance(m, bool) or not isinstance(m, int | float) or not -2.0 <= m <= MAX_DEEP_MAG:
        raise StarnavError(
            f"deep_mag_limit must be a magnitude between -2 and {MAX_DEEP_MAG:g}, got {m!r}"
        )
    return load_catalog(catalog, mag_limit=float(m), epoch_year=epoch_year)


def kernels():
    """The identification kernels (imported on first use: numba takes ~0.2 s to load)."""
    from starnav.identify import kernels

    return kernels


@functools.lru_cache(maxsize=4)
def _deep_sky(catalog: Catalog) -> tuple:
    """The sky grid of a deep catalog (built once per catalog, ~50 ms for 117 000 stars)."""
    return sky_grid(catalog.vectors)


def centroid_sigma_px(solution: Solution, sigma_px: float) -> float:
    """The centroid 1-sigma per axis (px): the fit's when it had ``MIN_FIT_STARS`` stars
    (rms residual length / sqrt(2), times sqrt(2n / (2n - 3)) for the 3 fitted angles),
    else the told ``sigma_px``."""
    n = solution.n_matched
    if n < MIN_FIT_STARS or not math.isfinite(solution.rms_px):
        return float(sigma_px)
    fitted = solution.rms_px / math.sqrt(2.0) * math.sqrt(2.0 * n / (2.0 * n - 3.0))
    return max(fitted, MIN_SIGMA_PX)


def match_probability(residual_px: np.ndarray, sigma_px: float, chance_per_px2: float):
    """P(the id is right) of matches with residual lengths ``residual_px`` (px): the
    Gaussian density of the residual at ``sigma_px`` (per axis) against ``chance_per_px2``,
    the density of chance neighbours (stars and false points per px^2). NaN stays NaN."""
    r = np.asarray(residual_px, dtype=float)
    f = np.exp(-0.5 * (r / sigma_px) ** 2) / (2.0 * math.pi * sigma_px**2)
    return f / (f + chance_per_px2)


def _rows_of_ids(catalog: Catalog, ids: np.ndarray) -> np.ndarray:
    """Rows of ``ids`` in ``catalog`` (-1 for ids it does not hold)."""
    order = np.argsort(catalog.ids, kind="stable")
    pos = np.searchsorted(catalog.ids, ids, sorter=order)
    pos = np.minimum(pos, len(order) - 1)
    rows = order[pos]
    return np.where(catalog.ids[rows] == ids, rows, -1)


def deep_match(solution: Solution, stars: StarList, deep: Catalog, *, sigma_px: float) -> Solution:
    """``solution`` with every point matched to the ``deep`` catalog at its fitted attitude
    and camera (the rules in the module docstring): the star table's ``catalog_id`` and
    ``residual_px`` of the newly matched points, ``match_probability`` and ``double`` of
    every point, and ``n_matched``. The attitude, its sigmas and ``false_match_probability``
    (of the bright identification) are unchanged. ``sigma_px``: the told centroid 1-sigma."""
    k = kernels()
    camera, R = solution.camera, np.ascontiguousarray(solution.R_cam_from_icrs)
    table = solution.star_table
    xy = np.asarray(stars.xy, dtype=float)
    n = len(xy)
    sky = _deep_sky(deep)
    scale = camera.scale_px_per_rad
    sigma = centroid_sigma_px(solution, sigma_px)
    radius_rad = MATCH_SIGMAS * max(sigma, sigma_px) / scale
    bearings = np.ascontiguousarray(camera.pixels_to_bearings(xy), dtype=np.float64)
    everything = np.ones(len(deep), dtype=np.bool_)
    work = np.empty(len(deep), dtype=np.int64)

    # the bright identification's stars, as deep rows (taken: not paired again)
    row_of = np.full(n, -1, dtype=np.int64)
    bright = np.flatnonzero(table.catalog_id >= 0)
    row_of[bright] = _rows_of_ids(deep, table.catalog_id[bright])
    owner = np.full(len(deep), -1, dtype=np.int64)
    held = bright[row_of[bright] >= 0]
    owner[row_of[held]] = held
    free = np.flatnonzero(table.catalog_id < 0)
    if len(free):
        allowed = owner < 0
        pairs = k.pair_catalog(
            np.ascontiguousarray(bearings[free]),
            R,
            sky,
            allowed,
            radius_rad,
            np.full((3, 3), np.nan),
            False,
            work,
        )
        row_of[free[pairs.obs]] = pairs.cat
        owner[pairs.cat] = free[pairs.obs]

    # unresolved doubles: the brightest free star in the circle, unless clearly worse
    double = np.zeros(n, dtype=np.bool_)
    chord2 = k.chord(radius_rad) ** 2
    sky_dir = bearings @ R  # rows: R^T b, the points' directions in ICRS
    worse = 2.0 * sigma**2 * math.log(DOUBLE_LIKELIHOOD_RATIO)
    for p in np.flatnonzero(row_of >= 0):
        m = k.cone(np.ascontiguousarray(sky_dir[p]), chord2, sky, everything, work)
        near = work[:m]
        near = near[(owner[near] < 0) | (owner[near] == p)]
        if len(near) < 2:
            continue
        double[p] = True
        d2 = np.sum((_pixels(camera, R, deep, near) - xy[p]) ** 2, axis=1)
        brightest = int(np.argmin(deep.mag[near]))
        choice = brightest if d2[brightest] - d2.min() <= worse else int(np.argmin(d2))
        owner[row_of[p]] = -1
        row_of[p] = near[choice]
        owner[row_of[p]] = p

    matched = np.flatnonzero(row_of >= 0)
    catalog_id = table.catalog_id.copy()
    catalog_id[matched] = deep.ids[row_of[matched]]
    residual_px = np.full(n, np.nan)
    residual_px[matched] = np.sqrt(
        np.sum((_pixels(camera, R, deep, row_of[matched]) - xy[matched]) ** 2, axis=1)
    )
    # chance neighbours: deep stars over the field, false points over the image
    half = camera.half_diagonal_rad
    n_field = k.cone(np.ascontiguousarray(R[2]), k.chord(half) ** 2, sky, everything, work)
    stars_per_px2 = n_field / (2.0 * math.pi * (1.0 - math.cos(half))) / scale**2
    false_per_px2 = max(n - len(matched), 1) / (camera.width * camera.height)
    probability = match_probability(residual_px, sigma, stars_per_px2 + false_per_px2)
    deep_table = StarTable(table.labels, table.xy, catalog_id, residual_px, probability, double)
    return replace(solution, star_table=deep_table, n_matched=len(matched))


def _pixels(camera, R: np.ndarray, catalog: Catalog, rows: np.ndarray) -> np.ndarray:
    """Pixel positions (m, 2) of catalog ``rows`` through ``camera`` at attitude ``R``."""
    return camera.bearings_to_pixels(catalog.vectors[rows] @ R.T)
