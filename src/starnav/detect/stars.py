"""Stars in an image, also a real sky's: background, hot pixels, detection, what is a star,
sub-pixel centroids, ranking.

Why sep: it is Source Extractor as a library, the de-facto astronomical detector, in C:
matched-filter detection, deblending and windowed centroids in a few ms per 1024 px frame
(photutils does the same in Python/numpy, slower, and adds nothing needed here). Around it,
one module per stage:

1. background (``starnav.detect.background``): a 64 px mesh of sigma-clipped medians and
   rms (about a plane per cell), interpolated bilinearly; the sky's noise correlation (1 for
   a raw frame, ~1.2-1.5 for a JPEG) scales the rms to the pixels' own; a sky clipped at the
   black level (10 % of the pixels or more at the lowest value) takes its noise from the
   upper half of its values, which the clipping leaves (``_rms_floor``);
2. hot pixels (``starnav.detect.hot``): a pixel above the threshold whose four neighbours
   average under a tenth of its excess is replaced by that average (every star of PSF
   sigma >= 0.4 px keeps more than that in its neighbours);
3. detection: sep.extract with sep's 3x3 kernel (or the PSF Gaussian when given, or when
   measured wider than 2.5 px), ``threshold_sigma`` counted in the filtered noise of the
   noise map, deblending by sep; where sources of more than 1500 px show that the mesh
   left patches (glow beside a tree line, a cloud's edge), a 24 px mesh is fitted to what
   is left with the compact sources masked, and sources are found again; sep's buffer
   limits, which a dense Milky Way or a nebula fills, are raised for the call, then the
   threshold (``_extract``): never an error;
4. PSF width (``starnav.detect.psf``): the most common half-light radius of round,
   unsaturated sources not in foreground (the brightest are often lit branches);
5. windowed centroids (``sep.winpos``, a Gaussian window of sigma sqrt(psf² + 1 px²): the
   extra pixel keeps an undersampled star unbiased), which reach the Cramér-Rao bound
   sqrt(2) psf_sigma / SNR per axis for psf_sigma >= 0.8 px;
6. what is a star (``starnav.detect.photometry``): each source measured against its own
   annulus (a plane plus a median: local background; the median absolute deviation: local
   noise), flux in an aperture of 3 PSF sigmas above it; dropped when *extended* (its ring
   brighter than a star's), *misshapen* (a trail, an edge: a > 2.5 b; or b > 4 sigma), *in
   foreground* (its annulus rougher than its pixel-to-pixel noise explains: foliage, a lit
   wall, an edge across it) or fainter than half ``threshold_sigma`` against its
   surroundings; a source dropped so whose peak comes near the image's maximum (90 % of the
   way up from the sky) and that is round and wider than 2 PSF sigmas (sep's sqrt(a b)) is
   judged again in zones of its own size (up to 32 px): the brightest stars of a long
   exposure or a stretched photograph are discs with halos, which the PSF's zones cut, and
   a patch of cloud or glow that wide has no core near the top;
7. ranking: saturated stars first, then by ``snr``, the local flux over the image's noise or
   the clearly higher (x 1.25) noise of the surroundings (a star judged whole: its whole
   flux, as if in the PSF): a lit wall, a patch of glow or a branch cannot outrank a star by
   being large or bright. Sources are measured in that order's likely part first: saturated
   ones, then by the better of their ranks in peak over the noise map and in sep's flux.

docs/images.md ("How stars are found in real skies") measures this on real photographs and
says what it still cannot do.

A clean star-tracker frame (finite pixels, white noise, a smooth unclipped sky, compact
sources, the PSF unknown: ``starnav.detect.tracker`` says what is tested) takes a fast path
instead of steps 1-4: its background on 64 px tiles, its sources found as sep finds them, in
numba kernels (``starnav.detect.kernels``); steps 5-7 follow with the same primitives
(windowed centroids, flux above the annulus's plane and median, the same SNR and ranking),
without the tests for foreground and extended sources a clean sky does not need. Any frame it
declines is detected as above, unchanged. docs/images.md ("Detection time") times both.

Limits: stars closer than ~4.5 px (PSF sigma 1) come out as one; a star cut by the image edge
is pulled inwards (up to ~0.6 px when centred on the last pixel); a star whose annulus (8 PSF
sigmas) reaches foreground is judged by it and usually dropped.

Saturated stars are kept and flagged (``saturated``), and sorted first: for a star tracker they
are the brightest, surest catalog stars, and the centroid of a symmetric saturated star stays
within ~0.1 px, well inside identification tolerances; their flux is only a lower bound, hence
first place. ``keep_saturated=False`` drops them (a blooming CCD smears them along columns).

Coordinates: sep puts pixel centres at integer coordinates; ours (docs/conventions.md) put the
top-left pixel's centre at (0.5, 0.5), so 0.5 is added to both.

sep's windowed centroid and half-light radius are computed by kernels with its numbers
(``starnav.detect.kernels``) when no pixel is masked; with a mask, by sep. A float32 image
is not copied until a step writes to it (the real-sky path's); the caller's pixels are left
as they were. The float32 pixels of an image of another type and the fast path's residual
go to arrays the thread keeps from one image to the next (``_frame_buffer``).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, replace

import numpy as np
import sep

from starnav.detect.background import (
    Background,
    estimate_background,
    fine_background,
    noise_correlation,
    subtract_background,
)
from starnav.detect.circle import ImageCircle
from starnav.detect.hot import clean_hot_pixels
from starnav.detect.photometry import (
    LocalPhotometry,
    elongated,
    local_photometry,
    misshapen,
    own_scale_photometry,
)
from starnav.detect.psf import measure_psf_sigma
from starnav.detect.tracker import TrackerSources, local_flux, tracker_sources
from starnav.errors import ImageError, shown

_DEFAULT_KERNEL = np.array([[1.0, 2.0, 1.0], [2.0, 4.0, 2.0], [1.0, 2.0, 1.0]], dtype=np.float32)
_NOISE_FREE_RMS = 1e-3  # rms assumed for a noise-free image, as a fraction of its range
_MAP_RMS_FLOOR = 0.5  # the noise map is kept above this fraction of the global rms
_CLIPPED_FRACTION = 0.1  # of the pixels at the lowest value: a sky clipped at the black level
_ONE_SIGMA_QUANTILE = 0.8413  # of Gaussian noise: its median + 1 rms
_UPPER_WIDTH_SHARE = 0.8  # the rms is kept above this share of that upper half-width
_NOISE_SAMPLE = 250_000  # pixels sampled (a regular grid) for those quantiles
_LOCAL_NOISE_MARGIN = 1.25  # the annulus noise counts when this much above the noise map
_MIN_SNR_FRACTION = 0.5  # of threshold_sigma: a source fainter than that here is dropped
_CROWD = 5  # an all-sky frame's saturated source with this many saturated others
_CROWD_RADIUS = 0.015  # within this share of the image's diagonal is a piece of glare
_TRAIL_PIECES = 5  # sources this many or more in a straight chain are a trail's pieces
_TRAIL_COS = math.cos(math.radians(10.0))  # a source between two neighbours this near in line
_TRAIL_STRAIGHTNESS = 0.15  # of the pieces' spacing: their rms off one straight line
_TRAIL_EVEN = 0.25  # a source's two neighbours in line lie this evenly (of the longer step)
_CANDIDATES_PER_STAR, _CANDIDATES_EXTRA = 4, 30  # most sources measured for max_stars
_FIRST_PER_STAR, _FIRST_EXTRA = 2, 20  # sources measured first
_UNIFORM_NOISE = 1.25
_WIDE_SIGMAS = 2.0  # a source this many PSF sigmas wide (sep's sqrt(a b)) is measured whole
_NEAR_TOP = 0.9  # of the way from the sky level to the image's maximum: a peak near the top
_PLATEAU_PX = 1500  # a source of more filtered pixels is a patch of residual glow
_WIDEST_FOR_DEFAULT_KERNEL = 2.5  # PSF sigma (px) beyond which its own Gaussian is used
# sep's buffers (its defaults: 300 000 pixels above the threshold at once, 1024 sub-objects in
# one source's deblending) are raised x4 up to these when a crowded field fills them, then the
# threshold is doubled, up to 3 times (5 -> 40 sigma), then the frame has no sources: from sep's
# defaults, at most 8 extractions
_SEP_MAX_PIXSTACK = 4_800_000  # ~200 MB of sep's pixel lists
_SEP_MAX_SUB_OBJECTS = 16_384
_SEP_THRESHOLD_DOUBLINGS = 3


@dataclass(frozen=True, eq=False)
class Detections:
    """Stars found in an image, saturated stars first (their flux is a lower bound), then the
    others by decreasing ``snr``.

    ``xy`` (n, 2): windowed centroids, px, our convention (top-left pixel centre at (0.5,
    0.5)); ``flux``: flux in an aperture of 3 PSF sigmas above the local background (image
    units); ``peak``: brightest pixel above the background (image units); ``snr``: flux over
    the local background noise in the PSF's noise-equivalent area 4 pi sigma² (the star's own
    photon noise is left out: the gain is unknown); ``saturated``: bool per star.
    ``background``, ``background_rms``: global level and pixel noise (image units);
    ``psf_sigma_px``: the PSF sigma given or measured; ``n_saturated``: saturated sources
    found; ``n_hot``: hot pixels removed; ``width``, ``height``: image size (px);
    ``elongation``: the median ratio of the long to the short axis of the stars (sep's
    isophotal a / b; 1 for round stars, 3 for stars trailed to 3 times their width, 1 when
    none); ``n_rejected``: sources measured and not taken for stars (extended, elongated, or faint
    against their surroundings); ``threshold_sigma``: the detection threshold the stars were
    found at (None: not recorded); ``sky_fraction``: the share of the image's pixels detection
    looked at (a fisheye's sky mask, ``starnav.detect.skymask``, leaves out the rest);
    ``circle``: a circular fisheye's image circle, when it was looked for and found
    (``detect.circle``), outside which nothing was detected; without one, the disc that the
    sky left by the mask suggests (``contrast`` 0: ``detect.skymask.SkyMask.lit_disc``), a
    start for the focal scan.
    """

    xy: np.ndarray
    flux: np.ndarray
    peak: np.ndarray
    snr: np.ndarray
    saturated: np.ndarray
    background: float
    background_rms: float
    psf_sigma_px: float
    n_saturated: int
    n_hot: int
    width: int
    height: int
    n_rejected: int = 0
    elongation: float = 1.0
    threshold_sigma: float | None = None
    sky_fraction: float = 1.0
    circle: ImageCircle | None = None

    def __len__(self) -> int:
        return len(self.xy)

    def kept(self, keep: np.ndarray) -> Detections:
        """These detections with only the stars where ``keep`` (bool per star) is True."""
        columns = ("xy", "flux", "peak", "snr", "saturated")
        return replace(self, **{name: getattr(self, name)[keep] for name in columns})


def detect_stars(
    image: np.ndarray,
    *,
    threshold_sigma: float = 5.0,
    max_stars: int | None = None,
    min_area_px: int = 3,
    saturation: float | None = None,
    psf_sigma_px: float | None = None,
    reject_hot_pixels: bool = True,
    keep_saturated: bool = True,
) -> Detections:
    """Find, clean and centroid the stars of a 2-D image (row 0 at the top; any numeric dtype,
    any byte order; NaN / infinite pixels are masked).

    ``threshold_sigma``: detection significance in the matched-filtered image, counted in the
    local noise; ``max_stars``: keep the first this many (None: all); ``min_area_px``: fewest
    filtered pixels above the threshold; ``saturation``: pixel value at which the sensor
    saturates (None: the integer dtype's maximum if reached, else the image maximum when it
    forms a plateau of adjacent pixels); ``psf_sigma_px``: Gaussian PSF sigma (None: measured
    on the compact sources); ``reject_hot_pixels``: remove isolated single bright pixels;
    ``keep_saturated``: keep (flagged) or drop saturated stars. A blank or constant image
    gives no stars.
    """
    _check_options(threshold_sigma, max_stars, min_area_px, saturation, psf_sigma_px)
    data, mask, dtype, (low, high) = _float_image(image)
    height, width = data.shape
    if mask is not None and mask.all():
        return _empty(width, height, psf_sigma_px)
    if not high > low:
        return _empty(width, height, psf_sigma_px, float(low))
    if saturation is None:
        saturation = _infer_saturation(data, dtype, high)
    if mask is None and psf_sigma_px is None:  # a clean star-tracker frame: the fast path
        found = tracker_sources(
            data,
            low,
            threshold_sigma,
            min_area_px,
            saturation,
            reject_hot_pixels,
            residual=_frame_buffer("residual", data.shape),
        )
        if found is not None:
            return _tracker_detections(found, threshold_sigma, max_stars, keep_saturated)
    if np.may_share_memory(data, image):  # the caller's pixels: the steps below write
        data = data.copy()

    clipped = _clipped(data, mask, low)
    background = estimate_background(data, mask)
    subtract_background(data, background)
    correlation = noise_correlation(data, mask)
    background = background.scaled_rms(correlation)
    level, rms = background.level, background.rms
    if not rms > 0:  # a noise-free image: an rms relative to its range
        rms = _NOISE_FREE_RMS * (high - level)
        background = background.with_rms_floor(rms)
    if clipped:  # its clipped noise map raised to the noise its upper half shows
        rms = max(rms, _rms_floor(data, mask))
        background = background.with_rms_floor(rms)
    background = background.with_rms_floor(_MAP_RMS_FLOOR * rms)
    n_hot = clean_hot_pixels(data, threshold_sigma * rms) if reject_hot_pixels else 0
    found = _sources(
        data, mask, background, threshold_sigma, min_area_px, psf_sigma_px, saturation, correlation
    )
    if found is None:
        return _empty(width, height, psf_sigma_px, level, rms, n_hot)
    objects, saturated, sigma = found
    n_saturated = int(saturated.sum())
    if not keep_saturated:
        objects, saturated = objects[~saturated], saturated[~saturated]
        if len(objects) == 0:
            return _empty(width, height, psf_sigma_px, level, rms, n_hot, n_saturated)
    peak_snr = objects["peak"] / _rms_at_peaks(background, objects)
    near_top = _raw_peaks(objects, data, background) >= level + _NEAR_TOP * (high - level)
    stars, n_rejected, elongation = _measured_in_batches(
        data,
        mask,
        objects,
        saturated,
        near_top,
        peak_snr,
        sigma,
        background,
        threshold_sigma,
        max_stars,
        correlation,
    )
    return Detections(
        *stars,
        float(level),
        float(rms),
        float(sigma),
        n_saturated,
        n_hot,
        width,
        height,
        n_rejected,
        elongation,
    )


def _sources(
    data: np.ndarray,
    mask: np.ndarray | None,
    background: Background,
    threshold_sigma: float,
    min_area_px: int,
    psf_sigma_px: float | None,
    saturation: float | None,
    correlation: float,
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(sep's sources, their saturation flags, the PSF sigma given or measured), None when
    nothing is found. With the PSF unknown, sources are found with sep's 3 x 3 kernel (a
    matched filter for PSF sigma ~0.6-1.5 px: 90 % of the best SNR or more, 60 % at 2.5 px)
    and found again with the measured PSF's Gaussian when that is wider than 2.5 px (a
    wider kernel lowers the filtered noise so far that the faint residual of glow along a
    horizon crosses the threshold in large patches, which swallow the stars in them)."""
    objects = _extract(data, mask, background, threshold_sigma, min_area_px, psf_sigma_px)
    plateaus = objects["npix"] > _PLATEAU_PX
    if plateaus.any():  # the coarse mesh left patches of glow: a finer one, stars masked
        objects, segments = _extract(
            data, mask, background, threshold_sigma, min_area_px, psf_sigma_px, segments=True
        )
        plateaus = objects["npix"] > _PLATEAU_PX
        compact = np.ones(len(objects) + 1, dtype=bool)
        compact[0] = False
        compact[1:][plateaus] = False
        subtract_background(data, fine_background(data, mask, compact[segments]))
        objects = _extract(data, mask, background, threshold_sigma, min_area_px, psf_sigma_px)
    if len(objects) == 0:
        return None
    saturated = _saturated(objects, data, background, saturation)
    sigma = psf_sigma_px
    if sigma is None:
        peak_snr = objects["peak"] / _rms_at_peaks(background, objects)
        sigma = measure_psf_sigma(
            data, objects[~saturated], mask, peak_snr[~saturated], correlation
        )
        if sigma > _WIDEST_FOR_DEFAULT_KERNEL:
            objects = _extract(data, mask, background, threshold_sigma, min_area_px, sigma)
            saturated = _saturated(objects, data, background, saturation)
    return objects, saturated, sigma


def _measured_in_batches(
    data: np.ndarray,
    mask: np.ndarray | None,
    objects: np.ndarray,
    saturated: np.ndarray,
    near_top: np.ndarray,
    peak_snr: np.ndarray,
    sigma: float,
    background: Background,
    threshold_sigma: float,
    max_stars: int | None,
    correlation: float,
):
    """``_measured`` on the likely stars first (``_in_batches``)."""
    args = (sigma, background, threshold_sigma, max_stars, correlation)

    def measure(pick):
        if pick is None:
            return _measured(data, mask, objects, saturated, near_top, *args)
        return _measured(data, mask, objects[pick], saturated[pick], near_top[pick], *args)

    return _in_batches(objects, saturated, peak_snr, max_stars, measure)


def _in_batches(objects, saturated, peak_snr, max_stars, measure):
    """``measure(pick)`` (the sources ``pick`` measured and ranked) on the likely stars
    first (saturated ones, then by the better of their ranks in peak over the noise map,
    ``peak_snr``, and in sep's flux), 2 ``max_stars`` + 20 of them, twice as many until
    ``max_stars`` are taken for stars or 4 ``max_stars`` + 30 were measured (all, ``pick``
    None, with ``max_stars`` None)."""
    if max_stars is None:
        return measure(None)
    # the better of two ranks: peak over the noise map, and sep's total flux (a bright
    # star's halo raises the noise map under its own peak)
    rank = np.minimum(_ranks(-peak_snr), _ranks(-objects["flux"]))
    order = np.lexsort((rank, ~saturated))
    limit = min(len(order), _CANDIDATES_PER_STAR * max_stars + _CANDIDATES_EXTRA)
    n = min(limit, _FIRST_PER_STAR * max_stars + _FIRST_EXTRA)
    while True:
        measured = measure(order[:n])
        if len(measured[0][0]) >= max_stars or n >= limit:
            return measured
        n = min(limit, 2 * n)


def _ranks(values: np.ndarray) -> np.ndarray:
    """Each value's rank, 0 for the smallest."""
    rank = np.empty(len(values), dtype=np.intp)
    rank[np.argsort(values, kind="stable")] = np.arange(len(values))
    return rank


def _measured(
    data: np.ndarray,
    mask: np.ndarray | None,
    objects: np.ndarray,
    saturated: np.ndarray,
    near_top: np.ndarray,
    sigma: float,
    background: Background,
    threshold_sigma: float,
    max_stars: int | None,
    correlation: float,
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], int, float]:
    """(centroids (our pixel convention), local flux, peak, SNR and saturation flag of the
    sources taken for stars, saturated first then by SNR, the first ``max_stars`` (None:
    all); how many sources were not taken for stars; their median elongation a / b).
    ``near_top``: whether each source's peak comes near the image's maximum."""
    x, y = _centroids(data, objects, sigma, mask)
    phot = local_photometry(data, mask, x, y, sigma)
    noise, snr = _judged(phot, background, sigma)
    flux = phot.flux
    peak_snr = phot.peak / noise
    shaped = ~misshapen(objects, sigma, peak_snr)
    foreground = phot.in_foreground(correlation)
    star = _taken(shaped, ~phot.extended(noise) & ~foreground, snr, saturated, threshold_sigma)
    # a star whose disc and halo are wider than the PSF, as the brightest are in a long
    # exposure or a stretched photograph (their cores near the image's maximum: a patch of
    # cloud or glow as wide has no such core): judged and measured whole, in its own zones
    size = np.sqrt(objects["a"] * objects["b"])
    wide = ~star & near_top & ~elongated(objects, sigma, peak_snr)
    wide = np.flatnonzero(wide & (size > _WIDE_SIGMAS * sigma))
    if len(wide):
        whole = own_scale_photometry(data, mask, x[wide], y[wide], size[wide])
        # ranked as bright as a star of the PSF with that flux
        whole_noise, whole_snr = _judged(whole, background, sigma)
        ok = ~whole.extended(whole_noise) & ~whole.in_foreground(correlation)
        ok &= whole_snr >= threshold_sigma
        wide = wide[ok]
        flux, snr = flux.copy(), snr.copy()
        flux[wide], snr[wide] = whole.flux[ok], whole_snr[ok]
        star[wide] = True
    return _ranked(objects, x, y, flux, snr, saturated, star, max_stars)


