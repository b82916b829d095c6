"""The image circle of a circular fisheye: the bright disc of sky inside a dark frame.

All-sky cameras put the sky in a disc; outside it are dark corners and often burned-in text
(time stamps, site names), whose saturated glyphs would otherwise be taken for the brightest
stars. ``find_image_circle`` finds the disc on a copy reduced to about 256 px a side: pixels
brighter than halfway between the dark frame (2nd percentile) and the sky (median) form the
largest connected region; its holes are filled (trees, buildings and stars do not matter), and
a circle is fitted by least squares (Kasa's algebraic fit) to the region's boundary pixels
that do not lie on the image border, so a disc cut by the frame is still found. Boundary
pixels farther than 3 reduced pixels from the circle (a tree line, a lit horizon) are dropped
and the circle refitted once; when they are most of the edge (all but ``_MIN_ROUND_SHARE``),
the bright region is sky between trees or roofs, not a disc. No disc (a full-frame fisheye, a
daylight frame) gives None, and so does a circle whose edge is soft (``contrast`` under
``LENS_EDGE_CONTRAST``): a photograph's vignetting, or a wide-angle lens's, is not an image
circle, and taken for one it would hide sky (three quarters of a meteor camera's frame) and
set a fisheye scan's focal lengths from a radius that is no horizon.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

_REDUCED_PX = 256
_OUTLIER_REDUCED_PX = 3.0
_MIN_RADIUS_FRACTION = 0.25  # of the shorter side
_MIN_DARK_FRACTION = 0.05  # of the reduced image outside the disc
_EDGE_BAND = 0.04  # of the radius: the rings either side of the edge whose levels are compared
_MIN_ROUND_SHARE = 0.15  # of the disc's edge on its circle (all-sky frames 0.23-1.0; the sky
# between a phone photograph's trees 0.07)
LENS_EDGE_CONTRAST = 0.5  # a lens's image circle from this edge contrast on (all-sky frames
# measured 0.65-1.5; vignetted photographs and wide-angle meteor cameras -0.2-0.35)


@dataclass(frozen=True)
class ImageCircle:
    """A circular fisheye's disc of sky: centre (``cx``, ``cy``, px, our convention: top-left
    pixel centre at (0.5, 0.5)) and ``radius_px``; ``contrast``: the step in level across
    the circle's edge (the median just inside less the median just outside, ±``_EDGE_BAND``
    of the radius) over the sky's level above the dark frame's (about 1 for a lens's sharp
    image circle; a photograph's vignetting, which a circle also fits, scores near 0)."""

    cx: float
    cy: float
    radius_px: float
    contrast: float = 1.0

    def outside(self, width: int, height: int, *, margin_px: float = 0.0) -> np.ndarray:
        """Boolean (height, width) mask, True for pixels whose centre lies outside the circle
        shrunk by ``margin_px``."""
        y = np.arange(height, dtype=np.float64)[:, None] + 0.5
        x = np.arange(width, dtype=np.float64)[None, :] + 0.5
        r = self.radius_px - margin_px
        return (x - self.cx) ** 2 + (y - self.cy) ** 2 > r * r


_CORNER_FRACTION = 0.04  # of the shorter side: the corner patches looked at
_DARK_CORNER_SHARE = 0.25  # a corner darker than this share of the way from black to the sky


def dark_corners(image: np.ndarray) -> bool:
    """Whether all four corners of a 2-D image are much darker than its centre, as around a
    circular fisheye's disc: each corner patch's median below a quarter of the way from the
    darkest corner to the centre's median, and the centre well above the corners' spread.
    Cheap (five small medians), so any image can be asked before ``find_image_circle``."""
    data = np.asarray(image)
    height, width = data.shape
    k = max(2, int(_CORNER_FRACTION * min(height, width)))
    corners = [data[:k, :k], data[:k, -k:], data[-k:, :k], data[-k:, -k:]]
    h2, w2 = height // 2, width // 2
    centre = float(np.nanmedian(data[h2 - k : h2 + k, w2 - k : w2 + k]))
    levels = np.array([float(np.nanmedian(c)) for c in corners])
    if not (np.all(np.isfinite(levels)) and math.isfinite(centre)):
        return False
    floor = float(levels.min())
    spread = max(float(np.nanstd(corners[int(np.argmin(levels))])), 1e-6)
    if centre - floor < 10.0 * spread:
        return False
    return bool(np.all(levels < floor + _DARK_CORNER_SHARE * (centre - floor)))


def find_image_circle(image: np.ndarray) -> ImageCircle | None:
    """The bright disc of a circular fisheye in a 2-D image (row 0 at the top), or None when
    the image has no dark frame around a disc of radius at least a quarter of its shorter
    side, or the disc's edge is too soft for a lens's image circle (``LENS_EDGE_CONTRAST``)."""
    from scipy import ndimage  # here: a pinhole image's solve does not import scipy.ndimage

    data = np.asarray(image, dtype=np.float32)
    height, width = data.shape
    step = max(1, math.ceil(max(height, width) / _REDUCED_PX))
    small = _block_mean(data, step)
    finite = small[np.isfinite(small)]
    if finite.size == 0:
        return None
    dark, sky = np.percentile(finite, [2.0, 50.0])
    if not sky > dark:
        return None
    bright = np.nan_to_num(small, nan=dark) > 0.5 * (dark + sky)
    labels, n = ndimage.label(bright)
    if n == 0:
        return None
    sizes = np.bincount(labels.ravel())[1:]
    disc = ndimage.binary_fill_holes(labels == 1 + int(np.argmax(sizes)))
    if disc.mean() > 1.0 - _MIN_DARK_FRACTION:
        return None
    edge = disc & ~ndimage.binary_erosion(disc)
    edge[0, :] = edge[-1, :] = edge[:, 0] = edge[:, -1] = False
    ys, xs = np.nonzero(edge)
    if len(xs) < 10:
        return None
    cx, cy, r = _fit_circle(xs + 0.5, ys + 0.5)
    near = np.abs(np.hypot(xs + 0.5 - cx, ys + 0.5 - cy) - r) <= _OUTLIER_REDUCED_PX
    if near.mean() < _MIN_ROUND_SHARE:  # sky between trees or roofs, not a lens's disc
        return None
    if near.sum() >= 10:
        cx, cy, r = _fit_circle(xs[near] + 0.5, ys[near] + 0.5)
    if not (np.isfinite(r) and r * step >= _MIN_RADIUS_FRACTION * min(height, width)):
        return None
    rows, cols = np.indices(small.shape)
    rho = np.hypot(cols + 0.5 - cx, rows + 0.5 - cy) / r
    inner = small[(rho > 1 - 2 * _EDGE_BAND) & (rho <= 1 - _EDGE_BAND)]
    outer = small[(rho >= 1 + _EDGE_BAND) & (rho < 1 + 2 * _EDGE_BAND)]
    inner, outer = inner[np.isfinite(inner)], outer[np.isfinite(outer)]
    contrast = 0.0
    if inner.size and outer.size:
        contrast = float((np.median(inner) - np.median(outer)) / (sky - dark))
    if contrast < LENS_EDGE_CONTRAST:
        return None
    return ImageCircle(float(cx * step), float(cy * step), float(r * step), contrast)


def _block_mean(data: np.ndarray, step: int) -> np.ndarray:
    """Mean of step x step blocks (the last partial row and column of blocks dropped)."""
    if step == 1:
        return data
    h, w = (data.shape[0] // step) * step, (data.shape[1] // step) * step
    blocks = data[:h, :w].reshape(h // step, step, w // step, step)
    with warnings.catch_warnings():  # a block of NaN only (a masked border) is NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(blocks, axis=(1, 3))


def _fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Kasa's fit: x² + y² + D x + E y + F = 0 by linear least squares."""
    a = np.column_stack([x, y, np.ones_like(x)])
    d, e, f = np.linalg.lstsq(a, -(x * x + y * y), rcond=None)[0]
    cx, cy = -d / 2.0, -e / 2.0
    return float(cx), float(cy), float(math.sqrt(max(cx * cx + cy * cy - f, 0.0)))
