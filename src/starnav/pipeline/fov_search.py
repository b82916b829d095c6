"""Identification when the field of view is unknown: 4-star patterns matched up to a scale.

The edge ratios of a 4-star pattern (``pattern4``) hardly depend on the focal length, so
they can be looked up before the scale is known. The caller (``starnav.pipeline.fov``) cuts the FOV
range into bands, each with its own catalog depth, KD-tree and pattern table. Within a band
the bearings are made with a few guessed focal lengths ("cells"): a wrong focal length
distorts the gnomonic projection towards the corners of the image (an edge at angle phi from
the boresight is stretched by about 2 delta tan^2 phi for a relative focal error delta), so
a cell is narrow enough for that distortion to stay within a loose ratio slack (0.5 %); the
cells of a band are looked up together. Every catalog pattern found that way gets its own
focal length, fitted to its six edges; only patterns whose edges then agree within the
measurement tolerance become hypotheses, verified on the whole field at that focal length by
the shared ``HypothesisTester`` (one tally over every band and cell, so the false-match
probability counts every hypothesis tried; a pattern found by two neighbouring cells counts
once).

Observed patterns are taken breadth-first over the brightest stars, and each batch of
patterns is tried in every band and cell before the next: most fields are identified by the
first few patterns, whatever their field of view.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from starnav.camera import Camera, focal_px_from_fov
from starnav.catalog import Catalog
from starnav.identify.base import Identification, MatchSettings
from starnav.identify.database import PairDatabase
from starnav.identify.pattern4 import (
    PatternTable,
    breadth_first_combinations,
    catalog_nbytes,
    concat_matches,
    match_patterns,
    pattern_edges,
)
from starnav.identify.verify import AMBIGUOUS_PARITY, HypothesisTester, Tally
from starnav.runtime.budget import Deadline, expired, next_chunk

BAND_FACTOR = math.sqrt(2.0)
BAND_OVERLAP = BAND_FACTOR**0.5  # a band's cells reach this far up into the next wider band
_LOOKUP_REL_TOL = 0.005  # ratio slack of the loose look-up (projection distortion of a cell)
_MAX_CELL_HALF_WIDTH = 0.2  # relative focal-length half-width of a cell at most
MIN_PATTERN_TOLS = 10.0  # a pattern's longest edge spans at least this many pair tolerances
_FIRST_LOOKUP = 16  # observed patterns of a band's first look-up when there is a deadline
_FOCAL_STEPS = 3  # Gauss-Newton steps of a pattern's focal length
_FOCAL_STEP_REL = 1e-4  # relative step of their central differences
_FIT_SLICE = 50_000  # pairings whose focal lengths are fitted at once
_LOCAL_BATCH = 128  # observed patterns given (``search_fov``'s ``patterns``) looked up at once


@dataclass(frozen=True, eq=False)
class Band:
    """One band of the FOV search: horizontal FOV ``fov_lo_deg``..``fov_hi_deg`` (degrees),
    its ``catalog``, ``database`` (catalog vectors and KD-tree, for the verification; no pair
    table; its catalog is ``catalog``) and pattern ``table``."""

    fov_lo_deg: float
    fov_hi_deg: float
    catalog: Catalog
    database: PairDatabase
    table: PatternTable

    @property
    def nbytes(self) -> int:
        """Bytes the search holds for the band: pattern table, catalog and KD-tree."""
        return self.table.nbytes + catalog_nbytes(self.database)


@dataclass(frozen=True, eq=False)
class FovMatch:
    """The outcome of a FOV search: the ``identification`` (rows of the stars given and of
    ``band.catalog``) and the focal length it was verified with (px), or the ``reason``."""

    identification: Identification | None
    reason: str
    hypotheses: int
    focal_px: float
    band: Band | None

    @property
    def final(self) -> bool:
        """Whether this ends the search with no identification (nothing left to try, or an
        ambiguous parity)."""
        return self.identification is None

    @property
    def ambiguous(self) -> bool:
        """Whether the search ended on an identification whose parity is ambiguous."""
        return self.reason == AMBIGUOUS_PARITY


def pinhole_bearings(xy: np.ndarray, cx: float, cy: float, focal: np.ndarray) -> np.ndarray:
    """Unit bearings of pixel positions ``xy`` (..., 2) through a distortion-free pinhole with
    principal point (cx, cy) and focal length(s) ``focal`` (px, broadcast against ``xy``'s
    leading dimensions; one focal length along the last of them), by the camera model's own
    projection (``camera.kernels``)."""
    from starnav.camera import kernels  # numba: loaded on first use

    shape = np.broadcast_shapes(xy.shape[:-1], np.shape(focal))
    rows = int(np.prod(shape[:-1])) if len(shape) > 1 else 1
    # writable C-ordered copies: one signature of the kernel (read-only or strided arrays
    # would each load another compiled version of it, ~10 ms a process)
    pixels = np.array(np.broadcast_to(xy, (*shape, 2)), dtype=np.float64, order="C")
    focals = np.array(np.broadcast_to(focal, shape), dtype=np.float64, order="C")
    params = np.array([1.0, cx, cy, 0.0, 0.0])  # [focal_px, cx, cy, k1, k2], focal per row
    out = kernels.bearings_at_focals(
        Camera.model_code,
        params,
        pixels.reshape(rows, -1, 2),
        np.ascontiguousarray(focals.reshape(rows, -1)[:, 0]),
    )
    return out.reshape(*shape, 3)


def fit_pattern_focal(
    xy: np.ndarray, cat_edges: np.ndarray, cx: float, cy: float, focal0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The focal length (px) at which the observed patterns ``xy`` (h, 4, 2) have the
    catalog's edge angles ``cat_edges`` (h, 6) (least squares on log f from ``focal0``,
    ``_FOCAL_STEPS`` Gauss-Newton steps), and the largest edge error left (radians); through
    a distortion-free pinhole of principal point (cx, cy) (``pipeline.kernels``)."""
    from starnav.pipeline import kernels  # numba: loaded on first use

    return kernels.pattern_focals(
        Camera.model_code,
        np.array([1.0, cx, cy, 0.0, 0.0]),  # [focal_px, cx, cy, k1, k2]
        np.ascontiguousarray(xy, dtype=np.float64),
        np.ascontiguousarray(cat_edges, dtype=np.float64),
        np.ascontiguousarray(focal0, dtype=np.float64),
        _FOCAL_STEPS,
        _FOCAL_STEP_REL,
    )


