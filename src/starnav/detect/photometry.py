"""Each source measured against its own surroundings: local background, noise, flux, shape.

Around each centroid, three zones scaled by the PSF sigma s (clipped to 0.5..8 px): the
aperture r < max(2, 3 s) (99 % of a Gaussian star), the ring up to max(4, 5 s), the annulus
up to max(7, 8 s). The annulus gives the local background (a plane fitted to it, plus the median of
what is left: a gradient of glow or moonlight is followed) and noise (median absolute
deviation x 1.4826): a star on a tree line, a roof edge or in foliage gets the noise of its
surroundings, a glow patch its own level. The aperture flux is counted above
that local background, so a patch wider than the aperture has none.

A source is *extended* when the ring's median lies above a quarter of the aperture's mean
excess, more than noise explains (3 sigmas of a median of the ring's pixels): a Gaussian star
puts 1 % there, a blob twice as wide as the PSF 25 %, a patch of glow or a lit wall about
100 %; a neighbouring star covers too few of the ring's pixels to move its median. A source
is *misshapen* when sep's isophotal axes have a > 2.5 b and a > 2 s (a trail, a lit edge; a
faint star's few pixels can be 3:1 but are short; not when most well-detected sources are,
as in a trailed frame), or when it is faint and b > 4 s (a star's second moments are about s
unless a bright halo widens them; a patch of glow wider than the annulus has no light in the
ring above its annulus, but it is wide). A source is *in the foreground* when its annulus,
after its plane is taken out, varies much more than its pixel-to-pixel noise explains
(``LocalPhotometry.in_foreground``): noise changes from one pixel to the next, foliage, a lit
wall, an edge or a trail across the annulus do not.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, fields

import numpy as np

from starnav.detect.background import nanmedian_last

_MAD_TO_SIGMA = 1.4826
_MEDIAN_NOISE = 1.25  # standard error of a median / that of a mean, Gaussian noise
_RING_FRACTION = 0.25
_RING_SIGMAS = 3.0
_ELONGATION = 2.5
_ELONGATED_LENGTH_SIGMAS = 2.0
_CLIP_SIGMAS = 3.0
_ROUGH_MIN, _ROUGH_OVER_SKY = 1.6, 1.4
_WINGS = 0.05
_LARGE_SIGMAS = 4.0
_FLAT_TOP = 0.05
_STRONG_PEAK = 20.0
_TRAILED_MIN = 5
_MAX_STAMP_VALUES = 2_000_000  # sources are measured in chunks of at most this many pixels
_MAX_PSF_SIGMA = 8.0  # px: the zones of a PSF wider than this are those of 8 px
_MAX_OWN_SIZE = 32.0  # px: a source's own zones (``own_scale_photometry``) up to this size


@dataclass(frozen=True, eq=False)
class LocalPhotometry:
    """Per source: ``flux`` in the aperture above the local background (image units),
    ``background`` (annulus median, over the background map already subtracted),
    ``noise`` (annulus pixel rms about a plane fitted to it: noise and structure, NaN when
    the annulus is masked or off the image), ``white_noise`` (the same from differences of
    adjacent pixels: noise only, as noise changes from pixel to pixel and structure does not),
    ``ring`` (ring median above the local background), ``n_aperture`` and ``n_ring``
    (pixels counted), ``peak`` (brightest aperture pixel above the local background),

    ``radius_px`` (the aperture radius)."""

    flux: np.ndarray
    background: np.ndarray
    noise: np.ndarray
    white_noise: np.ndarray
    ring: np.ndarray
    n_aperture: np.ndarray
    n_ring: np.ndarray
    peak: np.ndarray
    radius_px: float

    def extended(self, noise: np.ndarray) -> np.ndarray:
        """True for sources with more light in the ring than a star, given the pixel
        ``noise`` to judge by, and a ring of more than 5 % of their peak (a bright star's
        halo, in a long exposure or a processed photograph, fills the ring too, under a
        far higher peak)."""
        mean_excess = self.flux / np.maximum(self.n_aperture, 1)
        allowed = _RING_FRACTION * mean_excess + _RING_SIGMAS * _MEDIAN_NOISE * noise / np.sqrt(
            np.maximum(self.n_ring, 1)
        )
        # a flat top: a star's ring is a small fraction of its peak, halo or not
        return (self.ring > allowed) & (self.ring > _FLAT_TOP * self.peak)

    def in_foreground(self, noise_correlation: float = 1.0) -> np.ndarray:
        """True for sources whose surroundings are not sky: an annulus whose rms about its
        plane exceeds its pixel-to-pixel noise by more than 1.4 times what the image's sky
        does (``noise_correlation``: 1 for white noise), and by at least 1.6 (foliage, a
        lit wall, an edge or a trail across it: structure, not noise), and by more than 5 %
        of the source's peak (a bright star's own wings shape its annulus a little)."""
        rough = max(_ROUGH_MIN, _ROUGH_OVER_SKY * noise_correlation)
        white = np.nan_to_num(self.white_noise, nan=np.inf)
        return (self.noise > rough * white) & (self.noise > _WINGS * np.abs(self.peak))


def zones(sigma_px: float, max_sigma_px: float = _MAX_PSF_SIGMA) -> tuple[float, float, float]:
    """(aperture radius, ring outer radius, annulus outer radius), px, for PSF sigma
    (clipped to 0.5..``max_sigma_px``)."""
    s = min(max(sigma_px, 0.5), max_sigma_px)
    return max(2.0, 3.0 * s), max(4.0, 5.0 * s), max(7.0, 8.0 * s)


def local_photometry(
    data: np.ndarray,
    mask: np.ndarray | None,
    x: np.ndarray,
    y: np.ndarray,
    sigma_px: float,
    max_sigma_px: float = _MAX_PSF_SIGMA,
) -> LocalPhotometry:
    """Local photometry of the sources at (``x``, ``y``) (sep's convention: pixel centres at
    integers) in background-subtracted ``data``, ``mask`` True for pixels to leave out, in
    the zones of PSF sigma ``sigma_px`` (``zones``)."""
    r_ap, r_in, r_out = zones(sigma_px, max_sigma_px)
    if len(x) == 0:
        return LocalPhotometry(*([np.zeros(0)] * 8), radius_px=r_ap)
    half = math.ceil(r_out)
    chunk = max(1, _MAX_STAMP_VALUES // (2 * half + 1) ** 2)
    parts = [
        _measure(data, mask, x[i : i + chunk], y[i : i + chunk], half, (r_ap, r_in, r_out))
        for i in range(0, len(x), chunk)
    ]
    return LocalPhotometry(*(np.concatenate(c) for c in zip(*parts, strict=True)), radius_px=r_ap)


def own_scale_photometry(
    data: np.ndarray, mask: np.ndarray | None, x: np.ndarray, y: np.ndarray, size_px: np.ndarray
) -> LocalPhotometry:
    """``local_photometry`` of each source in zones scaled to its own size ``size_px`` (px,
    sep's isophotal sqrt(a b); up to 32 px) instead of the PSF's: the disc and halo of a
    bright star in a long exposure or a stretched photograph, which the PSF's zones cut (its
    ring is lit: "extended"; its annulus slopes: "foreground"), measured whole. Sizes are
    rounded up to powers of sqrt 2, so that sources of about one size share their stamps;
    ``radius_px`` is the largest aperture's."""
    scale = np.clip(np.asarray(size_px, dtype=float), 0.5, _MAX_OWN_SIZE)
    scale = np.minimum(2.0 ** (np.ceil(2.0 * np.log2(scale)) / 2.0), _MAX_OWN_SIZE)
    names = [f.name for f in fields(LocalPhotometry) if f.name != "radius_px"]
    columns = {name: np.zeros(len(x)) for name in names}
    for s in np.unique(scale):
        group = np.flatnonzero(scale == s)
        part = local_photometry(data, mask, x[group], y[group], float(s), _MAX_OWN_SIZE)
        for name in names:
            columns[name][group] = getattr(part, name)
    radius = zones(float(scale.max()), _MAX_OWN_SIZE)[0] if len(x) else 0.0
    return LocalPhotometry(**columns, radius_px=radius)


