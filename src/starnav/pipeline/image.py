"""From an image (file or array) to a verified attitude.

``solve_image`` reads the file (``starnav.detect.read``), finds and centroids the stars
(``starnav.detect.stars``) and solves them with the field of view unknown, roughly known or
calibrated (``pipeline.fov``). A camera file (JSON, written by ``starnav calibrate``) holds a
calibrated camera: size, focal length, principal point and radial distortion.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from starnav.camera import Camera, CameraModel, model_class
from starnav.catalog import GAIA, Catalog, is_embedded, load_catalog
from starnav.detect.circle import ImageCircle, dark_corners, find_image_circle
from starnav.detect.header import ImageHints, fits_hints, is_fits
from starnav.detect.read import read_image
from starnav.detect.skymask import find_sky_mask
from starnav.detect.stars import Detections, detect_stars, without_glare, without_trails
from starnav.errors import CameraError, ImageError, StarnavError
from starnav.pipeline.diagnose import BUDGET, Failure, diagnose
from starnav.pipeline.fov import UNREAD_SHAPE, diagonal_fov_deg, fov_limits_deg, search_range
from starnav.pipeline.options import (
    DEFAULT_FOV_RANGE_DEG,
    DEFAULT_MAX_STARS,
    DEFAULT_PATTERN_STARS,
    DEFAULT_THRESHOLD_SIGMA,
    FISHEYE,
    FISHEYE_MAX_STARS,
    SolveOptions,
)
from starnav.pipeline.stars import check_searched, exact_field, solve_stars
from starnav.results import Solution, SolveResult
from starnav.runtime.budget import Deadline, check_budget, default_budget_s

NO_HINTS = ImageHints()
WCS_MAX_STARS = 500  # detections a written WCS is fitted on (``fitted_wcs``)
MIN_DETECTIONS = 4  # fewer detected stars than this: not solved, without a search
AUTO_BIN_PIXELS = 4.2e6  # an image is detected binned to at most this many pixels
SPENT_ADVICE = "a longer --time-budget, or a smaller image"  # a budget spent before the solve
FEW_STARS_DEEPER = 15  # a fisheye sky with fewer stars than this is detected again, deeper
DEEPER_THRESHOLDS_SIGMA = (4.0, 3.0)  # the thresholds of those detections, in turn
# a searched pinhole image that is not solved is searched again in its middle, this share of
# its width and height, detected anew there (``_solve_middle``): a wide-angle lens's middle
# is nearly a pinhole's, and a stretched photograph's brightest points (nebula knots,
# spiked star glows) often lie elsewhere in it; then, unsolved and with budget left, a wider
# middle: a telescope frame of 0.625-1.04° has a 60 % middle under the narrowest field
# searched (0.625°), and stacking edges are narrower than a tenth of it
MIDDLE_FRACTIONS = (0.6, 0.8)
MIN_MIDDLE_PX = 96  # and not when that middle is smaller than this


@dataclass(frozen=True, eq=False)
class ImageSolveResult:
    """One image solved: the ``solution`` (None with the ``reason`` when unsolved), the
    ``detections``, the fitted ``camera`` (focal length, principal point, distortion; None
    when unsolved), the ``catalog`` the stars were matched in, the time (ms) spent decoding
    the file (``read_ms``, 0 for an array), detecting stars (``detect_ms``) and identifying
    + fitting (``solve_ms``), and the ``hints`` the file's header gave (``ImageHints``)."""

    solution: Solution | None
    reason: str
    detections: Detections
    camera: CameraModel | None
    read_ms: float
    detect_ms: float
    solve_ms: float
    catalog: Catalog | None = None
    hints: ImageHints = NO_HINTS
    failure: str | None = None

    @property
    def total_ms(self) -> float:
        """Detection and solve (ms): from the decoded image to the attitude."""
        return self.detect_ms + self.solve_ms

    def to_dict(self, file: str | None = None) -> dict:
        """The JSON of the solve (``starnav.results.solve_dict``; the stars are the detections,
        brightest first) with the image ``file``, its size, the fitted principal point and
        distortion (null when unsolved; the principal point in the image's pixels, the
        distortion in square ones when they are not square: ``pixel_aspect``), ``n_detected``,
        ``failure`` (the class of an unsolved image's failure, ``pipeline.diagnose``; null when
        solved) and the times (ms)."""
        from starnav.results import solve_dict

        det, cam = self.detections, self.camera
        out = solve_dict(self.solution, self.reason, self.solve_ms, None, det.xy)
        out.update(
            file=file,
            width=det.width,
            height=det.height,
            cx=cam.cx if cam else None,
            cy=cam.cy / self.solution.pixel_aspect if cam else None,
            **{k: getattr(self.solution, k) if cam else None for k in ("k1", "k2", "k3", "k4")},
            n_detected=len(det.xy),
            pixel_aspect=self.solution.pixel_aspect if cam else self.hints.pixel_aspect,
            failure=self.failure,
            hints=self.hints.to_dict() if self.hints.sources else None,
            read_ms=self.read_ms,
            detect_ms=self.detect_ms,
            solve_ms=self.solve_ms,
        )
        return out


