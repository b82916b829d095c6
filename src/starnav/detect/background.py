"""The sky background of an image and its pixel noise, as maps: sep's mesh.

sep (Source Extractor's background) splits the image into cells, takes a sigma-clipped mode
of each, median-filters the mesh (3 x 3 cells) and interpolates it with splines; the rms of
each cell makes a noise map the same way. The mesh is 64 px; it is estimated on every
``step``-th pixel so that about 256 px a side are used (the map is smooth and the rms per
pixel is unchanged; 8x faster at 1024 px). A 64 px mesh follows moonlight and horizon
glow, not a tree line or a roof edge: the residual there is left to the per-star local
background (``starnav.detect.photometry``), and the noise map, which rises over textured
foreground (foliage, lit walls), raises the detection threshold there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sep

MESH_PX = 64
SAMPLE_PX = 256  # the background is estimated on about this many px a side


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
    pixels to leave out."""
    height, width = data.shape
    step = max(1, min(height, width) // SAMPLE_PX)
    sample = data if step == 1 else np.ascontiguousarray(data[::step, ::step])
    sample_mask = None
    if mask is not None:
        sample_mask = mask if step == 1 else np.ascontiguousarray(mask[::step, ::step])
    cell = max(8, MESH_PX // step)
    bh, bw = min(cell, sample.shape[0]), min(cell, sample.shape[1])
    bkg = sep.Background(sample, mask=sample_mask, bw=bw, bh=bh, fw=3, fh=3)
    return Background(step, bkg.back(), bkg.rms(), float(bkg.globalback), float(bkg.globalrms))


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


def _full(sampled: np.ndarray, step: int, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    if step == 1:
        return np.ascontiguousarray(sampled[:height, :width], dtype=np.float32)
    full = np.repeat(np.repeat(sampled, step, axis=0), step, axis=1)[:height, :width]
    return np.ascontiguousarray(full, dtype=np.float32)
