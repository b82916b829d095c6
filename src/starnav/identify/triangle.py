"""Liebe's triangle algorithm: measured star triangles matched to catalog triangles.

Liebe (1992, 1993) identifies a field by one triangle of bright stars: its sides (and the
angle between two of them) are looked up in a catalog of star triangles, and the match gives
the attitude. Here the catalog triangles come from the pair database
(``pyramid.catalog_triangles``) and every candidate is verified with the whole field
(``verify.HypothesisTester``); what this module adds is the order in which measured triangles
are tried, the subject of the published whole-sky study (domain.md, section 2):

- ``"brightest"``: the triangles of the brightest NB = 6 stars in the order 1-2-3, 1-2-4, 1-2-5,
  ... (lexicographic combinations of the brightness order, 20 triangles), then those that add
  the 7th, 8th, ... brightest star, each in the same order.
- ``"optimized"`` (the "secondary optimisation"): the same order, but the observation triangle
  is chosen with two constraints before matching: no side shorter than ``min_side_px``
  (d_min = 10 px: the dimmer star of such a side is a likely double and is dropped, the next
  brightest takes its place) and no triangle flatter than ``min_height_px`` (delta = 4 px: its
  smallest height, over its longest side, is too small to fix its shape). The triangles that
  break a constraint are tried last, when no good one verifies.

Triangle geometry is measured in pixels on the focal plane (``settings.pixel_rad`` radians per
pixel): the smallest height of a triangle with sides s1 <= s2 <= s3 is the distance of the
vertex opposite its longest side (the base) from that side, 2 * area / s3 = s2 * sin(theta_min).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from starnav.errors import StarnavError, shown
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.pyramid import match_triangles

SELECTIONS = ("optimized", "brightest")
PUBLISHED_BRIGHTEST = 6  # NB of the published method: its 20 triangles come first
MIN_SIDE_PX = 10.0  # d_min: star images of ~5 x 5 px must be separate
MIN_HEIGHT_PX = 4.0  # delta: the double-star threshold, applied to the triangle's height


@lru_cache(maxsize=64)
def brightness_triangles(n: int, first: int = PUBLISHED_BRIGHTEST) -> np.ndarray:
    """Index triples (i < j < k), shape (m, 3), of ``n`` stars in brightness order.

    All triangles of the ``first`` brightest stars in lexicographic order (0-1-2, 0-1-3, ...,
    the published 1-2-3, 1-2-4, ...), then for each next star k the triangles (i, j, k) it
    closes with the brighter ones, again lexicographic. The array is cached and read-only.
    """
    rows = []
    head = min(first, n)
    for i in range(head):
        for j in range(i + 1, head):
            rows.extend((i, j, k) for k in range(j + 1, head))
    for k in range(head, n):
        for i in range(k):
            rows.extend((i, j, k) for j in range(i + 1, k))
    out = np.array(rows, dtype=np.intp).reshape(-1, 3)
    out.flags.writeable = False  # cached: shared by every call
    return out


def focal_plane_px(bearings: np.ndarray, pixel_rad: float) -> np.ndarray:
    """Camera-frame unit vectors (n, 3) to focal-plane offsets from the principal point in
    pixels (n, 2): the pinhole projection with a focal length of ``1 / pixel_rad`` px."""
    z = np.maximum(bearings[:, 2:3], 1e-12)
    return bearings[:, :2] / z / pixel_rad


def triangle_shape_px(points_px: np.ndarray, triples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shortest side and smallest height (pixels) of the triangles ``triples`` (m, 3) of the
    focal-plane ``points_px`` (n, 2).

    The smallest height is the one over the longest side (the base): 2 * area / s3, which is
    s2 * sin(theta_min) for sides s1 <= s2 <= s3 and smallest interior angle theta_min.
    """
    p = points_px[np.asarray(triples, dtype=np.intp).reshape(-1, 3)]
    u = p[:, 1] - p[:, 0]
    v = p[:, 2] - p[:, 0]
    sides = np.stack([np.hypot(*u.T), np.hypot(*v.T), np.hypot(*(p[:, 2] - p[:, 1]).T)], axis=1)
    twice_area = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    longest = sides.max(axis=1)
    height = np.divide(twice_area, longest, out=np.zeros_like(longest), where=longest > 0)
    return sides.min(axis=1), height


def bad_triangles(
    points_px: np.ndarray,
    triples: np.ndarray,
    *,
    min_side_px: float = MIN_SIDE_PX,
    min_height_px: float = MIN_HEIGHT_PX,
) -> np.ndarray:
    """Which triangles (m,) break a constraint: a side below ``min_side_px`` or the smallest
    height (over the longest side) below ``min_height_px``."""
    shortest, height = triangle_shape_px(points_px, triples)
    return (shortest < min_side_px) | (height < min_height_px)