def _cells(
    band: Band, width: int, half_diagonal_px: float, focal_range: tuple[float, float]
) -> list[tuple[float, float, float]]:
    """Guessed focal lengths of a band: (focal, half-width, look-up ratio slack) each. They
    reach ``BAND_OVERLAP`` into the next wider band's fields: a field at the bottom of a band
    holds half the pattern stars of that band's table fields, and this band's deeper table
    finds it there."""
    f_lo = max(focal_px_from_fov(band.fov_hi_deg * BAND_OVERLAP, width), focal_range[0])
    f_hi = min(focal_px_from_fov(band.fov_lo_deg, width), focal_range[1])
    if f_hi < f_lo:
        return []
    # a relative focal error delta stretches the corners by 2 delta tan^2(phi)
    tan2 = (half_diagonal_px / f_lo) ** 2
    delta = min(_MAX_CELL_HALF_WIDTH, 0.5 * _LOOKUP_REL_TOL / tan2)
    n = max(1, math.ceil(math.log(f_hi / f_lo) / (2.0 * delta)))
    delta = 0.5 * math.log(f_hi / f_lo) / n if f_hi > f_lo else delta
    return [
        (f_lo * math.exp(delta * (2 * k + 1)), delta, max(2.0 * delta * tan2, 1e-3))
        for k in range(n)
    ]


