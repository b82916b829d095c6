"""Each source measured against its own surroundings: local background, noise, flux, shape.

Around each centroid, three zones scaled by the PSF sigma s (clipped to 0.5..8 px): the
aperture r < max(2, 3 s) (99 % of a Gaussian star), the ring up to max(4, 5 s), the annulus
up to max(7, 8 s). The annulus gives the local background (median) and noise (median
absolute deviation x 1.4826): a star on a tree line, a roof edge or in foliage gets the
noise of its surroundings, a glow patch its own level. The aperture flux is counted above
that local background, so a patch wider than the aperture has none.

A source is *extended* when the ring's median lies above a quarter of the aperture's mean
excess, more than noise explains (3 sigmas of a median of the ring's pixels): a Gaussian star
puts 1 % there, a blob twice as wide as the PSF 25 %, a patch of glow or a lit wall about
100 %; a neighbouring star covers too few of the ring's pixels to move its median. A source
is *elongated* when sep's isophotal axes have a > 2.5 b and a > 2 s (a trail, a lit edge; a
faint star's few pixels can be 3:1 but are short).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

_MAD_TO_SIGMA = 1.4826
_MEDIAN_NOISE = 1.25  # standard error of a median / that of a mean, Gaussian noise
_RING_FRACTION = 0.25
_RING_SIGMAS = 3.0
_ELONGATION = 2.5
_ELONGATED_LENGTH_SIGMAS = 2.0
_MAX_STAMP_VALUES = 2_000_000  # sources are measured in chunks of at most this many pixels


@dataclass(frozen=True, eq=False)
class LocalPhotometry:
    """Per source: ``flux`` in the aperture above the local background (image units),
    ``background`` (annulus median, over the background map already subtracted),
    ``noise`` (annulus pixel rms, NaN when the annulus is masked or off the image),
    ``ring`` (ring median above the local background), ``n_aperture`` and ``n_ring``
    (pixels counted), ``radius_px`` (the aperture radius)."""

    flux: np.ndarray
    background: np.ndarray
    noise: np.ndarray
    ring: np.ndarray
    n_aperture: np.ndarray
    n_ring: np.ndarray
    radius_px: float

    def extended(self, noise: np.ndarray) -> np.ndarray:
        """True for sources with more light in the ring than a star, given the pixel
        ``noise`` to judge by."""
        mean_excess = self.flux / np.maximum(self.n_aperture, 1)
        allowed = _RING_FRACTION * mean_excess + _RING_SIGMAS * _MEDIAN_NOISE * noise / np.sqrt(
            np.maximum(self.n_ring, 1)
        )
        return self.ring > allowed


def zones(sigma_px: float) -> tuple[float, float, float]:
    """(aperture radius, ring outer radius, annulus outer radius), px, for PSF sigma."""
    s = min(max(sigma_px, 0.5), 8.0)
    return max(2.0, 3.0 * s), max(4.0, 5.0 * s), max(7.0, 8.0 * s)


def local_photometry(
    data: np.ndarray, mask: np.ndarray | None, x: np.ndarray, y: np.ndarray, sigma_px: float
) -> LocalPhotometry:
    """Local photometry of the sources at (``x``, ``y``) (sep's convention: pixel centres at
    integers) in background-subtracted ``data``, ``mask`` True for pixels to leave out."""
    r_ap, r_in, r_out = zones(sigma_px)
    if len(x) == 0:
        return LocalPhotometry(*([np.zeros(0)] * 6), radius_px=r_ap)
    half = math.ceil(r_out)
    chunk = max(1, _MAX_STAMP_VALUES // (2 * half + 1) ** 2)
    parts = [
        _measure(data, mask, x[i : i + chunk], y[i : i + chunk], half, (r_ap, r_in, r_out))
        for i in range(0, len(x), chunk)
    ]
    return LocalPhotometry(*(np.concatenate(c) for c in zip(*parts, strict=True)), radius_px=r_ap)


def elongated(objects: np.ndarray, sigma_px: float) -> np.ndarray:
    """True for sep sources much longer than wide and longer than a star."""
    a, b = objects["a"], objects["b"]
    s = max(sigma_px, 0.5)
    return (a > _ELONGATION * b) & (a > _ELONGATED_LENGTH_SIGMAS * s)


def _measure(data, mask, x, y, half, radii):
    r_ap, r_in, r_out = radii
    height, width = data.shape
    off = np.arange(-half, half + 1)
    cols = np.rint(x).astype(np.intp)[:, None] + off
    rows = np.rint(y).astype(np.intp)[:, None] + off
    inside = ((rows >= 0) & (rows < height))[:, :, None] & ((cols >= 0) & (cols < width))[
        :, None, :
    ]
    rr = np.clip(rows, 0, height - 1)[:, :, None]
    cc = np.clip(cols, 0, width - 1)[:, None, :]
    stamp = data[rr, cc]
    if mask is not None:
        inside &= ~mask[rr, cc]
    r2 = ((rows - y[:, None]) ** 2)[:, :, None] + ((cols - x[:, None]) ** 2)[:, None, :]
    n = len(x)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an annulus wholly masked: NaN
        annulus = np.where(inside & (r2 >= r_in**2) & (r2 < r_out**2), stamp, np.nan)
        annulus = annulus.reshape(n, -1)
        background = np.nanmedian(annulus, axis=1)
        noise = _MAD_TO_SIGMA * np.nanmedian(np.abs(annulus - background[:, None]), axis=1)
        background = np.nan_to_num(background, nan=0.0)
        ring_zone = inside & (r2 >= r_ap**2) & (r2 < r_in**2)
        ring = np.nanmedian(np.where(ring_zone, stamp, np.nan).reshape(n, -1), axis=1)
    aperture = inside & (r2 < r_ap**2)
    excess = stamp - background[:, None, None]
    flux = np.where(aperture, excess, 0.0).sum(axis=(1, 2))
    ring = np.nan_to_num(ring - background, nan=0.0)
    return (
        flux,
        background,
        noise,
        ring,
        aperture.sum(axis=(1, 2)),
        ring_zone.sum(axis=(1, 2)),
    )