def without_glare(found: Detections) -> Detections:
    """``found`` less its saturated stars that have ``_CROWD`` or more other saturated ones
    within ``_CROWD_RADIUS`` of the image's diagonal: in an all-sky frame those are the
    pieces of one saturated patch (a lamp's glare, the Moon's rim, a lit window, which sep's
    deblending cuts into 10-30 round pieces), not stars, for its saturated stars lie apart.
    (Not for narrower fields: an open cluster's members saturate side by side there: the
    Pleiades and M44 in the real-photo corpus.)"""
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(found.saturated)
    if len(rows) <= _CROWD:
        return found
    xy = found.xy[rows]
    reach = _CROWD_RADIUS * math.hypot(found.width, found.height)
    counts = cKDTree(xy).query_ball_point(xy, reach, return_length=True)
    keep = np.ones(len(found.xy), dtype=bool)
    keep[rows[counts - 1 >= _CROWD]] = False
    return found if keep.all() else found.kept(keep)


def without_trails(found: Detections) -> Detections:
    """``found`` less the pieces of trails: ``_TRAIL_PIECES`` or more sources in a chain of
    close neighbours (each within ``_CROWD_RADIUS`` of the image's diagonal of the next,
    each link a source midway between two in line: within 10° and ``_TRAIL_EVEN``) lying on
    one straight line, within ``_TRAIL_STRAIGHTNESS`` of their spacing. A fireball
    or meteor cut into dashes by a chopping shutter (the Desert Fireball Network's), a
    satellite or aircraft with blinking lights, a streak that deblending cuts into pieces:
    each piece is round, so the shape test keeps it, and a bright trail fills the brightest
    places meant for stars. Five stars evenly on a line that straight do not happen by chance.
    (All-sky frames only, as ``without_glare``.)"""
    n = len(found.xy)
    if n < _TRAIL_PIECES:
        return found
    xy = found.xy
    offsets = xy[None, :, :] - xy[:, None, :]
    distance = np.hypot(offsets[..., 0], offsets[..., 1])
    near = (distance > 0) & (distance <= _CROWD_RADIUS * math.hypot(found.width, found.height))
    unit = offsets / np.where(distance > 0, distance, 1.0)[..., None]
    linked = np.zeros((n, n), dtype=bool)
    for i in np.flatnonzero(near.sum(axis=1) >= 2):
        rows = np.flatnonzero(near[i])
        cosines = unit[i, rows] @ unit[i, rows].T
        steps = distance[i, rows]
        even = np.abs(steps[:, None] - steps[None, :]) <= _TRAIL_EVEN * np.fmax.outer(steps, steps)
        # i midway between j and k, in line with them
        j, k = np.nonzero(np.triu((cosines < -_TRAIL_COS) & even, 1))
        ends = np.unique(np.concatenate([rows[j], rows[k]]))
        linked[i, ends] = linked[ends, i] = True
    if not linked.any():
        return found
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(linked, directed=False)
    keep = np.ones(n, dtype=bool)
    for label in range(count):
        members = np.flatnonzero(labels == label)
        if len(members) < _TRAIL_PIECES:
            continue
        points = xy[members] - xy[members].mean(axis=0)
        across = np.linalg.svd(points, compute_uv=False)[-1] / math.sqrt(len(members))
        spacing = np.median(np.where(near[members][:, members], distance[members][:, members],
                                     np.inf).min(axis=1))  # fmt: skip
        if across <= _TRAIL_STRAIGHTNESS * spacing:
            keep[members] = False
    return found if keep.all() else found.kept(keep)