def search_fov(
    xy: np.ndarray,
    bands: list[Band],
    *,
    width: int,
    height: int,
    cx: float,
    cy: float,
    sigma_px: float | None,
    focal_range_px: tuple[float, float],
    parity: int | None = None,
    max_false_match_probability: float = 1e-4,
    pattern_stars: int = 15,
    max_hypotheses: int = 20000,
    deadline: Deadline | None = None,
    near: tuple[np.ndarray, float] | None = None,
    point_mag: np.ndarray | None = None,
    patterns: np.ndarray | None = None,
    lookup_sigma_px: float | None = None,
    screen: int | None = None,
) -> Iterator[FovMatch]:
    """Identify the stars at ``xy`` (n, 2, px, distortion removed, brightest first) with the
    focal length unknown within ``focal_range_px`` (px), searching ``bands``. Yields every
    verified identification as it is found (the caller fits it and stops, or asks for the
    next); the last match yielded has no identification (``final``) and says why the search
    ended. ``deadline``: the search ends when it passes (looked at before each band's
    look-up and after each hypothesis). ``near``: (unit vector, radius in rad): only catalog
    patterns whose first star lies within the radius plus the band's half diagonal of the
    vector (a position hint) are hypotheses. ``sigma_px``: px, None if unknown; ``point_mag``:
    the rows' magnitudes (they are in brightness order), None: not known. ``patterns``: the
    observed patterns to try instead of those of the brightest ``pattern_stars`` (``_observed``;
    ``pipeline.unordered``); ``lookup_sigma_px``: the centroid sigma (px) of the look-up's
    tolerances when not ``sigma_px`` (the verification's); ``screen``: a hypothesis is
    verified on the first this many rows and its own (None: all; the fit takes in the rest)."""
    n = len(xy)
    if n < 4:
        yield FovMatch(None, "fewer than 4 stars", 0, float("nan"), None)
        return
    half_diag = math.hypot(max(cx, width - cx), max(cy, height - cy))
    plans = [(band, _cells(band, width, half_diag, focal_range_px)) for band in bands]
    plans = [(band, cells) for band, cells in plans if cells]
    if not plans:
        yield FovMatch(None, "the FOV range holds no field of view", 0, float("nan"), None)
        return
    combos, ends = _observed(min(n, pattern_stars), patterns)
    lookup_sigma = sigma_px if lookup_sigma_px is None else lookup_sigma_px
    tally = Tally()
    tester: HypothesisTester | None = None
    at_focal = functools.partial(_settings, sigma_px, max_false_match_probability, parity,
                                 max_hypotheses, deadline, point_mag)  # fmt: skip
    work = {id(band): np.empty(len(band.catalog), dtype=np.int64) for band, _ in plans}
    start = 0
    for end in ends:
        if end <= start:
            continue
        rows = _informative(combos[start:end], xy, lookup_sigma)
        start = end
        for band, cells in plans:
            if expired(deadline):
                tried = f"{tally.hypotheses} hypotheses from up to {start} 4-star patterns"
                yield FovMatch(None, deadline.reason(tried), tally.hypotheses, math.nan, None)
                return
            obs_rows, cat_rows, parities, f_fit = _band_hypotheses(
                xy, rows, band, cells, lookup_sigma, parity, focal_range_px, (cx, cy), deadline
            )
            if near is not None:
                keep = _near(band, cat_rows, near)
                obs_rows, cat_rows, parities, f_fit = (
                    obs_rows[keep],
                    cat_rows[keep],
                    parities[keep],
                    f_fit[keep],
                )
            tally.hypotheses += len(f_fit)  # every hypothesis of the batch, before testing
            for h in range(len(f_fit)):
                f = float(f_fit[h])
                # each focal length its own bearings and tolerances, one tally for all
                tester, outcome = _test(xy, (obs_rows[h], cat_rows[h], int(parities[h])), f,
                                        band, at_focal(f), tally, work[id(band)], (cx, cy),
                                        screen)  # fmt: skip
                if outcome is not None:
                    yield FovMatch(
                        outcome.identification, outcome.reason, tally.hypotheses, f, band
                    )
                    if outcome.identification is None:  # ambiguous: the search ends
                        return
                if tester.exhausted:
                    yield FovMatch(None, tester.outcome().reason, tally.hypotheses, math.nan, None)
                    return
    if tester is None:
        yield FovMatch(
            None,
            "no 4-star pattern matches the catalog at any field of view in the range",
            0,
            float("nan"),
            None,
        )
        return
    yield FovMatch(None, tester.outcome().reason, tally.hypotheses, float("nan"), None)