def drop_doubles(points_px: np.ndarray, min_side_px: float = MIN_SIDE_PX) -> np.ndarray:
    """Indices of the points kept (ascending) when, brightest first, every point closer than
    ``min_side_px`` to a brighter kept point is dropped (``points_px`` rows best-first)."""
    kept: list[int] = []
    for n in range(len(points_px)):
        if not kept or np.min(np.hypot(*(points_px[kept] - points_px[n]).T)) >= min_side_px:
            kept.append(n)
    return np.array(kept, dtype=np.intp)


def select_triangles(
    points_px: np.ndarray,
    selection: str = "optimized",
    *,
    min_side_px: float = MIN_SIDE_PX,
    min_height_px: float = MIN_HEIGHT_PX,
) -> tuple[np.ndarray, int]:
    """Triangles (m, 3) of the focal-plane ``points_px`` (rows best-first) in the order a
    selection tries them, and how many of the first meet both constraints (for
    ``"brightest"``: all, it does not look).

    ``"optimized"``: the brightness order over the points left by ``drop_doubles``, without
    the too flat triangles, followed by every other triangle in brightness order.
    """
    if selection not in SELECTIONS:
        raise StarnavError(
            f"unknown triangle selection {selection!r}; choose one of {', '.join(SELECTIONS)}"
        )
    n = len(points_px)
    everything = brightness_triangles(n)
    if selection == "brightest":
        return everything, len(everything)
    kept = drop_doubles(points_px, min_side_px)
    candidates = kept[brightness_triangles(len(kept))]
    good = candidates[
        ~bad_triangles(points_px, candidates, min_side_px=min_side_px, min_height_px=min_height_px)
    ]
    # the rest, in brightness order, for when none of the good ones verifies
    key = (everything * np.array([n * n, n, 1])).sum(axis=1)
    rest = everything[~np.isin(key, (good * np.array([n * n, n, 1])).sum(axis=1))]
    return np.concatenate([good, rest]), len(good)


class Triangle:
    """Liebe's triangle method on the pair database, with whole-field verification.

    Keyword options: ``selection`` (``"optimized"`` or ``"brightest"``, see the module);
    ``max_triangles``: try at most this many measured triangles (None: until the hypothesis
    budget is spent; 1 or 2 reproduce the published first-try and two-try figures);
    ``min_side_px``, ``min_height_px``: the constraints of the optimized selection (pixels).
    """

    name = "triangle"
    OPTIONS = (("selection", SELECTIONS),)  # (name, allowed) set by name: identify/options.py

    def __init__(
        self,
        *,
        selection: str = "optimized",
        max_triangles: int | None = None,
        min_side_px: float = MIN_SIDE_PX,
        min_height_px: float = MIN_HEIGHT_PX,
    ) -> None:
        if selection not in SELECTIONS:
            raise StarnavError(
                f"unknown triangle selection {selection!r}; choose one of {', '.join(SELECTIONS)}"
            )
        if max_triangles is not None and (
            isinstance(max_triangles, bool)
            or not isinstance(max_triangles, (int, np.integer))
            or max_triangles < 1
        ):
            raise StarnavError(
                f"max_triangles must be a positive integer or None, got {shown(max_triangles)}"
            )
        for label, value in (("min_side_px", min_side_px), ("min_height_px", min_height_px)):
            if not (np.isfinite(value) and value >= 0):
                raise StarnavError(f"{label} must be >= 0 pixels, got {shown(value)}")
        self.selection = selection
        self.max_triangles = max_triangles
        self.min_side_px = float(min_side_px)
        self.min_height_px = float(min_height_px)

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (the only table this searches)."""
        return database.nbytes

    def triangles(
        self, bearings: np.ndarray, order: np.ndarray, settings: MatchSettings
    ) -> np.ndarray:
        """Rows of ``bearings`` of each measured triangle (m, 3), in the order they are tried:
        the first ``settings.max_stars`` of ``order`` make them."""
        order = np.asarray(order)[: settings.max_stars]
        # without a pixel scale, the thresholds count in units of the pair tolerance (>= 1 px)
        pixel_rad = settings.pixel_rad if settings.pixel_rad else settings.pair_tol_rad
        points = focal_plane_px(bearings[order], pixel_rad)
        triples, _ = select_triangles(
            points,
            self.selection,
            min_side_px=self.min_side_px,
            min_height_px=self.min_height_px,
        )
        if self.max_triangles is not None:
            triples = triples[: self.max_triangles]
        return order[triples.reshape(-1, 3)]

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        if min(len(order), settings.max_stars) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        triangles = self.triangles(bearings, order, settings)
        return match_triangles(bearings, triangles, database, settings, order=order)
