"""From an image (file or array) to a verified attitude.

``solve_image`` reads the file (``starnav.detect.read``), finds and centroids the stars
(``starnav.detect.stars``) and solves them with the field of view unknown, roughly known or
calibrated (``starnav.fov``). A camera file (JSON, written by ``starnav calibrate``) holds a
calibrated camera: size, focal length, principal point and radial distortion.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from starnav.budget import check_budget, default_budget_s
from starnav.camera import CameraModel, load_camera
from starnav.catalog import Catalog
from starnav.detect.circle import find_image_circle
from starnav.detect.header import ImageHints, fits_hints, is_fits
from starnav.detect.read import read_image
from starnav.detect.stars import Detections, detect_stars
from starnav.errors import CameraError, ImageError, shown
from starnav.fov import (
    DEFAULT_FOV_RANGE_DEG,
    DEFAULT_PATTERN_STARS,
    diagonal_fov_deg,
    search_range,
    solve_fov,
)
from starnav.results import Solution

DEFAULT_MAX_STARS = 50
NO_HINTS = ImageHints()
FISHEYE_MAX_STARS = 100  # a whole sky's brightest detections hold horizon lights and glow
DEFAULT_THRESHOLD_SIGMA = 5.0  # detection threshold over the background noise
MIN_DETECTIONS = 4  # fewer detected stars than this: not solved, without a search


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

    @property
    def total_ms(self) -> float:
        """Detection and solve (ms): from the decoded image to the attitude."""
        return self.detect_ms + self.solve_ms

    def to_dict(self, file: str | None = None) -> dict:
        """The JSON of the solve (``starnav.results.solve_dict``; the stars are the detections,
        brightest first) with the image ``file``, its size, the fitted principal point and
        distortion (null when unsolved), ``n_detected`` and the times (ms)."""
        from starnav.results import solve_dict

        det, cam = self.detections, self.camera
        out = solve_dict(self.solution, self.reason, self.solve_ms, None, det.xy)
        out.update(
            file=file,
            width=det.width,
            height=det.height,
            cx=cam.cx if cam else None,
            cy=cam.cy if cam else None,
            **{k: getattr(self.solution, k) if cam else None for k in ("k1", "k2", "k3", "k4")},
            n_detected=len(det.xy),
            hints=self.hints.to_dict() if self.hints.sources else None,
            read_ms=self.read_ms,
            detect_ms=self.detect_ms,
            solve_ms=self.solve_ms,
        )
        return out


def solve_image(
    image: str | Path | np.ndarray,
    *,
    fov_deg: float | None = None,
    fov_range_deg: tuple[float, float] = DEFAULT_FOV_RANGE_DEG,
    camera: CameraModel | str | Path | None = None,
    lens: str = "pinhole",
    fit_distortion: bool = False,
    max_stars: int | None = None,
    threshold_sigma: float = DEFAULT_THRESHOLD_SIGMA,
    sigma_px: float | None = None,
    catalog: Catalog | str | Path | None = None,
    epoch_year: float | None = None,
    parity: int | None = None,
    hints: ImageHints | None = None,
    time_budget_s: float | None = None,
    downsample: int = 1,
    **options,
) -> ImageSolveResult:
    """Solve an image file (FITS, PNG, JPEG, TIFF) or a 2-D array (row 0 at the top).

    The field of view is searched within ``fov_range_deg`` (horizontal, degrees) unless
    ``fov_deg`` (searched within 5 %) or a calibrated ``camera`` (a camera model or a camera
    file; within 1 %) is given; the fitted one is reported either way. ``lens``: the lens
    model when no camera is given (``starnav.camera.MODELS``; a fisheye model's focal length
    is scanned, see ``starnav.fov.scan_focal``). ``max_stars``: the brightest this many
    detections are used (default ``DEFAULT_MAX_STARS``, for a fisheye ``FISHEYE_MAX_STARS``);
    ``threshold_sigma``: detection threshold over the background noise; ``sigma_px``:
    centroid 1-sigma (px; None: unknown). With a fisheye lens (any model but
    the pinhole), detections outside the image circle found in the image
    (``starnav.detect.circle``) are not made: the dark frame around an all-sky camera's disc
    often holds burned-in text. ``hints``: what the file's header says
    (``starnav.detect.header.fits_hints``; read from a FITS file when None, none for an
    array): its FOV is searched (±5 %) when neither ``fov_deg``, ``camera`` nor another
    ``fov_range_deg`` is given and it lies within the default range, its epoch used when
    ``epoch_year`` is not, its position searched first; a solve that fails with the hinted
    FOV is tried again without it. ``time_budget_s``: the solve's (``starnav.budget``;
    detection is not counted). ``downsample``: stars detected on the image binned by this
    factor, solved at full resolution. Other keywords: see ``starnav.fov.solve_fov``.
    """
    camera = load_camera(camera) if isinstance(camera, str | Path) else camera
    search_range(fov_deg, fov_range_deg, camera, lens)  # a bad range fails before any work
    bad = isinstance(max_stars, bool) or not (isinstance(max_stars, int) and max_stars >= 4)
    if max_stars is not None and bad:
        raise ImageError(f"max_stars must be an integer >= 4, got {shown(max_stars)}")
    lens = camera.model if camera is not None else lens
    check_budget(time_budget_s, 1.0)  # a bad budget fails before any work
    t0 = time.perf_counter()
    if isinstance(image, np.ndarray):
        pixels, read_ms = image, 0.0
        if pixels.ndim != 2 or pixels.size == 0:
            raise ImageError(f"an image array must be 2-D and not empty, got shape {image.shape}")
    else:
        pixels = read_image(image)
        read_ms = (time.perf_counter() - t0) * 1e3
        if hints is None:
            hints = fits_hints(image)
    hints = hints or NO_HINTS
    height, width = pixels.shape
    if camera is not None and (camera.width, camera.height) != (width, height):
        raise CameraError(
            f"the camera file is for {camera.width} x {camera.height} px images, this image is "
            f"{width} x {height} px"
        )
    budget_s = check_budget(time_budget_s, _default_budget_s(camera, fov_deg, lens, pixels))
    t1 = time.perf_counter()
    found = _detect_binned(pixels, downsample, lens, threshold_sigma, max_stars)
    detect_ms = (time.perf_counter() - t1) * 1e3
    if len(found.xy) < MIN_DETECTIONS:
        reason = f"{len(found.xy)} stars detected, at least {MIN_DETECTIONS} are needed"
        return ImageSolveResult(None, reason, found, None, read_ms, detect_ms, 0.0, hints=hints)
    solve = functools.partial(
        solve_fov,
        found.xy,
        width=width,
        height=height,
        fov_range_deg=fov_range_deg,
        camera=camera,
        lens=lens,
        fit_distortion=fit_distortion,
        sigma_px=sigma_px,
        catalog=catalog,
        epoch_year=epoch_year if epoch_year is not None else hints.epoch_year,
        parity=parity,
    )
    searched = fov_deg is None and camera is None and lens == "pinhole"
    result = _solve_hinted(solve, hints if searched else NO_HINTS, fov_deg, fov_range_deg,
                           budget_s, options)  # fmt: skip
    sol = result.solution
    return ImageSolveResult(
        sol,
        result.reason,
        found,
        None if sol is None else sol.camera,
        read_ms,
        detect_ms,
        result.time_ms,
        result.database.catalog,
        hints,
    )


def _detect_binned(pixels, factor, lens, threshold_sigma, max_stars) -> Detections:
    """``detect_image`` on the image binned ``factor`` x ``factor`` (each block's mean; the
    last partial row and column of blocks dropped), in full-resolution pixels."""
    if isinstance(factor, bool) or not (isinstance(factor, int) and factor >= 1):
        raise ImageError(f"downsample must be an integer >= 1, got {shown(factor)}")
    if factor == 1:
        return detect_image(pixels, lens=lens, threshold_sigma=threshold_sigma,
                            max_stars=max_stars)  # fmt: skip
    height, width = (n // factor for n in pixels.shape)
    if min(height, width) < 16:
        raise ImageError(
            f"downsample {factor} leaves {width} x {height} px of a {pixels.shape[1]} x "
            f"{pixels.shape[0]} px image"
        )
    blocks = np.asarray(pixels[: height * factor, : width * factor], dtype=np.float32)
    binned = blocks.reshape(height, factor, width, factor).mean(axis=(1, 3))
    found = detect_image(binned, lens=lens, threshold_sigma=threshold_sigma, max_stars=max_stars)
    # a block's centre is its pixel's centre times the factor
    return replace(found, xy=found.xy * factor, width=pixels.shape[1], height=pixels.shape[0])


def _default_budget_s(camera, fov_deg, lens: str, pixels: np.ndarray) -> float:
    """The default time budget (s) of an image's solve (``starnav.budget.default_budget_s``)."""
    height, width = pixels.shape
    if camera is not None:
        field_deg = camera.diagonal_deg
    else:
        field_deg = diagonal_fov_deg(fov_deg, width, height) if fov_deg else 0.0
    known = camera is not None or fov_deg is not None
    return default_budget_s(known=known, scan=lens != "pinhole", field_deg=field_deg)


