"""Where an all-sky camera sees sky: its image circle less the horizon's obstacles and glare.

An all-sky frame holds more than sky: the dark frame around the image circle (often with
burned-in text), and inside it the horizon and what stands above it (trees, buildings, domes,
the camera's own housing), lights and the Moon's glare. Their edges, lit branches and lamps
are found as "stars" and crowd the real ones out of the brightest hundred. ``find_sky_mask``
marks them, before detection, from what they lack: stars.

The frame is reduced to blocks of ``block_px`` (16 px or more: about 200 blocks across the
longer side), each measured on the frame binned 2 x 2 (which halves a hot pixel's peak
against a star's): its median (the level) and its noise (the median absolute deviation).
A block is *starry* when its brightest binned pixel stands ``STAR_PEAK_SIGMA`` noise sigmas
above its upper quartile (no block of white noise does, nor one astride a tree line, whose
sky part lifts the quartile; a star at the detection limit often does not, but what counts
is the share of starry blocks in a region). The level is compared with the sky's at the
same distance from the circle's centre (median and spread over each ring of blocks: an
all-sky frame's sky brightens towards the horizon alike in every direction, apart from city
glow, which widens the ring's spread): a block more than ``LEVEL_SIGMA`` spreads off it is
*dark* or *bright*.

- obstacles: connected regions of dark blocks, or of bright ones, that reach the rim of the
  disc (its outer 10 % of radius; the image border for a frame without circle) and hold
  under ``STARLESS_FRACTION`` of the starry share of the sky inside the rim: a tree line, a
  roof, a dome, the housing, a lit wall, a lamp at the horizon;
- glare: a connected region of blocks ``GLARE_SIGMA`` spreads or more over their ring that
  holds a saturated core (``SATURATED_SHARE`` of a block's binned pixels or more at the
  image's maximum): the Moon and its halo, a lamp and the cloud it lights. A saturated
  star does not lift its block's median, so it is not glare.

- the unlit surround: connected regions of *flat black* blocks (at the frame's lowest value
  with no noise at all: the clipped black around a sky disc cut by trees, or past the lens's
  circle when no sharp circle is found), reaching the rim and less starry than the lit sky
  (``FLAT_STARLESS_FRACTION``: a caption's letters and the hot pixels, which the black shows
  as well as the sky, pass for stars there; a sky clipped to black keeps its stars, which the
  lit parts lack): the captions, logos and lamps burnt or standing in them are no stars.
  Their noise, nil, is not the sky's: every block's noise is floored at half the lit blocks'
  typical noise.

Both are widened by one block (their edges are where the false sources sit). A region whose
share of starry blocks is that of the sky is never taken for an obstacle, however bright or
dark (the Milky Way, a thin cloud with stars through it, a glow at the horizon): the mask
removes places where few stars are found anyway, and the junk in them. Clouds away from the
horizon are left alone.

Per-source rejection works beside the mask, in ``starnav.detect.stars``: hot pixels
(``starnav.detect.hot``), trails (``starnav.detect.photometry.misshapen``: a > 2.5 b),
sources in foreground (an annulus rougher than the noise) and extended ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from starnav.detect.circle import ImageCircle, find_image_circle

TARGET_BLOCKS = 200  # blocks across the longer side
MIN_BLOCK_PX = 16
MIN_INTERIOR_BLOCKS = 4
MIN_BLOCKS = 16  # a frame of fewer blocks a side is not judged (only its circle)
STAR_PEAK_SIGMA = 6.0  # a block's brightest binned pixel this far over its median: a star
STARLESS_FRACTION = 0.25  # of the sky's share of starry blocks: a starless region
FLAT_STARLESS_FRACTION = 1.0  # a flat black one (its hot pixels and captions pass for stars)
LEVEL_SIGMA = 3.0  # ring spreads off the ring's median: a dark or bright block
GLARE_SIGMA = 10.0  # ring spreads over the ring's median: glare around a saturated core
RIM_FRACTION = 0.9  # of the circle's radius: the rim, where the horizon lies
SATURATED_SHARE = 0.1  # of a block's pixels at the image's maximum: a glare core
RING_BLOCKS = 2.0  # width of the rings of the level model, in blocks
CIRCLE_MARGIN = 0.01  # of the radius: the circle shrunk by this (its rim is lit horizon)
LIT_DISC_SHARE = 0.25  # of the frame masked, without a circle: the sky left suggests a disc
LIT_DISC_QUANTILE = 0.99  # of the sky's distances from its centroid: that disc's radius


@dataclass(frozen=True, eq=False)
class SkyMask:
    """What of an image is not sky: ``excluded`` (bool, height x width, True: not sky), the
    ``circle`` (None: none found, a full-frame image), and the share of the image's pixels
    that is ``outside`` the circle, ``obstacles`` (the horizon and what stands above it) and
    ``glare`` (the Moon, lights); ``block_px``: the block size of the analysis."""

    excluded: np.ndarray
    circle: ImageCircle | None
    outside: float
    obstacles: float
    glare: float
    block_px: int

    @property
    def sky(self) -> float:
        """The share of the image's pixels left as sky."""
        return 1.0 - float(self.excluded.mean())

    def lit_disc(self) -> ImageCircle | None:
        """Without an image circle, the disc the sky left by the mask suggests when the
        mask took ``LIT_DISC_SHARE`` of the frame or more (a circular fisheye whose rim the
        trees or a dark housing hide): centred on the sky's centroid, as far out as its
        farthest part (``LIT_DISC_QUANTILE`` of its pixels' distances: a gap between trees
        lies near the horizon), ``contrast`` 0 (no edge was seen). A start for the focal
        scan, not a circle to mask by. None otherwise."""
        if self.circle is not None or 1.0 - self.sky < LIT_DISC_SHARE:
            return None
        step = max(1, self.block_px // 4)
        rows, cols = np.nonzero(~self.excluded[::step, ::step])
        if len(rows) == 0:
            return None
        x, y = (cols + 0.5) * step, (rows + 0.5) * step
        cx, cy = float(x.mean()), float(y.mean())
        radius = float(np.quantile(np.hypot(x - cx, y - cy), LIT_DISC_QUANTILE))
        return ImageCircle(cx, cy, radius, contrast=0.0)

    def to_dict(self) -> dict:
        """The shares (of the image's pixels) and the circle, for JSON."""
        circle = self.circle
        return {
            "circle": None
            if circle is None
            else {"cx": circle.cx, "cy": circle.cy, "radius_px": circle.radius_px},
            "sky": self.sky,
            "outside": self.outside,
            "obstacles": self.obstacles,
            "glare": self.glare,
        }

    def words(self) -> str:
        """What was masked, for a person: "obstacles 12 % of the disc, glare 3 %"."""
        disc = 1.0 - self.outside
        parts = [
            f"{name} {100.0 * share / disc:.0f} % of the {'disc' if self.circle else 'frame'}"
            for name, share in (("horizon obstacles", self.obstacles), ("glare", self.glare))
            if share > 0 and disc > 0
        ]
        return ", ".join(parts) if parts else "nothing inside the sky masked"


def find_sky_mask(image: np.ndarray, *, circle: ImageCircle | bool | None = True) -> SkyMask:
    """The sky mask of a 2-D image (row 0 at the top; NaN pixels count as not sky).
    ``circle``: the image circle (True: found with ``find_image_circle``; None or False:
    none, the whole frame is looked at)."""
    data = np.asarray(image, dtype=np.float32)
    height, width = data.shape
    if circle is True:
        circle = find_image_circle(data)
    circle = circle or None
    if circle is not None:
        outside = circle.outside(width, height, margin_px=CIRCLE_MARGIN * circle.radius_px)
    else:
        outside = np.zeros((height, width), dtype=bool)
    outside |= ~np.isfinite(data)
    block = max(MIN_BLOCK_PX, 2 * math.ceil(max(height, width) / TARGET_BLOCKS / 2))
    rows, cols = height // block, width // block
    if min(rows, cols) < MIN_BLOCKS:  # too small to judge: only the circle
        return _mask(outside, outside, None, None, circle, block)
    level, noise, peak, saturated, valid, flat = _blocks(data, outside, block)
    radius, rim = _radii(rows, cols, block, circle)
    starry = valid & (peak > STAR_PEAK_SIGMA * noise)
    inner = valid & ~rim & (radius <= RIM_FRACTION * _disc_radius(circle, height, width))
    lit = inner & ~flat
    reference = float(starry[lit].mean()) if lit.any() else 0.0
    deviation = _ring_deviation(level, valid & ~flat, radius, block, noise)
    seeds = rim & valid
    obstacles = _starless_parts(valid & (deviation < -LEVEL_SIGMA), seeds, starry, reference)
    obstacles |= _starless_parts(valid & (deviation > LEVEL_SIGMA), seeds, starry, reference)
    obstacles |= _starless_parts(flat, seeds, starry, reference, FLAT_STARLESS_FRACTION)
    glare = _touching(valid & (deviation > GLARE_SIGMA), saturated) & ~obstacles
    obstacles, glare = _grown(obstacles), _grown(glare)
    return _mask(outside, outside, obstacles, glare, circle, block)


def _blocks(data: np.ndarray, outside: np.ndarray, block: int):
    """Per block of ``block`` px: (median, noise, brightest over the upper quartile (each of
    the frame binned 2 x 2), whether it holds a glare core, whether it is sky enough to
    judge: under half outside, whether it is flat black: at the frame's lowest value, its
    noise nil). The noise is floored at half the typical noise of the blocks not flat."""
    height, width = data.shape
    rows, cols = height // block, width // block
    half = block // 2
    crop = data[: rows * block, : cols * block]
    cut = outside[: rows * block, : cols * block]
    vmax = float(np.nanmax(np.where(outside, -np.inf, data)))
    binned = 0.25 * (crop[0::2, 0::2] + crop[1::2, 0::2] + crop[0::2, 1::2] + crop[1::2, 1::2])
    gone = cut[0::2, 0::2] | cut[1::2, 0::2] | cut[0::2, 1::2] | cut[1::2, 1::2]
    cells = binned.reshape(rows, half, cols, half).transpose(0, 2, 1, 3).reshape(rows, cols, -1)
    masked = gone.reshape(rows, half, cols, half).transpose(0, 2, 1, 3).reshape(rows, cols, -1)
    valid = masked.mean(axis=2) < 0.5
    cells = np.where(masked, np.nan, cells)
    count = cells.shape[2] - masked.sum(axis=2)
    ordered = np.sort(cells, axis=2)  # NaN last
    level, upper, top = (_nth(ordered, count, share) for share in (0.5, 0.75, 1.0))
    noise = np.nan_to_num(
        1.4826 * _nth(np.sort(np.abs(cells - level[..., None]), axis=2), count, 0.5)
    )
    peak = top - upper
    vmin = float(np.nanmin(np.where(outside, np.inf, data)))
    flat = valid & (noise == 0) & (np.nan_to_num(level, nan=np.inf) <= vmin)
    judged = valid & ~flat
    floor = 0.5 * float(np.median(noise[judged])) if judged.any() else 0.0
    noise = np.fmax(noise, max(floor, 0.25))
    saturated = np.count_nonzero(cells >= vmax, axis=2) >= SATURATED_SHARE * cells.shape[2]
    return np.nan_to_num(level), noise, np.nan_to_num(peak), saturated, valid, flat


def _nth(ordered: np.ndarray, count: np.ndarray, share: float) -> np.ndarray:
    """The value at ``share`` (0.5: the upper median; 1: the largest) of each row of
    ``ordered`` (sorted along the last axis, its ``count`` finite values first), NaN where
    there are none."""
    index = np.clip((share * count).astype(np.intp), 0, np.maximum(count - 1, 0))
    value = np.take_along_axis(ordered, index[..., None], axis=2)[..., 0]
    return np.where(count > 0, value, np.nan)


def _disc_radius(circle: ImageCircle | None, height: int, width: int) -> float:
    """The disc's radius (px), or the half-diagonal of a frame without circle."""
    return circle.radius_px if circle is not None else 0.5 * math.hypot(width, height)


def _radii(rows: int, cols: int, block: int, circle: ImageCircle | None):
    """Each block centre's distance (px) from the circle's centre (the frame's without one),
    and whether it lies on the rim (the disc's outer tenth; a frame's border blocks)."""
    height, width = rows * block, cols * block
    y = (np.arange(rows)[:, None] + 0.5) * block
    x = (np.arange(cols)[None, :] + 0.5) * block
    if circle is None:
        radius = np.hypot(x - 0.5 * width, y - 0.5 * height)
        rim = np.zeros((rows, cols), dtype=bool)
        rim[0, :] = rim[-1, :] = rim[:, 0] = rim[:, -1] = True
        return radius, rim
    radius = np.hypot(x - circle.cx, y - circle.cy)
    return radius, radius >= RIM_FRACTION * circle.radius_px - block


def _ring_deviation(
    level: np.ndarray, valid: np.ndarray, radius: np.ndarray, block: int, noise: np.ndarray
) -> np.ndarray:
    """Each block's level off the median of its ring (``RING_BLOCKS`` wide), in the ring's
    spread (the median absolute deviation; at least the blocks' typical noise over the
    square root of a block's binned pixels, and a twentieth of the ring's level)."""
    ring = (radius / (RING_BLOCKS * block)).astype(int)
    out = np.zeros_like(level)
    per_pixel = float(np.median(noise[valid])) / (block / 2) if valid.any() else 0.0
    for k in np.unique(ring[valid]):
        members = valid & (ring == k)
        values = level[members]
        centre = float(np.median(values))
        spread = 1.4826 * float(np.median(np.abs(values - centre)))
        spread = max(spread, per_pixel, 0.05 * abs(centre), 1e-6)
        here = ring == k
        out[here] = (level[here] - centre) / spread
    return out


def _starless_parts(
    region: np.ndarray,
    seeds: np.ndarray,
    starry: np.ndarray,
    reference: float,
    fraction: float = STARLESS_FRACTION,
) -> np.ndarray:
    """The connected parts (8-connected) of ``region`` that hold a ``seeds`` block and whose
    share of ``starry`` blocks is under ``fraction`` of the sky's (``reference``),
    counted over their interior (the part one block from their edge) when that has
    ``MIN_INTERIOR_BLOCKS`` or more."""
    from scipy import ndimage

    labels, n = ndimage.label(region, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return np.zeros_like(region)
    index = np.arange(1, n + 1)
    # judged on its interior (its edge blocks hold some sky, and the stars in it), when it
    # has enough of one
    core = labels * ndimage.binary_erosion(region, structure=np.ones((3, 3), dtype=bool))
    inner = ndimage.sum_labels(np.ones_like(region), core, index) >= MIN_INTERIOR_BLOCKS
    judged = np.where(inner[labels - 1] & (labels > 0), core, labels)
    size = ndimage.sum_labels(np.ones_like(region), judged, index)
    stars = ndimage.sum_labels(starry, judged, index)
    seeded = ndimage.maximum(seeds, labels, index).astype(bool)
    keep = np.zeros(n + 1, dtype=bool)
    keep[1:] = seeded & (stars < fraction * reference * size)
    return keep[labels]


def _touching(region: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The connected parts (8-connected) of ``region`` that hold a ``seeds`` block."""
    from scipy import ndimage

    labels, n = ndimage.label(region, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return np.zeros_like(region)
    keep = np.zeros(n + 1, dtype=bool)
    keep[np.unique(labels[seeds & region])] = True
    keep[0] = False
    return keep[labels]


def _grown(region: np.ndarray) -> np.ndarray:
    """``region`` widened by one block (8-connected)."""
    from scipy import ndimage

    if not region.any():
        return region
    return ndimage.binary_dilation(region, structure=np.ones((3, 3), dtype=bool))


def _full(blocks: np.ndarray | None, shape: tuple[int, int], block: int) -> np.ndarray:
    """A block map at full resolution (the last partial blocks take their neighbours')."""
    height, width = shape
    if blocks is None:
        return np.zeros(shape, dtype=bool)
    full = np.repeat(np.repeat(blocks, block, axis=0), block, axis=1)
    pad = ((0, height - full.shape[0]), (0, width - full.shape[1]))
    return np.pad(full, pad, mode="edge")


def _mask(excluded, outside, obstacles, glare, circle, block) -> SkyMask:
    shape = outside.shape
    obstacle_px = _full(obstacles, shape, block) & ~outside
    glare_px = _full(glare, shape, block) & ~outside & ~obstacle_px
    excluded = excluded | obstacle_px | glare_px
    return SkyMask(
        excluded,
        circle,
        float(outside.mean()),
        float(obstacle_px.mean()),
        float(glare_px.mean()),
        block,
    )
