"""A clean star-tracker frame's sources in one pass of kernels (``starnav.detect.kernels``),
for the fast path that ``starnav.detect.stars.detect_stars`` takes when a frame shows no
need of its real-sky detection.

The frame is judged on what the fast path computes anyway, and every test is conservative:
any doubt sends the frame to the real-sky detection, unchanged. Clean is:

1. its pixels all finite, its sky not clipped at the black level (``_CLIPPED_FRACTION`` of
   the samples at the image's minimum), at least 2 x 2 tiles of 64 px;
2. white noise: on 64 px tiles (every other pixel of every 8th row: 256 pixels) the rms
   of the pixels within 1.1 times that of differences of adjacent pixels (median over every
   other tile each way; a JPEG's smoothing makes it 1.2-1.5);
3. a smooth sky: each tile's level within 2 pixel rms of the median of its 3 x 3 tiles (a
   linear ramp has none, the dark corners of a vignetted tetra3 frame up to 1.7; a tree
   line, a roof or a cloud's edge jump by 4-6 and more), the tile rms up to x1.5 their
   median (foliage and lit walls are rougher) and down to / 2 (a vignetted corner's photon
   noise); a noise map within 25 % of uniform has one threshold, else the tiles' noise,
   interpolated as the background is, sets it;
4. enough sure stars: at least 30 sources peaking over 10 noise sigmas (a seed-1024 render
   has 50-180; a sparse or short exposure fewer, and its solve leans on faint stars near the
   threshold, where the two paths' noise estimates, within a few per cent, decide which are
   found: the real-sky path is the reference there);
5. compact sources: no group of more than 1500 filtered pixels above the threshold (glow, a
   nebula; the real-sky path fits a finer mesh then), none of the bright ones (peak over 20
   noise sigmas) misshapen (a trail, an edge: ``starnav.detect.photometry.misshapen``), at
   most ``_MAX_SATURATED`` saturated, and a PSF sigma up to 2.5 px (the real-sky path finds
   wider stars again with their own Gaussian).

The sources themselves are found as sep finds them there (its 3 x 3 kernel, the threshold in
the filtered noise, deblending at 16 levels with contrast 0.005), on a background that is the
tile levels interpolated bilinearly; hot pixels are removed first (``starnav.detect.hot``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.detect.hot import clean_hot_pixels
from starnav.detect.photometry import misshapen, zones
from starnav.detect.psf import DEFAULT_SIGMA_PX, psf_samples, psf_sigma_from

TILE_PX = 64
ROW_STRIDE = 8  # the tiles are sampled on every other pixel of every 8th row
FILTER_NOISE = 0.375  # noise of sep's 3 x 3 kernel's output / pixel noise: sqrt(36) / 16
_CLIPPED_FRACTION = 0.1
_WHITE_RATIO = 1.1
_STEP_RMS = 2.0  # a tile's level off its neighbours' median, in pixel rms
_RMS_ABOVE, _RMS_BELOW = 1.5, 2.0  # the tiles' rms within median x 1.5 .. median / 2
_UNIFORM_NOISE = 1.25
_PLATEAU_PX = 1500
_BRIGHT_PEAK_SNR = 20.0
_MAX_SATURATED = 20
_SURE_STARS, _SURE_PEAK_SNR = 30, 10.0
_WIDEST_PSF_PX = 2.5
_CAPACITY_FRACTION = 0.02  # of the pixels above the threshold at most: more is no clean sky

SOURCE_DTYPE = np.dtype(
    [
        ("x", "f8"),
        ("y", "f8"),
        ("x2", "f8"),
        ("y2", "f8"),
        ("xy", "f8"),
        ("a", "f8"),
        ("b", "f8"),
        ("npix", "i8"),
        ("flux", "f8"),
        ("peak", "f8"),
        ("xpeak", "i8"),
        ("ypeak", "i8"),
    ]
)


@dataclass(frozen=True, eq=False)
class TrackerSources:
    """A clean frame's sources: ``objects`` (``SOURCE_DTYPE``, sep's fields and pixel
    convention: centres at integers), ``data`` (the image less its background, float32,
    hot pixels removed), the background ``level`` and pixel ``rms`` (image units), the PSF
    sigma ``psf_sigma_px``, ``n_hot`` hot pixels removed, and whether each source's peak
    pixel reaches the saturation level (``saturated``)."""

    objects: np.ndarray
    saturated: np.ndarray
    data: np.ndarray
    level: float
    rms: float
    psf_sigma_px: float
    n_hot: int


def tracker_sources(
    data: np.ndarray,
    low: float,
    threshold_sigma: float,
    min_area_px: int,
    saturation: float | None,
    reject_hot_pixels: bool,
    residual: np.ndarray | None = None,
) -> TrackerSources | None:
    """The sources of ``data`` (float32, every pixel finite, ``low`` its minimum; left
    unchanged) when the frame is clean (the module's tests), else None: ``threshold_sigma``
    in the noise of sep's 3 x 3 filtered image, ``min_area_px`` filtered pixels,
    ``saturation`` the sensor's saturation level (None: none). ``residual``: the array
    (float32, the shape of ``data``) the image less its background is written to, which
    becomes ``TrackerSources.data`` (None: a new one)."""
    from starnav.detect import kernels

    height, width = data.shape
    if height < 2 * TILE_PX or width < 2 * TILE_PX:
        return None
    level, rms, white, at_low = kernels.tile_statistics(data, TILE_PX, ROW_STRIDE, np.float32(low))
    samples = data.size / (2 * ROW_STRIDE)
    if at_low >= _CLIPPED_FRACTION * samples:
        return None
    # both median-filtered over 3 x 3 tiles, as the real-sky mesh
    smooth_level = kernels.median_3x3(level)
    if not _smooth_white_sky(level, smooth_level, rms, white):
        return None
    level, rms = smooth_level, kernels.median_3x3(rms)
    sky, noise = float(np.median(level)), float(np.median(rms))
    # in float32, as numpy compares the float32 pixels with it
    hot_level = np.float32(threshold_sigma * noise if reject_hot_pixels else np.inf)
    if residual is None:
        residual = np.empty(data.shape, dtype=np.float32)
    above = kernels.background_subtracted(data, level, TILE_PX, hot_level, residual)
    # one threshold on a noise within 25 % of uniform, as the real-sky path; else a map
    uniform = rms.max() <= _UNIFORM_NOISE * rms.min()
    threshold = threshold_sigma * FILTER_NOISE * (np.full_like(rms, noise) if uniform else rms)
    n_hot = clean_hot_pixels(residual, hot_level, above) if reject_hot_pixels else 0
    capacity = max(10_000, int(_CAPACITY_FRACTION * data.size))
    status, npix, flux, moments, peaks = kernels.find_sources(
        residual, threshold, TILE_PX, min_area_px, capacity, _PLATEAU_PX
    )
    if status != kernels.FOUND:
        return None
    objects = _objects(npix, flux, moments, peaks)
    if np.count_nonzero(objects["peak"] >= _SURE_PEAK_SNR * noise) < _SURE_STARS:
        return None
    saturated = np.zeros(len(objects), dtype=bool)
    if saturation is not None:
        saturated = data[objects["ypeak"], objects["xpeak"]] >= np.float32(saturation)
        if saturated.sum() > _MAX_SATURATED:
            return None
    unsaturated = objects[~saturated]
    peak_snr = unsaturated["peak"] / noise
    pick = psf_samples(unsaturated, peak_snr)
    if len(pick) >= 3:
        sigma = psf_sigma_from(residual, unsaturated[pick], None)
    else:
        sigma = DEFAULT_SIGMA_PX
    if sigma > _WIDEST_PSF_PX or _misshapen_bright(objects, sigma, noise):
        return None
    return TrackerSources(objects, saturated, residual, sky, noise, sigma, n_hot)


def _smooth_white_sky(
    level: np.ndarray, around: np.ndarray, rms: np.ndarray, white: np.ndarray
) -> bool:
    """Tests 2 and 3 of the module on the tiles' levels, their medians over 3 x 3 tiles
    (``around``) and rms."""
    measured = np.isfinite(white)
    if not (np.all(rms > 0) and np.all(white[measured] > 0)):
        return False  # a flat or quantised-away sky: the real-sky path has its floors
    if np.median(rms[measured] / white[measured]) > _WHITE_RATIO:
        return False
    typical = np.median(rms)
    if rms.max() > _RMS_ABOVE * typical or rms.min() < typical / _RMS_BELOW:
        return False
    return bool(np.all(np.abs(level - around) <= _STEP_RMS * rms))


def _misshapen_bright(objects: np.ndarray, sigma: float, noise: float) -> bool:
    """Whether a bright source (peak over ``_BRIGHT_PEAK_SNR`` noise sigmas) is misshapen."""
    peak_snr = objects["peak"] / noise
    bright = peak_snr >= _BRIGHT_PEAK_SNR
    return bool(np.any(misshapen(objects, sigma, peak_snr) & bright))


def _objects(
    npix: np.ndarray, flux: np.ndarray, moments: np.ndarray, peaks: np.ndarray
) -> np.ndarray:
    """The kernel's sources as a record array of ``SOURCE_DTYPE``: sep's isophotal axes
    a, b from the second moments (with its guard against a source one pixel wide)."""
    objects = np.zeros(len(npix), dtype=SOURCE_DTYPE)
    objects["npix"], objects["flux"] = npix, flux
    for k, name in enumerate(("x", "y", "x2", "y2", "xy")):
        objects[name] = moments[:, k]
    # a faint source's negative pixels can make its variance negative: none, then
    objects["x2"], objects["y2"] = np.maximum(objects["x2"], 0.0), np.maximum(objects["y2"], 0.0)
    objects["peak"] = peaks[:, 0]
    objects["xpeak"], objects["ypeak"] = peaks[:, 1], peaks[:, 2]
    x2, y2, xy = objects["x2"].copy(), objects["y2"].copy(), objects["xy"]
    thin = x2 * y2 - xy * xy < 0.00694  # sep: a source on one row or column
    x2[thin] += 0.0833333
    y2[thin] += 0.0833333
    mean, half = 0.5 * (x2 + y2), np.sqrt(0.25 * (x2 - y2) ** 2 + xy * xy)
    objects["a"] = np.sqrt(np.maximum(mean + half, 0.0))
    objects["b"] = np.sqrt(np.maximum(mean - half, 0.0))
    return objects


def local_flux(
    sources: TrackerSources, x: np.ndarray, y: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """(flux above the local background (image units), the annulus's rms) of the sources at
    (``x``, ``y``, sep's convention) in the zones of PSF sigma ``sigma`` px
    (``starnav.detect.photometry.zones``), as ``local_photometry`` measures them."""
    from starnav.detect import kernels

    r_ap, r_in, r_out = zones(sigma)
    return kernels.annulus_photometry(sources.data, x, y, r_ap, r_in, r_out)