def _solve_hinted(solve, hints: ImageHints, fov_deg, fov_range_deg, budget_s: float, options):
    """``solve`` (``solve_fov`` of the detections) with the ``hints`` of a pinhole search:
    the position searched first; the FOV, when in the default range searched, tried first
    and, if that fails, the whole range on what is left of the budget."""
    options = dict(options)
    if hints.ra_deg is not None and hints.dec_deg is not None:
        options.setdefault("position_hint_deg", (hints.ra_deg, hints.dec_deg))
    hinted = None
    lo, hi = DEFAULT_FOV_RANGE_DEG
    if (
        tuple(fov_range_deg) == DEFAULT_FOV_RANGE_DEG
        and hints.fov_deg
        and lo <= hints.fov_deg <= hi
    ):
        hinted = hints.fov_deg  # else ignored: outside what the search is for
    result = solve(fov_deg=fov_deg if hinted is None else hinted, time_budget_s=budget_s, **options)
    left_s = budget_s - result.time_ms / 1e3
    if result.solution is None and hinted is not None and left_s > 0:
        again = solve(fov_deg=None, time_budget_s=left_s, **options)  # the FOV may be wrong
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
    """The stars of an image array (row 0 at the top) as ``solve_image`` detects them: for a
    fisheye ``lens`` (any model but the pinhole) only inside the image circle found in the
    image; ``threshold_sigma`` over the background noise, the brightest ``max_stars``
    (default ``DEFAULT_MAX_STARS``, ``FISHEYE_MAX_STARS`` for a fisheye)."""
    if lens != "pinhole":
        pixels = _outside_circle_masked(pixels)
    if max_stars is None:
        max_stars = DEFAULT_MAX_STARS if lens == "pinhole" else FISHEYE_MAX_STARS
    return detect_stars(pixels, threshold_sigma=threshold_sigma, max_stars=max_stars)