def catalog_year(epoch_year: float) -> float:
    """The year Hipparcos' proper motion is taken to for an image dated ``epoch_year`` (decimal
    year): the nearest whole year, as without a date, so that a service or an archive gets one
    set of pattern tables a year, not a set (~100 MB, ~20 s to build) for every date. Half a
    year of proper motion is 0.012″ for the median star to Hp 8.5, 0.19″ at the 99th
    percentile, 3.5″ at most."""
    return float(round(epoch_year))


def solve_image(
    image: str | Path | np.ndarray,
    options: SolveOptions | None = None,
    *,
    hints: ImageHints | None = None,
    position_hint_deg: tuple[float, float] | None = None,
    prior: np.ndarray | None = None,
    budget_from: Deadline | None = None,
    on_budget: Callable[[float], None] | None = None,
    **option_fields: Any,
) -> ImageSolveResult:
    """Solve an image file (FITS, PNG, JPEG, TIFF) or a 2-D array (row 0 at the top) with
    ``options`` (``SolveOptions``; keyword ``option_fields`` override its fields).

    The field of view is searched within ``options.fov_range_deg`` (horizontal, degrees)
    unless ``fov_deg`` (searched within 5 %) or a calibrated ``camera`` (within 1 %) is
    given (``fov_exact=True``: taken as given); the fitted one is reported either way. A
    fisheye ``lens`` model's focal length is scanned (``pipeline.fov.scan_focal``), and its
    detections outside the image circle found in the image (``starnav.detect.circle``) are
    not made: the dark frame around an all-sky camera's disc often holds burned-in text.
    ``hints``: what the file's header says (``starnav.detect.header.fits_hints``; read from
    a FITS file when None, none for an array): its FOV searched (±5 %) when no ``fov_deg``,
    ``camera`` or other range is given and it is within the pinhole's limits, its epoch used
    when ``epoch_year`` is not (for the embedded Hipparcos: a Gaia, CSV or FITS catalog is
    used at its own epoch), its position searched first; a solve that fails with the hinted
    FOV is tried again without it, its pixels' aspect (``square_pixels``: solved in square
    pixels, answered in the image's). ``position_hint_deg``: the boresight's (RA, Dec), roughly
    (wins over the header's). ``prior``: the previous frame's ``R_cam_from_icrs``, with its
    fitted ``camera``: tracking. The time budget is the solve's (``runtime.budget``)."""
    options = SolveOptions.make(options, **option_fields)
    camera = options.camera
    search_range(
        options.fov_deg, options.search_range_deg, camera, options.lens_model, UNREAD_SHAPE
    )
    if not exact_field(options, images=True):  # bad options fail before any work
        check_searched(options, prior=prior is not None)
    pixels, read_ms, hints = _read(image, hints)
    height, width = pixels.shape
    if camera is not None and (camera.width, camera.height) != (width, height):
        raise CameraError(
            f"the camera file is for {camera.width} x {camera.height} px images, this image is "
            f"{width} x {height} px"
        )
    aspect, file_height = 1.0, height
    if hints.pixel_aspect != 1.0 and camera is None:  # a camera file is in the file's pixels
        pixels, aspect = square_pixels(pixels, hints.pixel_aspect)
        height = pixels.shape[0]
    if _unsaid_fisheye(options, pixels):
        options = replace(options, lens=FISHEYE)  # each common model, from the circle
    budget_s = check_budget(options.time_budget_s, _default_budget_s(options, pixels))
    t1 = time.perf_counter()
    found = _detect_binned(pixels, options)
    detect_ms = (time.perf_counter() - t1) * 1e3
    budget_s, spent = _budget_left(budget_s, budget_from, on_budget)
    if len(found.xy) < MIN_DETECTIONS or spent:
        reason = spent or f"{len(found.xy)} stars detected, at least {MIN_DETECTIONS} are needed"
        failure = Failure(BUDGET, SPENT_ADVICE) if spent else _diagnose(found, reason, options)
        return ImageSolveResult(
            None, failure.explain(reason), found, None, read_ms, detect_ms, 0.0,
            hints=hints, failure=failure.kind,
        )  # fmt: skip
    if options.epoch_year is None and hints.epoch_year is not None and is_embedded(options.catalog):
        options = replace(options, epoch_year=catalog_year(hints.epoch_year))
    if options.utc is None and hints.utc is not None:
        options = replace(options, utc=hints.utc)  # where the sky is, with the site
    if options.site is None and hints.site is not None:
        options = replace(options, site=hints.site)
    searched = not options.field_known and not options.scans_focal
    result = _solve_hinted(
        found.xy, (width, height), options, hints if searched else NO_HINTS, budget_s,
        position_hint_deg, prior, found.circle,
    )  # fmt: skip
    for fraction in MIDDLE_FRACTIONS if searched and prior is None else ():
        if result.solution is None:
            result = _solve_middle(pixels, found.xy, options, budget_s, result, fraction)
    sol = result.solution
    reason, failure = result.reason, None
    if sol is None:
        why = _diagnose(found, reason, options)
        reason, failure = why.explain(reason), why.kind
    if aspect != 1.0:
        sol, found = _in_file_pixels(sol, found, aspect, file_height)
    return ImageSolveResult(
        sol,
        reason,
        found,
        None if sol is None else sol.camera,
        read_ms,
        detect_ms,
        result.time_ms,
        result.catalog,
        hints,
        failure,
    )