def _observed(stars: int, patterns: np.ndarray | None) -> tuple[np.ndarray, list[int]]:
    """The observed patterns a search tries (rows of its points) and where its batches end:
    the 4-subsets of the first ``stars`` breadth first, a batch ending where a new star
    joins (C(m, 4) for m = 5, 7, 9, ...: most fields are identified by the first few), or the
    ``patterns`` given, in batches of ``_LOCAL_BATCH``."""
    if patterns is None:
        combos = breadth_first_combinations(stars)
        return combos, [math.comb(m, 4) for m in range(5, stars, 2)] + [len(combos)]
    combos = np.asarray(patterns, dtype=np.intp).reshape(-1, 4)
    return combos, [*range(_LOCAL_BATCH, len(combos), _LOCAL_BATCH), len(combos)]


def _test(xy, hypothesis, focal_px, band, settings, tally, work, principal, screen):
    """One ``hypothesis`` (rows of ``xy``, catalog rows, parity) verified with the bearings of
    ``focal_px`` (on the ``screen`` rows and its own, when given: ``_screened``): the tester
    and its outcome, the identification's rows those of ``xy``."""
    own, cat_rows, parity = hypothesis
    verified, points = None, xy
    if screen is not None:
        verified, own = _screened(screen, own, len(xy))
        points = xy[verified]
    tester = HypothesisTester(
        pinhole_bearings(points, *principal, focal_px),
        band.database,
        settings,
        tally,
        work=work,  # no order: the rows are brightest first
    )
    outcome = tester.test(own, cat_rows, parity)
    if outcome is not None and verified is not None and outcome.identification is not None:
        found = outcome.identification
        found = replace(found, obs_index=verified[found.obs_index])
        outcome = replace(outcome, identification=found)
    return tester, outcome


