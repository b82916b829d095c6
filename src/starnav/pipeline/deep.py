"""Faint stars: every measured point matched to a deep catalog with the fitted attitude.

A pair table of a catalog to Hp 12 is too large for a 6° field (``solver.MAX_PAIRS``), so a
solve identifies on a bright catalog and this stage, run after the fit, pairs the points
the bright identification left without an id with the deep catalog stars near them: a
cone search on the deep catalog's sky grid and the one-to-one least-squares pairing of
``identify.kernels.pairing.pair_catalog`` (no pair table of the deep catalog is ever built).

The rules (``deep_match``):

- Pairing. The points the bright identification left without an id are paired with the
  deep stars no bright id holds, one to one, least total squared distance
  (``pair_catalog``), within a match circle of ``MATCH_SIGMAS`` centroid sigmas. Then every
  contested group (a point with two or more deep stars in its circle, or a star in two
  points' circles, the bright identification's points and stars included) is decided
  again as one linear assignment: the most pairs, then the highest total log-likelihood,
  -d^2 / 2 sigma^2 for the residual d, minus (m - mag)^2 / 2 sigma_m^2 when the points have
  a brightness (m = zero point - 2.5 log10(brightness), the zero point and sigma_m fitted
  on the matched points, sigma_m at least ``MIN_MAG_SIGMA``), plus two bonuses of
  ln ``DOUBLE_LIKELIHOOD_RATIO`` (ln 20) described next. One to one, so two measured points
  never both get one star, and two points swap stars only when that is what the data say
  is most likely (the noise moved each nearer the other's star, and their brightness does
  not tell them apart).
- The bright identification's ids are kept unless the deep match is clearly better: its
  pairs have the bonus, so one changes only when another assignment is 20 times more
  likely (e.g. the bright stage gave a Hp 7.7 star to the point of its Hp 9.7 neighbour
  0.9 px away, which the bright catalog lacks, and the brightness says otherwise).
- Unresolved doubles: a point whose match circle holds two or more deep stars that no
  other point holds is flagged ``double``. When two of them are closer together than
  max(1 px, ``UNRESOLVED_SIGMAS`` sigma) (the separation at which the evaluation's
  ``_wrong_ids`` cannot tell them apart either), the point is taken for their blend, whose
  photocentre lies nearer the brighter: the brightest has the bonus, so it gets the id
  unless another star explains the centroid 20 times better. A wider neighbour is decided
  by the likelihood alone (a point sitting on a faint star keeps it even when a brighter
  one, not detected, lies 2 px away). Similar brightness needs no rule of its own: the
  brighter still has the bonus, and the likelihood decides.
- ``match_probability``: P(the id is right) = f / (f + rho), f the Gaussian density of the
  residual at the centroid sigma (per px^2) and rho the density of chance neighbours: deep
  catalog stars per px^2 over the field plus false points per px^2 (the points left
  without an id, at least one per image). This is the likelihood ratio of "the point is
  this star" to "the star is a chance neighbour inside the match circle" (whose prior,
  rho x the circle's area, spread uniformly over it, gives the density rho). The
  double's other free stars in the circle add their own Gaussian densities at the point
  to rho (either could be the one seen). Positions only: the brightness is not in it.

The centroid sigma: the fitted one (the bright fit's residual rms per axis, corrected for
the 3 fitted angles) when at least ``MIN_FIT_STARS`` stars were fitted, else the told
``sigma_px``; the match circle's radius uses the larger of the two. The attitude, camera,
their sigmas and ``false_match_probability`` stay the bright identification's;
``n_matched`` counts the deep matches too.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError, shown
from starnav.identify.database import sky_grid
from starnav.results import Solution, StarTable
from starnav.starlist import StarList

MATCH_SIGMAS = 4.0  # a point's match circle: this many centroid sigmas (misses 0.03 %)
DOUBLE_LIKELIHOOD_RATIO = 20.0  # a double's nearer star beats the brighter by this factor
MIN_FIT_STARS = 8  # the fitted sigma is used from this many fitted stars on
MIN_SIGMA_PX = 0.05  # the centroid sigma is never taken below this (px)
UNRESOLVED_SIGMAS = 3.0  # two stars closer than max(1 px, this many sigma): one point
MIN_MAG_SIGMA = 0.1  # the brightness model's scatter is never taken below this (mag)
_NO_PAIR = 1e12  # cost of a point and a star that are not within the match circle


MAX_DEEP_MAG = 16.0  # deep_mag_limit is a magnitude up to this (Hipparcos ends near Hp 14)
# the depth of the deep stage a narrow known field of the embedded Hipparcos runs by default
# (``pipeline.fov.known_field_depth``; docs/deep_stars.md), and the value that turns it off
DEEP_MAG_LIMIT = 12.0
DEEP_OFF = "off"
DEEP_CHANCE = 0.005  # ... where a match circle holds a chance deep star for fewer points


def deep_catalog(
    catalog: Catalog | str | Path | None,
    deep_mag_limit: float | str | None,
    epoch_year: float | None,
) -> Catalog | None:
    """The deep stage's catalog: ``catalog`` (a ``Catalog``, a CSV path or None for the
    embedded Hipparcos, as ``load_catalog``) to ``deep_mag_limit``, at ``epoch_year``; None
    when ``deep_mag_limit`` is None or ``DEEP_OFF`` (no deep stage). A one-line error for a
    bad limit."""
    if deep_mag_limit is None or deep_mag_limit == DEEP_OFF:
        return None
    m = deep_mag_limit
    if isinstance(m, bool) or not isinstance(m, int | float) or not -2.0 <= m <= MAX_DEEP_MAG:
        raise StarnavError(
            f"deep_mag_limit must be a magnitude between -2 and {MAX_DEEP_MAG:g}, got {shown(m)}"
        )
    return load_catalog(catalog, mag_limit=float(m), epoch_year=epoch_year)


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


def match_probability(residual_px: np.ndarray, sigma_px: float, chance_per_px2):
    """P(the id is right) of matches with residual lengths ``residual_px`` (px): the
    Gaussian density of the residual at ``sigma_px`` (per axis) against ``chance_per_px2``
    (a number or one per match), the density of the other explanations (chance stars and
    false points per px^2, a double's companions). NaN stays NaN."""
    r = np.asarray(residual_px, dtype=float)
    f = np.exp(-0.5 * (r / sigma_px) ** 2) / (2.0 * math.pi * sigma_px**2)
    return f / (f + chance_per_px2)


def deep_match(solution: Solution, stars: StarList, deep: Catalog, *, sigma_px: float) -> Solution:
    """``solution`` with every point matched to the ``deep`` catalog at its fitted attitude
    and camera (the rules in the module docstring): the star table's ``catalog_id`` and
    ``residual_px`` of the newly matched points, ``match_probability`` and ``double`` of
    every point, and ``n_matched``. The attitude, its sigmas and ``false_match_probability``
    (of the bright identification) are unchanged. ``sigma_px``: the told centroid 1-sigma."""
    from starnav.identify.kernels.pairing import pair_catalog
    from starnav.identify.kernels.sky import chord, cone

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
    row_of[bright] = deep.rows(table.catalog_id[bright], missing=-1)
    owner = np.full(len(deep), -1, dtype=np.int64)
    held = bright[row_of[bright] >= 0]
    owner[row_of[held]] = held
    free = np.flatnonzero(table.catalog_id < 0)
    if len(free):
        allowed = owner < 0
        pairs = pair_catalog(
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

    # contested groups (a point with two or more stars in its circle, or a star in two
    # circles) decided again, by likelihood: the most pairs, then position and brightness
    chord2 = chord(radius_rad) ** 2
    sky_dir = bearings @ R  # rows: R^T b, the points' directions in ICRS
    takes_part = (table.catalog_id < 0) | (row_of >= 0)  # not a bright id the deep lacks
    edges = []
    for p in np.flatnonzero(takes_part):
        m = cone(np.ascontiguousarray(sky_dir[p]), chord2, sky, everything, work)
        edges.extend((p, int(r)) for r in work[:m])
    edges.extend((int(p), int(row_of[p])) for p in held)  # even beyond the circle
    mag_sigma, zero_point = _magnitude_model(stars, row_of, deep)
    if edges:
        e = np.unique(np.array(edges, dtype=np.int64), axis=0)
        star_xy = _pixels(camera, R, deep, e[:, 1])
        d2 = np.sum((star_xy - xy[e[:, 0]]) ** 2, axis=1)
        score = -0.5 * d2 / sigma**2
        if mag_sigma is not None:
            measured = zero_point - 2.5 * np.log10(stars.brightness[e[:, 0]])
            score -= 0.5 * ((measured - deep.mag[e[:, 1]]) / mag_sigma) ** 2
        keep = math.log(DOUBLE_LIKELIHOOD_RATIO)
        bright_row = np.full(n, -1, dtype=np.int64)
        bright_row[held] = row_of[held]
        score += keep * (bright_row[e[:, 0]] == e[:, 1])  # the bright stage's id
        unresolved_px = max(1.0, UNRESOLVED_SIGMAS * sigma)
        score += keep * _brightest_of_double(e, deep.mag, star_xy, unresolved_px)
        _decide_contested(e, score, row_of, owner)
    double = np.zeros(n, dtype=np.bool_)
    companions = np.zeros(n)  # density (per px^2) of the other free stars at each point
    if edges:
        free_or_own = (owner[e[:, 1]] < 0) | (owner[e[:, 1]] == e[:, 0])
        double = np.bincount(e[free_or_own, 0], minlength=n) >= 2
        double &= row_of >= 0
        other = free_or_own & (row_of[e[:, 0]] != e[:, 1])
        density = np.exp(-0.5 * d2 / sigma**2) / (2.0 * math.pi * sigma**2)
        companions = np.bincount(e[other, 0], weights=density[other], minlength=n)

    matched = np.flatnonzero(row_of >= 0)
    catalog_id = table.catalog_id.copy()
    catalog_id[matched] = deep.ids[row_of[matched]]
    residual_px = np.full(n, np.nan)
    residual_px[matched] = np.sqrt(
        np.sum((_pixels(camera, R, deep, row_of[matched]) - xy[matched]) ** 2, axis=1)
    )
    # chance neighbours: deep stars over the field, false points over the image
    half = camera.half_diagonal_rad
    n_field = cone(np.ascontiguousarray(R[2]), chord(half) ** 2, sky, everything, work)
    stars_per_px2 = n_field / (2.0 * math.pi * (1.0 - math.cos(half))) / scale**2
    false_per_px2 = max(n - len(matched), 1) / (camera.width * camera.height)
    chance = stars_per_px2 + false_per_px2 + companions
    probability = match_probability(residual_px, sigma, chance)
    deep_table = StarTable(table.labels, table.xy, catalog_id, residual_px, probability, double)
    catalog = f"{solution.catalog}; deep stage: {deep.name}"
    return replace(solution, star_table=deep_table, n_matched=len(matched), catalog=catalog)


def _magnitude_model(stars: StarList, row_of: np.ndarray, deep: Catalog):
    """(sigma, zero point) of catalog mag = zero point - 2.5 log10(brightness), from the
    matched points (median; sigma 1.4826 MAD, at least ``MIN_MAG_SIGMA``), or (None, 0)
    without brightness or with fewer than ``MIN_FIT_STARS`` matched points having it."""
    b = stars.brightness
    if b is None:
        return None, 0.0
    ok = (row_of >= 0) & np.isfinite(b) & (b > 0)
    if ok.sum() < MIN_FIT_STARS or not np.all(np.isfinite(b) & (b > 0)):
        return None, 0.0
    offset = deep.mag[row_of[ok]] + 2.5 * np.log10(b[ok])
    zero_point = float(np.median(offset))
    mad = float(np.median(np.abs(offset - zero_point)))
    return max(1.4826 * mad, MIN_MAG_SIGMA), zero_point


def _brightest_of_double(
    e: np.ndarray, mag: np.ndarray, star_xy: np.ndarray, unresolved_px: float
) -> np.ndarray:
    """Whether each edge (point, star) joins its point to the brightest star of the point's
    circle when another star of that circle is within ``unresolved_px`` of it (px)."""
    out = np.zeros(len(e), dtype=bool)
    order = np.argsort(e[:, 0], kind="stable")
    starts = np.flatnonzero(np.r_[True, e[order[1:], 0] != e[order[:-1], 0]])
    for group in np.split(order, starts[1:]):
        if len(group) < 2:
            continue
        b = group[np.argmin(mag[e[group, 1]])]
        apart = np.hypot(*(star_xy[group] - star_xy[b]).T)
        out[b] = np.sum(apart <= unresolved_px) >= 2  # itself and another
    return out


def _decide_contested(e: np.ndarray, score: np.ndarray, row_of, owner) -> None:
    """Re-pair each group of edges (point, star) linked through shared points or stars and
    holding more than one edge: one to one, the most pairs, then the highest total ``score``
    (a linear assignment; a point may stay unpaired). ``row_of`` (point -> star) and
    ``owner`` (star -> point) are updated in place."""
    from scipy.optimize import linear_sum_assignment
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    points, p_index = np.unique(e[:, 0], return_inverse=True)
    rows, s_index = np.unique(e[:, 1], return_inverse=True)
    n_p, n_s = len(points), len(rows)
    graph = coo_matrix((np.ones(len(e)), (p_index, n_p + s_index)), shape=(n_p + n_s,) * 2)
    _, label = connected_components(graph, directed=False)
    edge_group = label[p_index]
    pair_bonus = 1.0 + np.ptp(score) + 1.0  # more than any difference of scores
    for g in np.unique(edge_group[np.bincount(edge_group)[edge_group] > 1]):
        sel = np.flatnonzero(edge_group == g)
        gp, gp_i = np.unique(p_index[sel], return_inverse=True)
        gs, gs_i = np.unique(s_index[sel], return_inverse=True)
        cost = np.full((len(gp), len(gs) + len(gp)), _NO_PAIR)
        cost[gp_i, gs_i] = -(score[sel] + pair_bonus)
        cost[np.arange(len(gp)), len(gs) + np.arange(len(gp))] = 0.0  # unpaired
        r, c = linear_sum_assignment(cost)
        for pi in points[gp]:
            if row_of[pi] >= 0 and owner[row_of[pi]] == pi:
                owner[row_of[pi]] = -1
            row_of[pi] = -1
        for i, j in zip(r, c, strict=True):
            if j < len(gs):
                p, star = points[gp[i]], rows[gs[j]]
                row_of[p], owner[star] = star, p


def _pixels(camera, R: np.ndarray, catalog: Catalog, rows: np.ndarray) -> np.ndarray:
    """Pixel positions (m, 2) of catalog ``rows`` through ``camera`` at attitude ``R``."""
    return camera.bearings_to_pixels(catalog.vectors[rows] @ R.T)
