"""A solved image's WCS fitted on every detection a deeper catalog explains.

A solve matches the image's ~50 brightest detections to the identification catalog; a plate
solver's WCS (astrometry.net's "tweak") is fitted on hundreds. ``deep_fit`` takes the WCS fitted
to the solve's matched stars, projects a deeper catalog through it (as many stars in the image
as there are detections, the embedded Gaia DR3 to G 10 unless the solve's own catalog is deeper),
pairs each detection with a catalog star only where the pairing is unambiguous, fits again on
all the pairs (``fit_wcs_to_stars``: its F-tests pick the SIP order the stars can measure) and
repeats with the pairs that new WCS leaves within 3 rms, until the pairs no longer change.

A pairing is unambiguous when the detection and the catalog star are each other's nearest and
no other catalog star lies within twice the match radius of the detection. The match radius is
3 times the rms of the fit it starts from, at least ``MIN_RADIUS_PX``, and at most the radius
within which a detection would meet a catalog star by chance once in ``CHANCE`` tries.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from starnav.catalog import Catalog
from starnav.errors import StarnavError
from starnav.output.wcs import StarFitWcs, fit_wcs_to_stars

MIN_RADIUS_PX = 1.0
MAX_RADIUS_PX = 5.0
CHANCE = 100  # a detection meets a catalog star by chance within the match radius 1 time in this
CATALOG_PER_DETECTION = 1.0  # catalog stars in the image per detection, at most
ROUNDS = 4
CLIP_RMS = 3.0


def in_image(xy: np.ndarray, width: int, height: int) -> np.ndarray:
    """Whether each of ``xy`` (n, 2), starnav px, is finite and on a ``width`` x ``height``
    image, edges included."""
    ok = np.isfinite(xy).all(axis=1)
    ok[ok] &= (xy[ok, 0] >= 0) & (xy[ok, 0] <= width) & (xy[ok, 1] >= 0) & (xy[ok, 1] <= height)
    return ok


def _field(fit: StarFitWcs, catalogs, width: int, height: int, n_detections: int):
    """The brightest stars inside the image through ``fit`` of whichever of ``catalogs``
    holds the most there, at most ``CATALOG_PER_DETECTION`` per detection: (vectors (m, 3),
    px (m, 2))."""
    corners = np.array([[0, 0], [width, 0], [0, height], [width, height], [width / 2, height / 2]])
    v = fit.directions(corners)
    centre = v[-1]
    radius = float(np.max(np.arccos(np.clip(v[:4] @ centre, -1.0, 1.0))))
    if not math.isfinite(radius) or radius >= math.radians(80.0):
        raise StarnavError("the field is too wide for a TAN fit on deep stars")
    near = max((c.within(centre, radius * 1.02, "field") for c in catalogs), key=len)
    order = np.argsort(near.mag, kind="stable")
    vectors = near.vectors[order]
    px = np.full((len(vectors), 2), np.nan)
    inside = np.zeros(len(vectors), dtype=bool)
    keep = max(int(CATALOG_PER_DETECTION * n_detections), 1)
    start = 0
    while start < len(vectors) and inside.sum() < keep:  # project in slices, brightest first
        part = slice(start, start + 2 * keep)
        px[part] = fit.pixels(vectors[part])
        inside[part] = in_image(px[part], width, height)
        start += 2 * keep
    rows = np.flatnonzero(inside)[:keep]
    return vectors[rows], px[rows]


def unambiguous_pairs(detections: np.ndarray, px: np.ndarray, radius_px: float):
    """Unambiguous pairs (detection rows, catalog rows) within ``radius_px``: each the other's
    nearest, no other catalog star within twice the radius of the detection (a distance matrix:
    a few hundred of each; scipy.spatial's import alone costs a drop-in call ~65 ms)."""
    if len(px) < 2 or len(detections) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    d2 = np.sum((detections[:, None, :] - px[None, :, :]) ** 2, axis=2)
    d2[~np.isfinite(d2)] = np.inf  # a star the WCS puts nowhere
    two = np.argpartition(d2, 1, axis=1)[:, :2]
    near2 = np.take_along_axis(d2, two, axis=1)
    first = np.argmin(near2, axis=1)
    cat = np.take_along_axis(two, first[:, None], axis=1)[:, 0]
    dist = np.sqrt(near2.min(axis=1))
    second = np.sqrt(near2.max(axis=1))
    det = np.flatnonzero((dist <= radius_px) & (second > 2.0 * radius_px))
    cat = cat[det]
    mutual = np.argmin(d2[:, cat], axis=0) == det  # the catalog star's nearest detection
    return det[mutual], cat[mutual]


def deep_fit(
    fit: StarFitWcs,
    detections_xy: np.ndarray,
    catalogs: Sequence[Catalog],
    width: int,
    height: int,
    *,
    crpix_px: tuple[float, float] | None = None,
) -> StarFitWcs | None:
    """``fit`` (the WCS fitted to a solve's matched stars) fitted again on every detection
    (``detections_xy`` (n, 2), starnav px) that a star explains unambiguously (module
    docstring), the stars taken from whichever of ``catalogs`` holds the most in the field;
    None when the deep pairs are not more than the stars of ``fit``."""
    xy = np.asarray(detections_xy, dtype=float).reshape(-1, 2)
    xy = xy[np.isfinite(xy).all(axis=1)]
    if len(xy) <= fit.n_stars:
        return None
    with np.errstate(all="ignore"):
        try:
            return _refitted(fit, xy, catalogs, width, height, crpix_px)
        except (StarnavError, np.linalg.LinAlgError):  # a field too wide, SIP not invertible
            return None


def _refitted(fit, xy, catalogs, width, height, crpix_px) -> StarFitWcs | None:
    vectors, px = _field(fit, catalogs, width, height, len(xy))
    chance_px = math.sqrt(width * height / (math.pi * max(len(px), 1) * CHANCE))
    radius = float(np.clip(3.0 * fit.rms_px, MIN_RADIUS_PX, min(MAX_RADIUS_PX, chance_px)))
    best, used = None, None
    for _ in range(ROUNDS):
        det, cat = unambiguous_pairs(xy, px, radius)
        if len(det) <= fit.n_stars:
            break
        key = (tuple(det), tuple(cat))
        if key == used:
            break
        start = (best or fit).crval_vector
        best = fit_wcs_to_stars(xy[det], vectors[cat], width, height, crpix_px=crpix_px,
                                start=start)  # fmt: skip
        used = key
        px = best.pixels(vectors)
        radius = float(np.clip(CLIP_RMS * best.rms_px, MIN_RADIUS_PX, radius))
    return best