def _screened(screen: int, own: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``n`` points a hypothesis is verified on: the first ``screen`` and the
    hypothesis's ``own`` rows, and where those are among them."""
    first = np.arange(min(screen, n))
    extra = np.unique(own[own >= screen])
    rows = np.concatenate([first, extra])
    return rows, np.where(own < screen, own, screen + np.searchsorted(extra, own))


def _informative(rows: np.ndarray, xy: np.ndarray, sigma_px: float | None) -> np.ndarray:
    """The 4-star patterns (rows of ``xy``) whose longest edge spans at least
    ``MIN_PATTERN_TOLS`` pair tolerances: the edge ratios of a smaller one are known too
    loosely to pick catalog patterns (a tight cluster of bright stars, the Pleiades in a 10°
    field, matched thousands per band and took seconds a look-up), and it is verified no
    better than the patterns around it."""
    tol_px = MatchSettings.for_focal(sigma_px, 1.0).pair_tol_rad  # at a focal length of 1 px
    d = np.linalg.norm(xy[rows[:, :, None]] - xy[rows[:, None, :]], axis=-1)  # (m, 4, 4)
    return rows[d.reshape(len(rows), -1).max(axis=1) >= MIN_PATTERN_TOLS * tol_px]


def _settings(sigma_px, max_false_match_probability, parity, max_hypotheses, deadline, point_mag,
              focal_px):  # fmt: skip
    """The verification settings of one hypothesis's focal length."""
    settings = MatchSettings.for_focal(
        sigma_px, focal_px, max_false_match_probability=max_false_match_probability, parity=parity
    )
    return replace(settings, max_hypotheses=max_hypotheses, deadline=deadline, point_mag=point_mag)


def _near(band: Band, cat_rows: np.ndarray, near: tuple[np.ndarray, float]) -> np.ndarray:
    """Which hypotheses' first catalog star lies within the hint's radius plus the band's
    half diagonal of its direction (``near``: unit vector, radius in rad)."""
    reach = math.cos(min(near[1] + 0.5 * band.database.max_angle_rad, math.pi))
    return band.catalog.vectors[cat_rows[:, 0]] @ near[0] >= reach


def _band_hypotheses(xy, rows, band, cells, sigma_px, parity, focal_range_px, principal, deadline):
    """The hypotheses of one band for the observed patterns ``rows`` (4-subsets of ``xy``):
    every cell of the band in one look-up (the patterns with the bearings of each guessed
    focal length, stacked), a pairing found by two overlapping cells counted once, each
    given the focal length its six edges fit, kept when they then agree to the pixel
    tolerance within the focal range; none when the ``deadline`` passes. Returns (rows of xy
    (h, 4), catalog rows (h, 4), parities (h,), focal lengths (h,), px)."""
    cx, cy = principal
    f_cells = np.array([f for f, _, _ in cells])
    delta, rel_tol = cells[0][1], cells[0][2]
    settings = MatchSettings.for_focal(sigma_px, float(f_cells.min()), parity=parity)
    bearings = pinhole_bearings(xy[None], cx, cy, f_cells[:, None])  # (cells, n, 3)
    observed = bearings[:, rows].reshape(-1, 4, 3)
    parts, offsets = [], []
    # without a deadline in one look-up; with one in consecutive batches lasting about
    # ``budget.UNIT_SHARE`` of the budget (the same matches, in the same order)
    start, size = 0, len(observed) if deadline is None else _FIRST_LOOKUP
    while start < len(observed):
        if expired(deadline):
            parts, offsets = [], []  # the caller stops on the deadline
            break
        clock = time.perf_counter()
        parts.append(
            match_patterns(
                observed[start : start + size],
                band.table,
                band.catalog.vectors,
                settings.pair_tol_rad,
                band.database.max_angle_rad,
                parity,
                scale_range=(1.0 / (1.0 + 1.2 * delta), 1.0 / (1.0 - 1.2 * delta)),
                rel_tol=rel_tol,
                deadline=deadline,
            )
        )
        offsets.append(start)
        start += size
        if deadline is not None:
            size = next_chunk(deadline, time.perf_counter() - clock, size, len(observed))
    hyp = concat_matches(parts, offsets) if parts else None
    if hyp is None or len(hyp.pattern) == 0:
        empty = np.empty((0, 4), dtype=np.intp)
        return empty, empty, np.empty(0, dtype=np.int64), np.empty(0)
    cell, pattern = np.divmod(hyp.pattern, len(rows))
    key = np.column_stack([pattern[:, None], hyp.obs_local, hyp.cat_rows, hyp.parity])
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    cell, pattern = cell[first], pattern[first]
    obs_local, cat_rows, parities = hyp.obs_local[first], hyp.cat_rows[first], hyp.parity[first]
    obs_rows = rows[pattern[:, None], obs_local]  # (h, 4) rows of xy
    # each pairing's focal length, in slices with the deadline looked at between them (a
    # dense band's look-up may pair a frame's patterns hundreds of thousands of ways)
    f_fit, err = np.ones(len(first)), np.full(len(first), np.inf)
    for start in range(0, len(first), _FIT_SLICE):
        if expired(deadline):
            break
        part = slice(start, start + _FIT_SLICE)
        cat_edges = pattern_edges(band.catalog.vectors[cat_rows[part]])
        obs_edges = pattern_edges(bearings[cell[part, None], obs_rows[part]])
        f0 = f_cells[cell[part]] * obs_edges.max(axis=1) / cat_edges.max(axis=1)
        f_fit[part], err[part] = fit_pattern_focal(xy[obs_rows[part]], cat_edges, cx, cy, f0)
    tol_px = settings.pair_tol_rad * float(f_cells.min())
    good = np.flatnonzero(
        (err * f_fit <= tol_px)
        & (f_fit >= focal_range_px[0] * 0.99)
        & (f_fit <= focal_range_px[1] * 1.01)
    )
    return obs_rows[good], cat_rows[good], parities[good], f_fit[good]