def _read(
    image: str | Path | np.ndarray, hints: ImageHints | None
) -> tuple[np.ndarray, float, ImageHints]:
    """The pixels of an image file or 2-D array, the time (ms) reading took, and the
    ``hints`` (None: a FITS file's header's, none for another file or an array)."""
    if isinstance(image, np.ndarray):
        if image.ndim != 2 or image.size == 0:
            raise ImageError(f"an image array must be 2-D and not empty, got shape {image.shape}")
        return image, 0.0, hints or NO_HINTS
    t0 = time.perf_counter()
    pixels = read_image(image)
    read_ms = (time.perf_counter() - t0) * 1e3
    return pixels, read_ms, (fits_hints(image) if hints is None else hints) or NO_HINTS


def _in_file_pixels(
    solution: Solution | None, found: Detections, aspect: float, height: int
) -> tuple[Solution | None, Detections]:
    """A solution and detections made in square pixels (``square_pixels``) given in the
    image's, ``aspect`` times as tall as wide and ``height`` rows: their y divided by it."""
    solution, found = _rows_scaled(solution, found, 1.0 / aspect)
    found = replace(found, height=height)
    return (None if solution is None else replace(solution, pixel_aspect=aspect)), found


def _rows_scaled(
    solution: Solution | None, found: Detections, factor: float
) -> tuple[Solution | None, Detections]:
    """The solution's stars and the detections with their y times ``factor``."""
    found = replace(found, xy=found.xy * (1.0, factor))
    if solution is None:
        return None, found
    table = solution.star_table
    return replace(solution, star_table=replace(table, xy=table.xy * (1.0, factor))), found


def square_pixels(pixels: np.ndarray, aspect: float) -> tuple[np.ndarray, float]:
    """An image of pixels ``aspect`` times as tall as wide resampled to square ones
    (linearly, its rows only: a pixel's width stays the unit), and the aspect kept (its new
    height over its old: the rows are whole). Edges map to edges: y square = y image x
    aspect, in pixels from the top edge."""
    from scipy.ndimage import zoom

    height = pixels.shape[0]
    rows = max(round(height * aspect), 1)
    scale = rows / height
    out = zoom(np.asarray(pixels, dtype=np.float32), (scale, 1.0), order=1, grid_mode=True,
               mode="nearest")  # fmt: skip
    return out, scale