def _taken(
    shaped: np.ndarray,
    surroundings: np.ndarray | bool,
    snr: np.ndarray,
    saturated: np.ndarray,
    threshold_sigma: float,
) -> np.ndarray:
    """Whether each source is taken for a star: ``shaped`` as a star, its ``surroundings``
    a star's (not extended, not in foreground) and of SNR ``_MIN_SNR_FRACTION``
    ``threshold_sigma`` or more; or saturated and ``shaped`` (a saturated star's flat top and
    halo fill the ring)."""
    star = shaped & surroundings & (snr >= _MIN_SNR_FRACTION * threshold_sigma)
    return star | (saturated & shaped)


def _ranked(
    objects: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    flux: np.ndarray,
    snr: np.ndarray,
    saturated: np.ndarray,
    star: np.ndarray,
    max_stars: int | None,
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], int, float]:
    """``_measured``'s answer from the sources' centroids (sep's convention), flux, SNR,
    saturation and whether each is taken for a star: saturated first (by flux), then by
    SNR, the first ``max_stars`` (None: all)."""
    keep = np.flatnonzero(star)
    order = keep[np.lexsort((-np.where(saturated, flux, snr)[keep], ~saturated[keep]))]
    if max_stars is not None:
        order = order[:max_stars]
    xy = np.column_stack([x[order], y[order]]) + 0.5
    peak = objects["peak"][order].astype(float)
    measured = (xy, flux[order], peak, snr[order], saturated[order])
    b = np.maximum(objects["b"][order], 1e-3)
    elongation = float(np.median(objects["a"][order] / b)) if len(order) else 1.0
    return measured, int(len(objects) - len(keep)), elongation