def elongated(objects: np.ndarray, sigma_px: float, peak_snr: np.ndarray) -> np.ndarray:
    """True for sep sources much longer than wide and longer than a star (a trail, a lit
    edge), unless most well-detected sources (peak over 20 noise sigmas, ``peak_snr``) are,
    as in a frame trailed by the camera's motion."""
    a, b = objects["a"], objects["b"]
    long = (a > _ELONGATION * b) & (a > _ELONGATED_LENGTH_SIGMAS * max(sigma_px, 0.5))
    strong = peak_snr >= _STRONG_PEAK
    if strong.sum() >= _TRAILED_MIN and long[strong].mean() > 0.5:
        return np.zeros_like(long)
    return long


def misshapen(objects: np.ndarray, sigma_px: float, peak_snr: np.ndarray) -> np.ndarray:
    """True for ``elongated`` sources, or faint ones (peak below 20 noise sigmas,
    ``peak_snr``) whose light spreads far wider than the PSF (a glow patch larger than the
    annulus, which the ring test cannot see; a bright star's halo is wide too)."""
    large = objects["b"] > _LARGE_SIGMAS * max(sigma_px, 0.5)
    return elongated(objects, sigma_px, peak_snr) | (large & (peak_snr < _STRONG_PEAK))


def _measure(data, mask, x, y, half, radii):
    r_ap, r_in, r_out = radii
    stamp, inside, dx, dy = _stamps(data, mask, x, y, half)
    n = len(x)
    r2 = dx**2 + dy**2
    annulus = inside & (r2 >= r_in**2) & (r2 < r_out**2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an annulus wholly masked: NaN
        local = _plane(stamp, annulus, dx, dy)
        # once more without the pixels far off the first plane (a neighbouring star)
        rest = np.where(annulus, stamp - local, np.nan).reshape(n, -1)
        centre = nanmedian_last(rest)[:, None]
        spread = _MAD_TO_SIGMA * nanmedian_last(np.abs(rest - centre))[:, None]
        near = (np.abs(rest - centre) <= _CLIP_SIGMAS * spread).reshape(stamp.shape)
        local = _plane(stamp, annulus & near, dx, dy)
        c0 = local[:, half, half]
        rest = np.where(annulus, stamp - local, np.nan).reshape(n, -1)
        offset = np.nan_to_num(nanmedian_last(rest), nan=0.0)
        noise = _MAD_TO_SIGMA * nanmedian_last(np.abs(rest - offset[:, None]))
        pairs = annulus[:, :, 1:] & annulus[:, :, :-1]
        step = np.where(pairs, stamp[:, :, 1:] - stamp[:, :, :-1], np.nan).reshape(n, -1)
        white = _quantised_sigma(step) / math.sqrt(2)
        excess = stamp - local - offset[:, None, None]
        ring_zone = inside & (r2 >= r_ap**2) & (r2 < r_in**2)
        ring = nanmedian_last(np.where(ring_zone, excess, np.nan).reshape(n, -1))
    aperture = inside & (r2 < r_ap**2)
    flux = np.where(aperture, excess, 0.0).sum(axis=(1, 2))
    peak = np.where(aperture, excess, -np.inf).max(axis=(1, 2), initial=-np.inf)
    return (
        flux,
        c0 + offset,
        noise,
        white,
        np.nan_to_num(ring, nan=0.0),
        aperture.sum(axis=(1, 2)),
        ring_zone.sum(axis=(1, 2)),
        np.where(np.isfinite(peak), peak, 0.0),
    )


def _quantised_sigma(values: np.ndarray) -> np.ndarray:
    """Per row of ``values`` (NaN: none): the rms of a Gaussian from the mean absolute
    deviation about the median (x sqrt(pi / 2)), of the values within 3 sigmas of the
    median absolute deviation. Differences of 8-bit pixels are whole numbers, and so is
    their median absolute deviation: at a sky rms of 1.2-1.6 levels it reads 1.05 or 2.1
    (35 % off, which made clean stars of an 8-bit sky look rough around, "in foreground");
    the mean of the deviations is not quantised (within 3 % from rms 0.8 up)."""
    deviation = np.abs(values - nanmedian_last(values)[:, None])
    scale = _MAD_TO_SIGMA * nanmedian_last(deviation)[:, None]
    kept = deviation <= _CLIP_SIGMAS * scale  # NaN: not kept
    count = kept.sum(axis=1)
    mean = np.where(kept, deviation, 0.0).sum(axis=1) / np.maximum(count, 1)
    return np.where(count > 0, math.sqrt(math.pi / 2.0) * mean, np.nan)


def _stamps(data, mask, x, y, half):
    """(n, k, k) pixel stamps around the sources, whether each pixel is on the image and
    unmasked, and the pixel centres' offsets from the source, dx (n, 1, k) and dy (n, k, 1)."""
    height, width = data.shape
    off = np.arange(-half, half + 1)
    cols = np.rint(x).astype(np.intp)[:, None] + off
    rows = np.rint(y).astype(np.intp)[:, None] + off
    inside = ((rows >= 0) & (rows < height))[:, :, None] & ((cols >= 0) & (cols < width))[
        :, None, :
    ]
    rr = np.clip(rows, 0, height - 1)[:, :, None]
    cc = np.clip(cols, 0, width - 1)[:, None, :]
    if mask is not None:
        inside &= ~mask[rr, cc]
    dx = (cols - x[:, None])[:, None, :]
    dy = (rows - y[:, None])[:, :, None]
    return data[rr, cc], inside, dx, dy


def _plane(stamp, zone, dx, dy):
    """The plane c0 + cx dx + cy dy through each stamp's ``zone`` pixels, fitted as if the
    zone were symmetric about the source (an annulus: the offsets are then uncorrelated, so
    each coefficient is a ratio of sums; a zone cut by the image edge is fitted a little
    less well), evaluated on the stamp."""
    w = zone.astype(float)
    count = np.maximum(w.sum(axis=(1, 2)), 1.0)
    gx, gy = np.broadcast_to(dx, zone.shape), np.broadcast_to(dy, zone.shape)
    mx = (w * gx).sum(axis=(1, 2)) / count
    my = (w * gy).sum(axis=(1, 2)) / count
    v = np.where(zone, stamp, 0.0)
    c0 = v.sum(axis=(1, 2)) / count
    ux, uy = gx - mx[:, None, None], gy - my[:, None, None]
    sx = np.maximum((w * ux * ux).sum(axis=(1, 2)), 1e-9)
    sy = np.maximum((w * uy * uy).sum(axis=(1, 2)), 1e-9)
    cx = (v * ux).sum(axis=(1, 2)) / sx
    cy = (v * uy).sum(axis=(1, 2)) / sy
    c0 = c0 - cx * mx - cy * my
    return c0[:, None, None] + cx[:, None, None] * dx + cy[:, None, None] * dy