def _solve_middle(
    pixels: np.ndarray,
    xy: np.ndarray,
    options: SolveOptions,
    budget_s: float,
    failed,
    fraction: float,
) -> SolveResult:
    """An unsolved searched pinhole image (``failed``: its result; ``xy``: its detections)
    solved again from its middle (``fraction`` of each side, the same principal point)
    on what is left of ``budget_s``: detected anew there and searched (the default ranges, or
    the middle's part of the range given). From that attitude and focal length (``prior``)
    the whole frame's detections are fitted with the radial distortion freed (a wide-angle
    lens bends the rest), or, when that is refused, the middle's detections in the whole
    frame's pixels: either answer passes the same verification as any, at a quarter of the
    false-match probability asked for (``MIDDLE_FRACTIONS``' two middles share half of it:
    a false answer from any of the three searches is at most 1.5 times as likely as the
    probability asked for). The budget counts the searches and fits (``time_ms``), as every
    solve's does, not the detection or the tables loaded. ``failed`` when nothing is found,
    its reason telling the middle's."""
    spent_ms = failed.time_ms

    def unsolved(why: str) -> SolveResult:
        return replace(
            failed,
            reason=f"{failed.reason}; the middle {fraction:.0%} of the frame alone: {why}",
            time_ms=spent_ms,
        )

    height, width = pixels.shape
    y0, x0 = (round(n * (1.0 - fraction) / 2.0) for n in pixels.shape)
    size = (width - 2 * x0, height - 2 * y0)
    if options.lens_model != "pinhole" or spent_ms >= budget_s * 1e3 or min(size) < MIN_MIDDLE_PX:
        return failed
    searched = options.fov_range_deg
    if searched is not None:  # the middle's part of each field given, at the same focal length
        lo = fov_limits_deg("pinhole", size)[0]
        searched = tuple(
            max(lo, Camera(*size, Camera.from_fov(v, width, height).focal_px).fov_deg)
            for v in searched
        )
        if searched[0] >= searched[1]:
            return unsolved("its fields are narrower than the narrowest searched")
    middle = np.ascontiguousarray(pixels[y0 : height - y0, x0 : width - x0])
    inner = _detect_binned(middle, options).xy
    step, why = None, "too few stars detected"
    if len(inner) >= MIN_DETECTIONS:
        # the middles share half the false-match probability asked for
        share = options.max_false_match_probability / (2 * len(MIDDLE_FRACTIONS))
        options = replace(options, max_false_match_probability=share)
        left_s = budget_s - spent_ms / 1e3
        within = replace(options, fov_range_deg=searched, time_budget_s=left_s)
        found = solve_stars(inner, within, width=size[0], height=size[1], images=True)
        spent_ms += found.time_ms
        why = found.reason or "no time left"
        camera = None if found.solution is None else Camera(width, height, found.solution.focal_px)
        for points, bent in ((xy, True), (inner + np.array([x0, y0]), False)):
            if camera is None or spent_ms >= budget_s * 1e3:
                break
            whole = replace(
                options, camera=camera, fov_deg=None, fov_range_deg=None, fit_distortion=bent,
                time_budget_s=budget_s - spent_ms / 1e3,
            )  # fmt: skip
            step = solve_stars(points, whole, prior=found.solution.R_cam_from_icrs, images=True)
            spent_ms += step.time_ms
            if step.solution is not None:
                break
            why = f"solved, but not in the whole frame's pixels: {step.reason}"
    if step is not None and step.solution is not None:  # named for how it was found
        named = replace(step.solution, algorithm=f"{found.solution.algorithm} (middle)")
        return replace(step, solution=named, time_ms=spent_ms)
    return unsolved(why)


def _budget_left(budget_s: float, budget_from, on_budget) -> tuple[float, str | None]:
    """The budget (s) left to the solve of an image read and detected: all of ``budget_s``,
    or, counted from ``budget_from`` (a ``Deadline``: the job's start, as in a service), what
    is left, then told to ``on_budget(seconds)``; and the reason when none is left."""
    if budget_from is not None:
        spent_s = budget_from.spent_s()
        if spent_s >= budget_s:
            return 0.0, (
                f"the budget of {budget_s:g} s went to reading and detecting the image "
                f"({spent_s:.1f} s)"
            )
        budget_s -= spent_s
    if on_budget is not None:
        on_budget(budget_s)
    return budget_s, None


def _unsaid_fisheye(options: SolveOptions, pixels: np.ndarray) -> bool:
    """Whether an image solved with nothing said of its lens or field is a circular fisheye's:
    dark corners (``detect.circle.dark_corners``) around an image circle that is found (with
    a lens's sharp edge: ``detect.circle.LENS_EDGE_CONTRAST``)."""
    said = options.camera is not None or options.fov_deg is not None
    if said or options.fov_range_deg is not None or options.lens != "pinhole":
        return False
    if not dark_corners(pixels):
        return False
    return find_image_circle(pixels) is not None