def _tracker_detections(
    found: TrackerSources,
    threshold_sigma: float,
    max_stars: int | None,
    keep_saturated: bool,
) -> Detections:
    """The stars of a clean star-tracker frame's sources (``starnav.detect.tracker``):
    windowed centroids, each source's flux against its annulus, taken for a star when not
    misshapen (a saturated one too) and, unsaturated, of SNR half ``threshold_sigma`` or
    more; ranked as ``_measured`` ranks."""
    objects, data, rms, sigma = found.objects, found.data, found.rms, found.psf_sigma_px
    height, width = data.shape
    saturated = found.saturated
    n_saturated = int(saturated.sum())
    if not keep_saturated:
        objects, saturated = objects[~saturated], saturated[~saturated]
    if len(objects) == 0:
        return _empty(width, height, sigma, found.level, rms, found.n_hot, n_saturated)
    peak_snr = objects["peak"] / rms

    def measure(pick):
        part = objects if pick is None else objects[pick]
        sat = saturated if pick is None else saturated[pick]
        x, y = _centroids(data, part, sigma, None)
        flux, local_noise = local_flux(found, x, y, sigma)
        _, snr = _snr(flux, local_noise, rms, sigma)
        shaped = ~misshapen(part, sigma, part["peak"] / rms)
        star = _taken(shaped, True, snr, sat, threshold_sigma)
        return _ranked(part, x, y, flux, snr, sat, star, max_stars)

    stars, n_rejected, elongation = _in_batches(objects, saturated, peak_snr, max_stars, measure)
    return Detections(
        *stars,
        found.level,
        rms,
        sigma,
        n_saturated,
        found.n_hot,
        width,
        height,
        n_rejected,
        elongation,
    )


