"""The sky background of an image and its pixel noise, as maps on a mesh of cells.

As Source Extractor does, the image is split into cells, each gets a sigma-clipped median
and rms, and the mesh is median-filtered over 3 x 3 cells; it is then interpolated
bilinearly (``mesh_maps``; sep's bicubic splines ring beside a roof or a lit tree line, and
their undershoot left bands of false residual, and negative noise, up to 100 px from it).
The mesh is 64 px; it is estimated on every
``step``-th pixel so that about 256 px a side are used (the map is smooth and the rms per
pixel is unchanged; 8x faster at 1024 px). A 64 px mesh follows moonlight and horizon
glow, not a tree line, a roof edge or the edge of a cloud: where its residual forms large
patches above the detection threshold, a second mesh of 24 px (``fine_background``) is
fitted to what is left with the compact sources masked. The rest is left to the per-star
local background (``starnav.detect.photometry``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

MESH_PX = 64
SAMPLE_PX = 256  # the background is estimated on about this many px a side
FINE_MESH_PX = 24
FINE_SAMPLE_PX = 384
CORRELATION_TILES = 32
_TILE_PX = 32
_MIN_TILES = 4
_MIN_CELL_FRACTION = 0.2
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True, eq=False)
class Background:
    """Background level and pixel rms of an image (image units): ``level_map`` and
    ``rms_map`` sampled every ``step`` px (map[i, j] covers rows i*step.., columns
    j*step..), ``level`` and ``rms`` their global values."""

    step: int
    level_map: np.ndarray
    rms_map: np.ndarray
    level: float
    rms: float

    def level_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Background level at integer pixel columns ``x`` and rows ``y``."""
        return self.level_map[y // self.step, x // self.step]

    def rms_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Pixel rms at integer pixel columns ``x`` and rows ``y``."""
        return self.rms_map[y // self.step, x // self.step]

    def scaled_rms(self, factor: float) -> Background:
        """The same background with its noise map and global rms multiplied by
        ``factor`` (the pixel rms of noise that is smoother than white noise)."""
        return Background(
            self.step,
            self.level_map,
            self.rms_map * np.float32(factor),
            self.level,
            self.rms * factor,
        )

    def with_rms_floor(self, floor: float) -> Background:
        """The same background with its global rms and noise map raised to at least
        ``floor`` (a noise-free image, or a quantised sky whose clipped rms is 0)."""
        return Background(
            self.step,
            self.level_map,
            np.maximum(self.rms_map, np.float32(floor)),
            self.level,
            max(self.rms, floor),
        )

    def full_rms(self, shape: tuple[int, int]) -> np.ndarray:
        """The noise map at every pixel of an image of ``shape`` (float32, C order)."""
        return _full(self.rms_map, self.step, shape)


def estimate_background(data: np.ndarray, mask: np.ndarray | None) -> Background:
    """sep's background and noise maps of ``data`` (float32, C order), ``mask`` True for
    pixels to leave out. The noise map rises under moonlight and over textured foreground
    (foliage, lit walls), which raises the detection threshold there."""
    height, width = data.shape
    step = max(1, min(height, width) // SAMPLE_PX)
    sample = data if step == 1 else np.ascontiguousarray(data[::step, ::step])
    sample_mask = None
    if mask is not None:
        sample_mask = mask if step == 1 else np.ascontiguousarray(mask[::step, ::step])
    cell = max(8, MESH_PX // step)
    bh, bw = min(cell, sample.shape[0]), min(cell, sample.shape[1])
    level_map, rms_map, level, rms = mesh_maps(sample, sample_mask, bh, bw)
    return Background(step, level_map, rms_map, level, rms)


def mesh_maps(
    sample: np.ndarray, mask: np.ndarray | None, bh: int, bw: int
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(level map, rms map, global level, global rms) of ``sample`` on a mesh of bh x bw
    px cells: in each cell the median and rms (median absolute deviation x 1.4826 about a
    plane fitted to the cell, or the standard deviation when that is 0) of the pixels
    within 3 sigmas (clipped three times), cells with too few such pixels (masked, a wall
    of stars) taken from their neighbours, the mesh median-filtered over 3 x 3 cells and
    interpolated bilinearly between cell centres (a spline rings beside a roof or a bright
    tree line, and its undershoot would leave a band of false residual there). Global
    values: medians."""
    height, width = sample.shape
    ny, nx = -(-height // bh), -(-width // bw)
    padded = np.full((ny * bh, nx * bw), np.nan, dtype=np.float32)
    padded[:height, :width] = sample
    if mask is not None:
        padded[:height, :width][mask] = np.nan
    cells = padded.reshape(ny, bh, nx, bw).transpose(0, 2, 1, 3).reshape(ny, nx, -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # cells wholly masked: NaN
        level = nanmedian_last(cells)
        rms = np.nanstd(cells, axis=2)
        for _ in range(3):
            kept = np.where(np.abs(cells - level[..., None]) <= 3.0 * rms[..., None], cells, np.nan)
            level, rms = nanmedian_last(kept), np.nanstd(kept, axis=2)
        # the median absolute deviation about a plane fitted to the cell (the gradient of a
        # cloud's edge or of moonlight is not noise), which a bright star's wings do not
        # raise, unless the sky is quantised so finely that it is 0
        rest = kept - _cell_planes(kept, bh, bw)
        centre = nanmedian_last(rest)
        mad = _MAD_TO_SIGMA * nanmedian_last(np.abs(rest - centre[..., None]))
        rms = np.where(mad > 0, mad, rms)
        few = np.sum(np.isfinite(kept), axis=2) < _MIN_CELL_FRACTION * bh * bw
    level[few], rms[few] = np.nan, np.nan
    if not np.isfinite(level).any():
        return np.zeros_like(sample), np.zeros_like(sample), 0.0, 0.0
    level, rms = _filled(level), _filled(rms)
    level, rms = median_3x3(level), median_3x3(rms)
    return (
        _bilinear(level, bh, bw, sample.shape),
        _bilinear(rms, bh, bw, sample.shape),
        float(np.median(level)),
        float(np.median(rms)),
    )


def nanmedian_last(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """The median over the last axis (``axis`` must be it) ignoring NaN (NaN where all
    are): numpy's nanmedian of many short rows takes a slow masked-array path, 20x
    slower than this sort."""
    if axis not in (-1, values.ndim - 1):
        raise ValueError(f"nanmedian_last works on the last axis, not axis {axis}")
    ordered = np.sort(values, axis=-1)  # NaN last
    count = np.isfinite(values).sum(axis=-1)
    low = np.take_along_axis(ordered, np.maximum(count - 1, 0)[..., None] // 2, axis=-1)[..., 0]
    high = np.take_along_axis(ordered, (count // 2)[..., None], axis=-1)[..., 0]
    return np.where(count > 0, 0.5 * (low + high), np.nan)


def _cell_planes(cells: np.ndarray, bh: int, bw: int) -> np.ndarray:
    """Least-squares planes through each cell's finite pixels (ny, nx, bh * bw), evaluated
    at every pixel of the cell (the cell mean where the fit is singular)."""
    row, col = np.divmod(np.arange(bh * bw), bw)
    terms = np.stack([np.ones(bh * bw), col - (bw - 1) / 2.0, row - (bh - 1) / 2.0])
    w = np.isfinite(cells).astype(np.float64)
    v = np.where(np.isfinite(cells), cells, 0.0)
    rhs = v @ terms.T  # (ny, nx, 3)
    normal = (w @ (terms[:, None, :] * terms[None, :, :]).reshape(9, -1).T).reshape(
        *cells.shape[:2], 3, 3
    )
    count = normal[..., 0, 0]
    ok = np.linalg.det(normal) > 1e-6 * np.maximum(count, 1.0) ** 3
    coef = np.zeros(rhs.shape)
    coef[..., 0] = rhs[..., 0] / np.maximum(count, 1.0)
    if ok.any():
        coef[ok] = np.linalg.solve(normal[ok], rhs[ok][..., None])[..., 0]
    return coef @ terms


def median_3x3(mesh: np.ndarray) -> np.ndarray:
    """The median of each cell's 3 x 3 neighbourhood, the edge cells repeated beyond the
    mesh: ``scipy.ndimage.median_filter(mesh, size=3, mode="nearest")`` for a mesh of finite
    values (the same numbers), without importing scipy.ndimage (0.2-0.3 s of a process that
    solves one image): ``detect.kernels.median_3x3``, which the fast path calls too."""
    from starnav.detect import kernels

    out = kernels.median_3x3(np.ascontiguousarray(mesh, dtype=np.float64))
    return out.astype(mesh.dtype, copy=False)


def _filled(mesh: np.ndarray) -> np.ndarray:
    """The mesh with its NaN cells set to the nearest finite cell's value."""
    bad = ~np.isfinite(mesh)
    if not bad.any():
        return mesh
    from scipy import ndimage  # here: a mesh without gaps (most) does not import it

    _, (iy, ix) = ndimage.distance_transform_edt(bad, return_indices=True)
    return mesh[iy, ix]


def _bilinear(mesh: np.ndarray, bh: int, bw: int, shape: tuple[int, int]) -> np.ndarray:
    """The mesh of cell values interpolated bilinearly to every pixel (cell values at the
    cell centres, constant beyond the outer centres), float32: along rows, then columns."""
    height, width = shape

    def weights(n: int, cell: int, cells: int):
        t = np.clip((np.arange(n) + 0.5) / cell - 0.5, 0, cells - 1)
        lo = np.minimum(t.astype(int), max(cells - 2, 0))
        return lo, np.minimum(lo + 1, cells - 1), (t - lo).astype(np.float32)

    y0, y1, fy = weights(height, bh, mesh.shape[0])
    x0, x1, fx = weights(width, bw, mesh.shape[1])
    mesh = mesh.astype(np.float32)
    rows = mesh[:, x0] * (1 - fx) + mesh[:, x1] * fx  # (cells down, width)
    out = rows[y0] * (1 - fy)[:, None]
    out += rows[y1] * fy[:, None]
    return np.ascontiguousarray(out)


def fine_background(data: np.ndarray, mask: np.ndarray | None, sources: np.ndarray) -> Background:
    """The background left in background-subtracted ``data`` at the scale of
    ``FINE_MESH_PX``, with ``sources`` (True on the pixels of compact sources: stars) and
    ``mask`` left out: a tree line, the edge of a cloud, a roof, which the coarse mesh
    smooths over, so that the stars beside them are not merged into their residual.
    Estimated on every ``step``-th pixel (about 384 px a side)."""
    height, width = data.shape
    step = max(1, min(height, width) // FINE_SAMPLE_PX)
    from scipy import ndimage

    keep_out = sources if mask is None else sources | mask
    sample = np.ascontiguousarray(data[::step, ::step])
    out = ndimage.binary_dilation(keep_out[::step, ::step], iterations=max(1, 3 // step))
    cell = max(6, FINE_MESH_PX // step)
    bh, bw = min(cell, sample.shape[0]), min(cell, sample.shape[1])
    return Background(step, *mesh_maps(sample, out, bh, bw))


def subtract_background(data: np.ndarray, background: Background) -> None:
    """data -= background level map, in place, each sample covering a step x step block."""
    subtract_map(data, background.level_map, background.step)


def subtract_map(data: np.ndarray, back: np.ndarray, step: int) -> None:
    """data -= back, each sample of the map ``back`` covering a step x step block."""
    height, width = data.shape
    if (
        step > 1
        and height % step == 0
        and width % step == 0
        and back.shape == (height // step, width // step)
    ):  # the map widened to full rows only, then one broadcast over each block of rows
        wide = np.repeat(back, step, axis=1)
        data.reshape(height // step, step, width)[...] -= wide[:, None, :]
        return
    data -= _full(back, step, (height, width))


def noise_correlation(data: np.ndarray, mask: np.ndarray | None) -> float:
    """How much smoother than white noise the sky's noise is: the lower quartile (tiles
    with a cloud's or a tree's edge have more), over up to ``CORRELATION_TILES`` tiles of
    32 x 32 px spread over background-subtracted ``data``, of the pixel rms over the rms
    that differences of adjacent pixels give (1 for the white noise of a raw frame; ~1.2-1.5
    for a JPEG, whose compression smooths the noise), clipped to 1..2. Both rms are clipped
    at 4 sigmas (stars; 8-bit skies are too quantised for medians)."""
    height, width = data.shape
    rows, cols = height // _TILE_PX, width // _TILE_PX
    if rows * cols < _MIN_TILES:
        return 1.0
    every = max(1, math.ceil(math.sqrt(rows * cols / CORRELATION_TILES)))
    tiles = (
        data[: rows * _TILE_PX, : cols * _TILE_PX]
        .reshape(rows, _TILE_PX, cols, _TILE_PX)[::every, :, ::every, :]
        .transpose(0, 2, 1, 3)
        .reshape(-1, _TILE_PX, _TILE_PX)
        .astype(np.float64)
    )
    if mask is not None:
        hidden = (
            mask[: rows * _TILE_PX, : cols * _TILE_PX]
            .reshape(rows, _TILE_PX, cols, _TILE_PX)[::every, :, ::every, :]
            .transpose(0, 2, 1, 3)
            .reshape(len(tiles), -1)
            .any(axis=1)
        )
        tiles = tiles[~hidden]
    spread = _clipped_std(tiles.reshape(len(tiles), -1))
    step_spread = _clipped_std(np.diff(tiles, axis=2).reshape(len(tiles), -1)) / math.sqrt(2.0)
    good = (spread > 0) & (step_spread > 0)  # a quantised, flat tile tells nothing
    if not good.any():
        return 1.0
    return float(np.clip(np.percentile(spread[good] / step_spread[good], 25), 1.0, 2.0))


def _clipped_std(values: np.ndarray) -> np.ndarray:
    """Per row: the standard deviation of the values within 4 of it (clipped twice)."""
    centre = np.median(values, axis=1)[:, None]
    spread = values.std(axis=1)[:, None]
    for _ in range(2):
        kept = np.abs(values - centre) <= 4.0 * spread
        n = np.maximum(kept.sum(axis=1, keepdims=True), 1)
        centre = np.where(kept, values, 0.0).sum(axis=1, keepdims=True) / n
        spread = np.sqrt(np.where(kept, (values - centre) ** 2, 0.0).sum(axis=1, keepdims=True) / n)
    return spread[:, 0]


def _full(sampled: np.ndarray, step: int, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    if step == 1:
        return np.ascontiguousarray(sampled[:height, :width], dtype=np.float32)
    full = np.repeat(np.repeat(sampled, step, axis=0), step, axis=1)[:height, :width]
    return np.ascontiguousarray(full, dtype=np.float32)