def _outside_circle_masked(pixels: np.ndarray) -> np.ndarray:
    """A fisheye's pixels with those outside its image circle (``starnav.detect.circle``,
    shrunk by 1 % of its radius: the rim is lit horizon) set to NaN, which detection masks;
    the pixels unchanged when no circle is found (a full-frame fisheye)."""
    circle = find_image_circle(pixels)
    if circle is None:
        return pixels
    height, width = pixels.shape
    masked = np.array(pixels, dtype=np.float32)
    masked[circle.outside(width, height, margin_px=0.01 * circle.radius_px)] = np.nan
    return masked


def annotate_result(path_out: str | Path, image: np.ndarray, result: ImageSolveResult) -> None:
    """Draw an image into a PNG. Solved: detections, catalog stars, ids, names of bright stars
    and the residuals (``starnav.annotate``); not solved: the detections by rank and the
    reason (``starnav.annotate.unsolved_figure``)."""
    from starnav.annotate import save_figure, unsolved_figure

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
    annotate_solution(path_out, image, result.detections.xy, s, cam, cat)


def annotate_solution(
    path_out: str | Path,
    image: np.ndarray,
    detected_xy: np.ndarray,
    s: Solution,
    cam: CameraModel,
    cat: Catalog,
) -> None:
    """Draw a solution on an image into a PNG: the ``detected_xy`` (px), the catalog stars of
    the field, ids, names of bright stars and the residuals (``starnav.annotate``)."""
    from starnav.annotate import annotate_image

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
    header of the fitted camera (``solution_wcs``; solved only; ``wcs``: that WCS, when the
    caller has it already); "new_fits", the image as FITS with that WCS in its header, like
    astrometry.net's ``.new`` (solved only; a FITS ``source`` keeps its own 2-D data and header
    cards, others get the luminance that was solved); "annotate", the picture
    (``annotate_result``, solved or not). Returns the paths written, by kind."""
    written: dict[str, str] = {}
    s = result.solution
    if s is not None and (paths.get("wcs") or paths.get("new_fits")):
        from starnav.wcs import write_wcs

        if wcs is None:
            wcs = solution_wcs(s.R_cam_from_icrs, result.camera)
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
    (``starnav.wcs.wcs_from_attitude``), with SIP polynomials of the order
    ``choose_sip_order`` picks for its distortion (TAN without distortion). Its CRPIX is the
    principal point, the image centre unless a camera file says otherwise."""
    from starnav.wcs import choose_sip_order, wcs_from_attitude

    return wcs_from_attitude(R_cam_from_icrs, camera, sip_order=choose_sip_order(camera))


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