def _diagnose(found: Detections, reason: str, options: SolveOptions) -> Failure:
    """Why the image was not solved (``pipeline.diagnose``), with the options it was solved
    with."""
    ranges = options.searched_ranges_deg
    searched = None if options.field_known else (min(ranges)[0], max(r[1] for r in ranges))
    return diagnose(
        found,
        reason,
        fov_range_deg=searched,
        threshold_sigma=options.threshold_sigma,
        lens=options.lens_model,
        fit_distortion=options.fit_distortion,
    )


def detection_binning(width: int, height: int) -> int:
    """The binning factor of an image's detection when none is given: the smallest k for
    which the binned image has at most ``AUTO_BIN_PIXELS`` pixels (1 up to 4.2 MP: a star
    camera's or a finder's frame is detected as it is; 2 for a 12-16 MP phone or camera
    photograph, 3 for 24 MP). sep's time grows with the pixels and with the sources above the
    threshold, and a 16 MP deep-sky stack holds 60 000 of them (10 s at full resolution,
    2 s binned 2 x 2); the 50 stars solved are among the brightest either way."""
    return max(1, math.ceil(math.sqrt(width * height / AUTO_BIN_PIXELS) - 1e-9))


def _detect_binned(pixels: np.ndarray, options: SolveOptions) -> Detections:
    """``detect_image`` on the image binned ``options.downsample`` x ``options.downsample``
    (``detection_binning`` when None; each block's mean, the last partial row and column of
    blocks dropped), in full-resolution pixels."""
    factor = options.downsample
    if factor is None:
        factor = detection_binning(pixels.shape[1], pixels.shape[0])
    detect = functools.partial(
        detect_image,
        lens=options.lens_model,
        threshold_sigma=options.threshold_sigma,
        max_stars=options.max_stars,
    )
    if factor == 1:
        return detect(pixels)
    height, width = (n // factor for n in pixels.shape)
    if min(height, width) < 16:
        raise ImageError(
            f"downsample {factor} leaves {width} x {height} px of a {pixels.shape[1]} x "
            f"{pixels.shape[0]} px image"
        )
    blocks = np.asarray(pixels[: height * factor, : width * factor], dtype=np.float32)
    binned = blocks.reshape(height, factor, width, factor).mean(axis=(1, 3))
    found = detect(binned)
    # a block's centre is its pixel's centre times the factor
    circle = found.circle
    if circle is not None:
        scaled = {name: getattr(circle, name) * factor for name in ("cx", "cy", "radius_px")}
        circle = replace(circle, **scaled)
    return replace(
        found, xy=found.xy * factor, width=pixels.shape[1], height=pixels.shape[0], circle=circle
    )


def _default_budget_s(options: SolveOptions, pixels: np.ndarray) -> float:
    """The default time budget (s) of an image's solve (``runtime.budget.default_budget_s``)."""
    height, width = pixels.shape
    if options.camera is not None:
        field_deg = options.camera.diagonal_deg
    else:
        fov = options.fov_deg
        field_deg = diagonal_fov_deg(fov, width, height) if fov else 0.0
    return default_budget_s(
        known=options.field_known, scan=options.scans_focal, field_deg=field_deg
    )


def _solve_hinted(
    xy, size, options: SolveOptions, hints: ImageHints, budget_s, position, prior, circle=None
):
    """The detections ``xy`` of an image of ``size`` (width, height px) solved
    (``pipeline.stars.solve_stars``) with the ``hints`` of a pinhole search: the position
    searched first (unless ``position`` is given); the FOV, when the default range is searched
    and the FOV lies within the pinhole's limits (``fov_limits_deg``: a telescope's 1.5° too),
    tried first and, if that fails, the whole range on what is left of the budget.
    ``circle``: a fisheye's image circle found in the image (``detect.circle``), where its
    focal scan starts."""
    if position is None and hints.ra_deg is not None and hints.dec_deg is not None:
        position = (hints.ra_deg, hints.dec_deg)
    width, height = size

    def solve(fov_deg, time_budget_s):
        return solve_stars(
            xy,
            replace(options, fov_deg=fov_deg, time_budget_s=time_budget_s),
            width=width,
            height=height,
            position_hint_deg=position,
            prior=prior,
            images=True,
            image_circle=circle,
        )

    hinted = None
    lo, hi = fov_limits_deg("pinhole", size)
    if options.fov_range_deg in (None, DEFAULT_FOV_RANGE_DEG) and hints.fov_deg:
        if lo <= hints.fov_deg <= hi:
            hinted = hints.fov_deg  # else ignored: outside what the search is for
    result = solve(options.fov_deg if hinted is None else hinted, budget_s)
    left_s = budget_s - result.time_ms / 1e3
    if result.solution is None and hinted is not None and left_s > 0:
        again = solve(None, left_s)  # the FOV may be wrong
        result = replace(
            again,
            reason=f"{again.reason} (and with the header's FOV {hinted:.3f}°: {result.reason})",
            time_ms=result.time_ms + again.time_ms,
        )
    return result


def detect_image(
    pixels: np.ndarray,
    *,
    lens: str = "pinhole",
    threshold_sigma: float = DEFAULT_THRESHOLD_SIGMA,
    max_stars: int | None = None,
) -> Detections:
    """The stars of an image array (row 0 at the top) as ``solve_image`` detects them:
    ``threshold_sigma`` over the background noise, the brightest ``max_stars`` (default
    ``DEFAULT_MAX_STARS``, ``FISHEYE_MAX_STARS`` for a fisheye). For a fisheye ``lens`` (any
    model but the pinhole) only in its sky (``starnav.detect.skymask``: inside the image
    circle found in the image, less the horizon's obstacles and glare, and the saturated pieces
    of glare and the pieces of trails among the stars: ``detect.stars.without_glare``,
    ``without_trails``); and when fewer than
    ``FEW_STARS_DEEPER`` stars are found there, again at each of ``DEEPER_THRESHOLDS_SIGMA``
    in turn while too few are found (a narrow filter, a short exposure, thin cloud: going
    deeper before refusing; those no brighter than the noise's peaks are dropped,
    ``_deeper``), an answer kept when it holds more. The ``Detections`` record the threshold
    used and the sky's share."""
    kind = model_class(lens).kind
    if max_stars is None:
        max_stars = DEFAULT_MAX_STARS if kind == "pinhole" else FISHEYE_MAX_STARS
    if kind != "fisheye":
        found = detect_stars(pixels, threshold_sigma=threshold_sigma, max_stars=max_stars)
        return replace(found, threshold_sigma=threshold_sigma)
    pixels, sky_fraction, circle = _outside_sky_masked(pixels)
    found = _sky_stars(pixels, threshold_sigma, max_stars)
    for deeper_sigma in DEEPER_THRESHOLDS_SIGMA:
        if len(found) >= FEW_STARS_DEEPER or deeper_sigma >= threshold_sigma:
            continue
        deeper = _deeper(pixels, deeper_sigma, max_stars)
        if len(deeper) > len(found):
            found, threshold_sigma = deeper, deeper_sigma
    return replace(found, threshold_sigma=threshold_sigma, sky_fraction=sky_fraction, circle=circle)


def _deeper(pixels: np.ndarray, threshold_sigma: float, max_stars: int) -> Detections:
    """The stars found at ``threshold_sigma`` that are brighter (in SNR) than every source
    found in the negated image, which are noise: noise is symmetric, stars are not (3 sigma
    finds 15-25 noise peaks of SNR up to ~6.6 in a 512 px all-sky frame of pure noise, 4 and
    5 sigma none)."""
    deeper = _sky_stars(pixels, threshold_sigma, max_stars)
    noise = detect_stars(-pixels, threshold_sigma=threshold_sigma, max_stars=max_stars)
    return deeper.kept(deeper.saturated | (deeper.snr > (noise.snr.max() if len(noise) else 0.0)))


def _sky_stars(pixels: np.ndarray, threshold_sigma: float, max_stars: int) -> Detections:
    """An all-sky frame's stars at ``threshold_sigma``: ``detect_stars`` less the pieces of
    glare and of trails (``detect.stars.without_glare``, ``without_trails``)."""
    found = detect_stars(pixels, threshold_sigma=threshold_sigma, max_stars=max_stars)
    return without_trails(without_glare(found))


def _outside_sky_masked(pixels: np.ndarray) -> tuple[np.ndarray, float, ImageCircle | None]:
    """A fisheye's pixels with those outside its sky (``starnav.detect.skymask``: outside the
    image circle shrunk by 1 % of its radius, the rim being lit horizon; the horizon's
    obstacles; glare) set to NaN, which detection masks, the share of the pixels left and
    the image circle (without one, the disc the sky left suggests, ``SkyMask.lit_disc``;
    None: neither); the pixels unchanged when nothing is masked (a full-frame fisheye of a
    clear sky)."""
    sky = find_sky_mask(pixels)
    if not sky.excluded.any():
        return pixels, 1.0, sky.circle
    masked = np.array(pixels, dtype=np.float32)
    masked[sky.excluded] = np.nan
    return masked, sky.sky, sky.circle or sky.lit_disc()


def annotate_result(path_out: str | Path, image: np.ndarray, result: ImageSolveResult) -> None:
    """Draw an image into a PNG. Solved: detections, catalog stars, ids, names of bright stars
    and the residuals (``starnav.output.annotate``), in square pixels when the image's are
    not (``square_pixels``); not solved: the detections by rank and the reason
    (``starnav.output.annotate.unsolved_figure``)."""
    from starnav.output.annotate import save_figure, unsolved_figure

    s, cam, cat = result.solution, result.camera, result.catalog
    if s is None or cam is None or cat is None:
        det = result.detections
        lines = [
            f"not solved: {result.reason}",
            f"{len(det.xy)} stars detected ({det.n_saturated} saturated, {det.n_hot} hot "
            f"pixels removed), PSF sigma {det.psf_sigma_px:.2f} px, background rms "
            f"{det.background_rms:.3g}; detect {result.detect_ms:.0f} ms, solve "
            f"{result.solve_ms:.0f} ms",
        ]
        used = min(len(det.xy), DEFAULT_PATTERN_STARS)
        save_figure(unsolved_figure(image, detected_xy=det.xy, used=used, lines=lines), path_out)
        return
    det = result.detections
    if s.pixel_aspect != 1.0:  # drawn in the square pixels it was solved in
        image = square_pixels(image, s.pixel_aspect)[0]
        s, det = _rows_scaled(s, det, s.pixel_aspect)
    annotate_solution(path_out, image, det.xy, s, cam, cat)


def annotate_solution(
    path_out: str | Path,
    image: np.ndarray,
    detected_xy: np.ndarray,
    s: Solution,
    cam: CameraModel,
    cat: Catalog,
) -> None:
    """Draw a solution on an image into a PNG: the ``detected_xy`` (px), the catalog stars of
    the field, ids, names of bright stars and the residuals (``starnav.output.annotate``)."""
    from starnav.output.annotate import annotate_image

    matched = [m for m in s.stars if m.catalog_id is not None]
    rows = cat.rows([m.catalog_id for m in matched])
    xy = np.array([(m.x, m.y) for m in matched]).reshape(-1, 2)
    projected = cam.bearings_to_pixels(cat.vectors[rows] @ s.R_cam_from_icrs.T)
    annotate_image(
        path_out,
        image,
        detected_xy=detected_xy,
        R_cam_from_icrs=s.R_cam_from_icrs,
        camera=cam,
        catalog=cat,
        matched=np.column_stack([xy, cat.ids[rows], projected - xy]),
        title=(
            f"rms {s.rms_px:.2f} px, false-match probability {s.false_match_probability:.1e}"
            + "".join(f", {k} {getattr(s, k):.4f}" for k in cam.coefficients)
        ),
    )


def write_outputs(
    paths: Mapping[str, Path | None],
    source: str | Path | None,
    pixels: np.ndarray,
    result: ImageSolveResult,
    wcs=None,
) -> dict[str, str]:
    """Write what ``paths`` asks for (a kind's path None: not written): "wcs", a FITS WCS
    header fitted to the matched stars (``fitted_wcs``; solved only; ``wcs``: that WCS, when the
    caller has it already); "new_fits", the image as FITS with that WCS in its header, like
    astrometry.net's ``.new`` (solved only; a FITS ``source`` keeps its own 2-D data and header
    cards, others get the luminance that was solved); "annotate", the picture
    (``annotate_result``, solved or not). Returns the paths written, by kind."""
    written: dict[str, str] = {}
    s = result.solution
    if s is not None and (paths.get("wcs") or paths.get("new_fits")):
        from starnav.output.wcs import write_wcs

        if wcs is None:
            wcs = fitted_wcs(s, result.catalog, detections_xy=result.detections.xy, pixels=pixels)
        if paths.get("wcs"):
            write_wcs(paths["wcs"], wcs)
            written["wcs"] = str(paths["wcs"])
        if paths.get("new_fits"):
            data, header = _source_fits(source, pixels)
            write_wcs(paths["new_fits"], wcs, image=data, extra_header=header)
            written["new_fits"] = str(paths["new_fits"])
    if paths.get("annotate"):
        annotate_result(paths["annotate"], pixels, result)
        written["annotate"] = str(paths["annotate"])
    return written


def solution_wcs(R_cam_from_icrs: np.ndarray, camera: CameraModel):
    """The WCS (astropy) written for a solved image: the fitted camera's projection
    (``starnav.output.wcs.wcs_from_attitude``), with SIP polynomials of the order
    ``choose_sip_order`` picks for its distortion (TAN without distortion). Its CRPIX is the
    principal point, the image centre unless a camera file says otherwise."""
    from starnav.output.wcs import choose_sip_order, wcs_from_attitude

    return wcs_from_attitude(R_cam_from_icrs, camera, sip_order=choose_sip_order(camera))


def fitted_wcs(
    solution: Solution,
    catalog: Catalog | None,
    *,
    crpix_px=None,
    detections_xy: np.ndarray | None = None,
    pixels: np.ndarray | None = None,
):
    """The WCS (astropy) written for a solved image: TAN-SIP fitted to the matched stars
    (``starnav.output.wcs.fit_wcs_to_stars``: the order its F-tests find measurable) when the
    camera is a pinhole without distortion terms of its own and either SIP terms are
    measurable, ``crpix_px`` (starnav px) asks for a reference pixel away from the principal
    point or the pixels are not square (``Solution.pixel_aspect``); else the camera's own
    (``solution_wcs``: the attitude's TAN, or the lens model's projection and SIP), through
    a grid of its pixels when they are not square. The matched stars are looked up in
    ``catalog`` (those it lacks are left out of the fit). Given the image's ``detections_xy``
    (starnav px; with ``pixels``, the image, detected again to ``WCS_MAX_STARS`` when they are
    fewer), the TAN-SIP fit is made again on every detection the embedded Gaia catalog (or
    ``catalog``, where it holds more stars) explains (``starnav.output.tweak.deep_fit``):
    when it pairs more stars than the solve matched, that fit is the WCS, whatever its order."""
    from starnav.output.wcs import STAR_FIT_MAX_ORDER, fit_points, fit_wcs_to_stars

    camera, aspect = solution.camera, solution.pixel_aspect
    principal = (camera.cx, camera.cy / aspect)  # in the image's pixels
    crpix = principal if crpix_px is None else crpix_px
    own = getattr(camera, "fits_projection", "") != "TAN" or camera.distorted
    table = solution.star_table
    matched = table.catalog_id >= 0
    rows = np.full(0, -1)
    if catalog is not None and not own:
        rows = catalog.rows(table.catalog_id[matched], missing=-1)
    found = rows >= 0
    if found.sum() >= 3:
        try:
            fit = fit_wcs_to_stars(table.xy[matched][found], catalog.vectors[rows[found]],
                                   camera.width, round(camera.height / aspect), crpix_px=crpix,
                                   start=solution.R_cam_from_icrs[2])  # fmt: skip
        except StarnavError:  # stars on a line: the attitude's own WCS still holds
            fit = None
        deep = None
        if fit is not None and detections_xy is not None:
            from starnav.output.tweak import deep_fit

            if pixels is not None and len(detections_xy) < WCS_MAX_STARS:
                detections_xy = _detect_binned(pixels, SolveOptions(max_stars=WCS_MAX_STARS)).xy
            catalogs = (catalog, load_catalog(GAIA))
            deep = deep_fit(fit, detections_xy, catalogs, camera.width,
                            round(camera.height / aspect), crpix_px=crpix)  # fmt: skip
        if deep is not None:
            return deep.wcs
        away = not np.allclose(crpix, principal)
        if fit is not None and (fit.order > 1 or aspect != 1.0 or away):
            return fit.wcs
    if aspect == 1.0:
        return solution_wcs(solution.R_cam_from_icrs, camera)
    grid = fit_points(camera)  # the camera's own projection, through its pixels
    vectors = camera.pixels_to_bearings(grid) @ solution.R_cam_from_icrs  # in ICRS
    order = STAR_FIT_MAX_ORDER if camera.distorted else 1
    return fit_wcs_to_stars(grid / (1.0, aspect), vectors, camera.width,
                            round(camera.height / aspect), crpix_px=crpix,
                            start=solution.R_cam_from_icrs[2], max_order=order).wcs  # fmt: skip


def _source_fits(source: str | Path | None, pixels: np.ndarray):
    """The data and header of a FITS ``source``'s first 2-D image of the solved shape (row 0
    first, as ``read_image`` takes it), else the solved luminance ``pixels`` and no header."""
    if source is not None and is_fits(source):
        from astropy.io import fits

        with fits.open(source, memmap=False) as hdul:
            for hdu in hdul:
                data = hdu.data if hdu.header.get("NAXIS") == 2 else None
                if data is not None and data.shape == pixels.shape:
                    return np.array(data), hdu.header.copy()
    return pixels, None
