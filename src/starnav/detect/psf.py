"""The width of the point-spread function, from the compact sources of an image.

Stars share one PSF; foreground (lit branches, a roof edge, holes of sky in a canopy), glow
patches and trails come in every size. So the width is the most common size among round,
unsaturated, well-detected sources not in foreground (``starnav.detect.photometry``), not
the size of the brightest ones (which in a photograph with trees are the lit branches): the
half-light radius of each of up to ``PSF_CANDIDATES`` such sources (sep's ``flux_radius``,
within 3 times its second-moment size), a histogram of log radius in 0.05 dex bins smoothed
over 5 bins, and the median radius within 0.1 dex of its peak; when two peaks are about
equally high (at least 2/3 of the highest), the smaller one, as foreground is never smaller
than the PSF. Converted to a Gaussian sigma (half-light radius = 1.177 sigma). Fewer than 3
sources: 1 px.
"""

from __future__ import annotations

import math

import numpy as np
import sep

from starnav.detect.photometry import local_photometry

PSF_CANDIDATES = 100
DEFAULT_SIGMA_PX = 1.0
_GAUSSIAN_HALF_LIGHT = math.sqrt(2.0 * math.log(2.0))  # half-light radius / sigma (2-D)
_BIN_DEX = 0.05
_WINDOW_DEX = 0.1
_ROUND = 2.0  # a / b above this: a trail, a blend or an edge, not a PSF sample
_PEAK_RATIO = 2.0 / 3.0
_SUBPIX = 5  # samples per pixel side of sep's flux_radius (its default)


def measure_psf_sigma(
    data: np.ndarray,
    objects: np.ndarray,
    mask: np.ndarray | None,
    peak_snr: np.ndarray,
    noise_correlation: float = 1.0,
) -> float:
    """PSF Gaussian sigma (px) of background-subtracted ``data`` from sep's unsaturated
    ``objects``, the ``peak_snr`` (peak over the local noise) of each choosing the best
    detected, those in foreground (``starnav.detect.photometry``; ``noise_correlation`` of
    the sky's noise) left out."""
    pick = psf_samples(objects, peak_snr)
    if len(pick) < 3:
        return DEFAULT_SIGMA_PX
    # not sources in foreground (judged with their second moments as the PSF's size)
    size = float(np.median(np.sqrt(objects["a"][pick] * objects["b"][pick])))
    phot = local_photometry(data, mask, objects["x"][pick], objects["y"][pick], size)
    clean = ~phot.in_foreground(noise_correlation)
    if clean.sum() >= 3:
        pick = pick[clean]
    return psf_sigma_from(data, objects[pick], mask)


def psf_samples(objects: np.ndarray, peak_snr: np.ndarray) -> np.ndarray:
    """Indices of the sources (sep's fields) fit to measure the PSF on: of 5 pixels or more,
    round (a <= 2 b), up to ``PSF_CANDIDATES`` of them by decreasing ``peak_snr``."""
    a, b = objects["a"], objects["b"]
    usable = np.flatnonzero((objects["npix"] >= 5) & (a <= _ROUND * b) & (b > 0))
    return usable[np.argsort(-peak_snr[usable], kind="stable")[:PSF_CANDIDATES]]


def psf_sigma_from(data: np.ndarray, objects: np.ndarray, mask: np.ndarray | None) -> float:
    """PSF Gaussian sigma (px) from the modal half-light radius of ``objects`` (sep's
    fields) in background-subtracted ``data`` (sep's ``flux_radius`` within 3 times each
    one's second-moment size, 3..50 px); ``DEFAULT_SIGMA_PX`` from fewer than 3."""
    size = np.sqrt(objects["x2"] + objects["y2"])
    rmax = np.clip(3.0 * size, 3.0, 50.0)
    x, y = np.ascontiguousarray(objects["x"]), np.ascontiguousarray(objects["y"])
    if mask is None:  # sep.flux_radius's numbers (subpix 5), without its cost per sample
        from starnav.detect import kernels

        r_half = kernels.half_light_radii(data, x, y, rmax, _SUBPIX)
    else:
        r_half, _ = sep.flux_radius(data, x, y, rmax, 0.5, mask=mask, subpix=_SUBPIX)
    r_half = r_half[np.isfinite(r_half) & (r_half > 0)]
    if len(r_half) < 3:
        return DEFAULT_SIGMA_PX
    return float(np.clip(_modal_radius(r_half) / _GAUSSIAN_HALF_LIGHT, 0.3, 20.0))


def _modal_radius(r_half: np.ndarray) -> float:
    """The most common of the radii: the smaller of two about equally common ones."""
    logr = np.log10(r_half)
    edges = np.arange(logr.min() - 3 * _BIN_DEX, logr.max() + 4 * _BIN_DEX, _BIN_DEX)
    counts, _ = np.histogram(logr, edges)
    smooth = np.convolve(counts, np.array([1.0, 2.0, 3.0, 2.0, 1.0]), mode="same")
    # local maxima of the smoothed histogram, the first (smallest radius) that is high enough
    peaks = np.flatnonzero(
        (smooth >= np.roll(smooth, 1)) & (smooth > np.roll(smooth, -1)) & (smooth > 0)
    )
    high = peaks[smooth[peaks] >= _PEAK_RATIO * smooth.max()]
    centre = 0.5 * (edges[high[0]] + edges[high[0] + 1])
    near = np.abs(logr - centre) <= _WINDOW_DEX
    return float(np.median(r_half[near])) if near.any() else float(np.median(r_half))