def _judged(
    phot: LocalPhotometry, background: Background, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """(the noise each source is judged by, its SNR): the noise of its surroundings where it
    is clearly above the image's (a tree line, a roof edge, foliage, a bright sky), else the
    image's (so that uniform skies rank by flux); the SNR of its local flux as if in a
    Gaussian PSF of ``sigma`` px."""
    return _snr(phot.flux, phot.noise, background.rms, sigma)


def _snr(
    flux: np.ndarray, local_noise: np.ndarray, rms: float, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """(the noise each source is judged by: its surroundings' ``local_noise`` where clearly
    above the image's ``rms``, else that; the SNR of its ``flux`` as if in a Gaussian PSF of
    ``sigma`` px)."""
    noise = np.fmax(rms, local_noise / _LOCAL_NOISE_MARGIN)
    return noise, flux / (noise * math.sqrt(4.0 * math.pi) * sigma)


def _sample(data: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """About ``_NOISE_SAMPLE`` of the image's unmasked pixels, on a regular grid."""
    step = max(1, int(math.sqrt(data.size / _NOISE_SAMPLE)))
    sample = data[::step, ::step]
    return sample.ravel() if mask is None else sample[~mask[::step, ::step]]


def _clipped(data: np.ndarray, mask: np.ndarray | None, low: float) -> bool:
    """Whether the sky is clipped at the black level: ``_CLIPPED_FRACTION`` of the pixels or
    more at the image's lowest value (8-bit star-tracker and finder frames: 35-80 %)."""
    sample = _sample(data, mask)
    return sample.size > 0 and np.count_nonzero(sample == low) >= _CLIPPED_FRACTION * sample.size


def _rms_floor(data: np.ndarray, mask: np.ndarray | None) -> float:
    """The global pixel rms of a clipped sky (``_clipped``), from the background-subtracted
    ``data``: ``_UPPER_WIDTH_SHARE`` of the width of its upper half (the 84th percentile less
    the median: 1 rms of Gaussian noise), which the clipping leaves. Its sigma-clipped rms is
    far below its true noise (0.14 ADU where the values scatter over 0-3); left at that, the
    threshold falls under the noise, and the glow beside a horizon becomes one source of
    300 000 pixels, which takes sep seconds and hides the stars in it."""
    sample = _sample(data, mask)
    if not sample.size:
        return 0.0
    median, upper = np.quantile(sample, [0.5, _ONE_SIGMA_QUANTILE])
    return _UPPER_WIDTH_SHARE * float(upper - median)


def _rms_at_peaks(background: Background, objects: np.ndarray) -> np.ndarray:
    return background.rms_at(objects["xpeak"].astype(np.intp), objects["ypeak"].astype(np.intp))


def _float_image(
    image: np.ndarray,
) -> tuple[np.ndarray, np.ndarray | None, np.dtype, tuple[float, float]]:
    """The image as a C-ordered float32 array in native byte order (for sep: the caller's own
    when it is one and every pixel is finite, which the caller must not write to; else this
    thread's ``_frame_buffer``, or a new array when a pixel is not finite) with its
    non-finite pixels set to 0 and masked (mask None when every pixel is finite), the dtype
    it came in and the range of its finite pixels (``_finite_range``; 0, 0 for none);
    ``ImageError`` for what is not a 2-D image of at least 3 x 3 numbers."""
    raw = np.asarray(image)
    if raw.ndim != 2 or raw.size == 0:
        raise ImageError(f"an image must be a 2-D array, not empty; got shape {raw.shape}")
    if raw.dtype.kind not in "uifb":
        raise ImageError(f"image pixels must be numbers, got dtype {raw.dtype}")
    height, width = raw.shape
    if height < 3 or width < 3:
        raise ImageError(f"image of {width} x {height} px is too small to detect stars in")
    data = raw
    if not (raw.dtype == np.float32 and raw.dtype.isnative and raw.flags.c_contiguous):
        data = _frame_buffer("pixels", raw.shape)
        np.copyto(data, raw, casting="unsafe")  # np.asarray(raw, dtype=np.float32)'s values
    low, high = data.min(), data.max()  # NaN or infinite when a pixel is
    if np.isfinite(low) and np.isfinite(high):
        return data, None, raw.dtype, (float(low), float(high))
    finite = np.isfinite(data)
    mask = ~finite
    data = np.where(finite, data, np.float32(0.0))
    return data, mask, raw.dtype, _finite_range(data, mask) if finite.any() else (0.0, 0.0)


_FRAME_BUFFERS = threading.local()


def _frame_buffer(name: str, shape: tuple[int, int]) -> np.ndarray:
    """This thread's float32 array ``name`` of ``shape``, kept from one image to the next:
    an image's pixels as float32 (``_float_image``) and its residual on the fast path
    (``tracker_sources``). A new 4-16 MB array every frame is memory the allocator gives back
    to the system between frames and the system zeroes again page by page when it is asked
    for it (500-1000 page faults, about 1.5 ms of a 1024 px frame). Their contents live only
    within one ``detect_stars`` call (detection does not call itself, and no result holds
    them); the memory stays with the thread, for the last image size it detected."""
    buffers = _FRAME_BUFFERS.__dict__
    buffer = buffers.get(name)
    if buffer is None or buffer.shape != shape:
        buffer = buffers[name] = np.empty(shape, dtype=np.float32)
    return buffer


def _extract(
    data: np.ndarray,
    mask: np.ndarray | None,
    background: Background,
    threshold_sigma: float,
    min_area_px: int,
    psf_sigma_px: float | None,
    *,
    segments: bool = False,
):
    """sep's sources of the background-subtracted ``data``: matched filter (the PSF Gaussian
    or sep's 3x3 kernel), ``threshold_sigma`` counted in the filtered image's noise, from the
    noise map (so the threshold rises over textured foreground); with ``segments``, also
    sep's segmentation map (0: no source, i: the pixels of source i - 1)."""
    kernel = _DEFAULT_KERNEL if psf_sigma_px is None else _gaussian_kernel(psf_sigma_px)
    filtered = float(np.sqrt((kernel**2).sum()) / kernel.sum())  # filtered / pixel noise
    # a noise map within 25 % of uniform (a star tracker's sky): one threshold, 1.4x faster
    uniform = background.rms_map.max() <= _UNIFORM_NOISE * background.rms_map.min()
    threshold = threshold_sigma * filtered * (background.rms if uniform else 1.0)
    err = None if uniform else background.full_rms(data.shape)
    pixstack, sub_objects = sep.get_extract_pixstack(), sep.get_sub_object_limit()
    doublings = 0
    try:
        while doublings <= _SEP_THRESHOLD_DOUBLINGS:
            try:
                return sep.extract(
                    data,
                    threshold,
                    err=err,
                    mask=mask,
                    minarea=min_area_px,
                    filter_kernel=kernel,
                    filter_type="conv",
                    # half sep's default: 2x faster on 300 stars, and it still splits equal
                    # stars 4.5 px apart and 5:1 pairs 5.5 px apart at PSF sigma 1 (closer
                    # ones are one star to a star tracker anyway)
                    deblend_nthresh=16,
                    segmentation_map=segments,
                )
            except Exception as exc:  # sep raises plain Exception for its buffer limits
                if not _raised_sep_limit(str(exc), data.size):
                    threshold *= 2.0
                    doublings += 1
        return _no_sources(segments, data.shape)
    finally:
        sep.set_extract_pixstack(pixstack)
        sep.set_sub_object_limit(sub_objects)


def _raised_sep_limit(message: str, n_pixels: int) -> bool:
    """After sep stopped on one of its buffer limits (``message``, its error): raise that limit
    x4, up to its bound (the image's pixel count or ``_SEP_MAX_PIXSTACK`` for the pixel
    stack, ``_SEP_MAX_SUB_OBJECTS`` sub-objects per source), and say whether it could be
    raised; a Milky Way or a nebula that joins thousands of stars into one source above the
    threshold splits at a higher one, which the caller tries when it could not. Anything else
    sep raises is not a limit: ``ImageError``."""
    if "pixel buffer full" in message:
        limit, setter = sep.get_extract_pixstack(), sep.set_extract_pixstack
        bound = min(_SEP_MAX_PIXSTACK, n_pixels)
    elif "deblending overflow" in message:
        limit, setter = sep.get_sub_object_limit(), sep.set_sub_object_limit
        bound = _SEP_MAX_SUB_OBJECTS
    else:
        raise ImageError(f"star detection failed ({' '.join(message.split())})")
    if limit >= bound:
        return False
    setter(min(bound, 4 * limit))
    return True


def _no_sources(segments: bool, shape: tuple[int, int]):
    """sep's answer for no sources (with an empty segmentation map when asked for)."""
    objects = sep.extract(np.zeros((8, 8), dtype=np.float32), 1.0)
    return (objects, np.zeros(shape, dtype=np.int32)) if segments else objects


def _saturated(
    objects: np.ndarray, data: np.ndarray, background: Background, saturation: float | None
) -> np.ndarray:
    """Whether each source's peak pixel, background added back, reaches ``saturation``."""
    if saturation is None:
        return np.zeros(len(objects), dtype=bool)
    return _raw_peaks(objects, data, background) >= np.float32(saturation)


def _raw_peaks(objects: np.ndarray, data: np.ndarray, background: Background) -> np.ndarray:
    """Each source's peak pixel in background-subtracted ``data``, the background added
    back."""
    xpeak = objects["xpeak"].astype(np.intp)
    ypeak = objects["ypeak"].astype(np.intp)
    return data[ypeak, xpeak] + background.level_at(xpeak, ypeak)


def _centroids(
    data: np.ndarray, objects: np.ndarray, sigma: float, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Windowed centroids (sep's pixel convention) of the sources, Gaussian window of sigma
    sqrt(``sigma``² + 1 px²)."""
    window = np.full(len(objects), math.sqrt(sigma**2 + 1.0))
    x0, y0 = objects["x"].astype(float), objects["y"].astype(float)
    if mask is None:  # sep.winpos's numbers (subpix=1), without its cost per call
        from starnav.detect import kernels

        x, y = kernels.windowed_centroids(data, x0, y0, window)
    else:  # subpix=1: the window is a Gaussian, so finer sampling of its edge changes nothing
        x, y, _ = sep.winpos(data, x0, y0, window, mask=mask, subpix=1)
    # a faint star deblended from a bright neighbour drags its window towards it: keep
    # sep's isophotal barycentre (of its own pixels) when the window wanders off (< 1 %)
    wandered = ~(np.hypot(x - objects["x"], y - objects["y"]) <= window)
    x[wandered], y[wandered] = objects["x"][wandered], objects["y"][wandered]
    return x, y


def _check_options(threshold_sigma, max_stars, min_area_px, saturation, psf_sigma_px) -> None:
    if not (_is_real(threshold_sigma) and np.isfinite(threshold_sigma) and threshold_sigma > 0):
        raise ImageError(f"threshold_sigma must be a positive number, got {shown(threshold_sigma)}")
    if max_stars is not None and not (_is_int(max_stars) and max_stars >= 1):
        raise ImageError(f"max_stars must be an integer >= 1 or None, got {shown(max_stars)}")
    if not (_is_int(min_area_px) and min_area_px >= 1):
        raise ImageError(f"min_area_px must be an integer >= 1, got {shown(min_area_px)}")
    if saturation is not None and not (_is_real(saturation) and np.isfinite(saturation)):
        raise ImageError(f"saturation must be a pixel value or None, got {shown(saturation)}")
    if psf_sigma_px is not None and not (
        _is_real(psf_sigma_px) and np.isfinite(psf_sigma_px) and 0.2 <= psf_sigma_px <= 20.0
    ):
        raise ImageError(
            f"psf_sigma_px must be within 0.2..20 px or None, got {shown(psf_sigma_px)}"
        )


def _is_real(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _is_int(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def _empty(
    width: int,
    height: int,
    psf_sigma_px: float | None,
    level: float = 0.0,
    rms: float = 0.0,
    n_hot: int = 0,
    n_saturated: int = 0,
) -> Detections:
    none = np.zeros(0)
    return Detections(
        np.zeros((0, 2)),
        none,
        none,
        none,
        np.zeros(0, dtype=bool),
        float(level),
        float(rms),
        float(psf_sigma_px or 0.0),
        n_saturated,
        n_hot,
        width,
        height,
    )


def _finite_range(data: np.ndarray, mask: np.ndarray | None) -> tuple[float, float]:
    values = data if mask is None else data[~mask]
    return float(values.min()), float(values.max())


def _infer_saturation(data: np.ndarray, dtype: np.dtype, high: float) -> float | None:
    """The saturation level: the integer dtype's maximum when some pixel reaches it, else the
    image maximum when at least two adjacent pixels share it (a clipped, flat-topped star)."""
    if dtype.kind in "ui" and high >= np.iinfo(dtype).max:
        return high
    from starnav.detect import kernels

    count, adjacent = kernels.plateau(data, np.float32(high))
    if count < 2 or count > data.size // 2:
        return None
    return high if adjacent else None


def _gaussian_kernel(sigma: float) -> np.ndarray:
    half = max(1, math.ceil(2.5 * sigma))
    r = np.arange(-half, half + 1, dtype=np.float32)
    g = np.exp(-0.5 * (r / np.float32(sigma)) ** 2)
    return np.ascontiguousarray(np.outer(g, g), dtype=np.float32)
