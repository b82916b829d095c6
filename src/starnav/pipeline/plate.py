"""Plate solving in astrometry.net's and ASTAP's terms: their hints in, their numbers out.

Astronomy software drives a plate solver through astrometry.net's web API (nova), its
``solve-field`` command line or ASTAP's. They all speak of an image in FITS pixels (1-based,
the first pixel's centre at (1, 1)) and describe a solution by its WCS. Ours has no flip: row 0
of the array is FITS y = 1 (``output.wcs``), exactly as solve-field numbers the rows of a JPEG
or PNG, so a point's FITS pixel is ours + 0.5 and the WCS is the one either tool would write.

``PlateHints`` collects what a client may say of an image (the scale in any of astrometry.net's
units, a position and radius, the parity, a downsampling factor, the centroid error, the
reference pixel at the centre); ``solve_plate`` solves an image file or an x, y list with them;
``Plate`` is the answer in their terms: field centre, radius, pixel scale, the orientation
("up is X degrees E of N") and parity (nova's +1: det CD >= 0, solve-field's "neg") computed
from the CD matrix with astrometry.net's own formulas (``net/wcs.py``: ``get_orientation``,
``get_parity``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from astropy.wcs import WCS

from starnav.catalog import Catalog
from starnav.detect.header import fits_hints, is_fits
from starnav.detect.read import MAX_PIXELS, primary_fits_header
from starnav.errors import StarnavError, shown
from starnav.pipeline.fov import FOV_LIMITS_DEG, fov_limits_deg
from starnav.pipeline.image import (
    ImageSolveResult,
    annotate_solution,
    fitted_wcs,
    solve_image,
    write_outputs,
)
from starnav.pipeline.options import DEFAULT_FOV_RANGE_DEG, DEFAULT_PATTERN_STARS, SolveOptions
from starnav.pipeline.stars import solve_stars
from starnav.pipeline.unordered import uniform_order
from starnav.results import Solution, SolveResult
from starnav.runtime.budget import Deadline, check_budget, default_budget_s

SCALE_UNITS = ("degwidth", "arcminwidth", "arcsecperpix", "focalmm")
FULL_FRAME_WIDTH_MM = 36.0  # "focalmm" is the focal length of a 35 mm camera's 36 mm width
DEFAULT_POSITION_RADIUS_DEG = 10.0  # a position given without a radius (as fov.py's hint)


@dataclass(frozen=True)
class PlateHints:
    """What a client tells of an image, in starnav's terms.

    ``fov_range_deg``: (low, high) horizontal field of view, degrees (None: starnav's default
    range); ``ra_deg``, ``dec_deg``, ``radius_deg``: the boresight lies within ``radius_deg``
    of this position (searched first, then the whole sky); ``parity``: starnav's (+1: the sky
    as seen with y down, astrometry.net's "neg"; None: both); ``downsample``: stars detected on
    the image binned by this factor (None: to at most 4.2 MP); ``positional_error_px``:
    centroid 1-sigma (px; None: 1); ``crpix_center``: the WCS's reference pixel at the image
    centre (always so unless ``crpix_fits`` says otherwise: a plate solve has no camera file,
    so the principal point is the centre); ``crpix_fits``: the WCS's reference pixel (FITS
    pixels, 1-based, as solve-field's ``--crpix-x``/``--crpix-y``; None: the centre);
    ``max_false_match_probability``: accept an answer only as sure as this (None: starnav's
    default; solve-field's ``--odds-to-solve``).
    """

    fov_range_deg: tuple[float, float] | None = None
    ra_deg: float | None = None
    dec_deg: float | None = None
    radius_deg: float | None = None
    parity: int | None = None
    downsample: int | None = None
    positional_error_px: float | None = None
    crpix_center: bool = False
    crpix_fits: tuple[float, float] | None = None
    max_false_match_probability: float | None = None


def width_deg_from_scale(units: str, value: float, width_px: float) -> float:
    """The image width (degrees) a scale ``value`` in astrometry.net's ``units`` says:
    "degwidth", "arcminwidth", "arcsecperpix" (times ``width_px``) or "focalmm" (the focal
    length, mm, of a 35 mm camera: 36 mm wide)."""
    if units not in SCALE_UNITS:
        raise StarnavError(f"unknown scale units {units!r}; known: {', '.join(SCALE_UNITS)}")
    value = _positive(value, "scale")
    if units == "degwidth":
        return value
    if units == "arcminwidth":
        return value / 60.0
    if units == "arcsecperpix":
        return value * width_px / 3600.0
    return math.degrees(2.0 * math.atan(FULL_FRAME_WIDTH_MM / (2.0 * value)))


def fov_range_from_scale(
    units: str, lower: float, upper: float, width_px: float, height_px: float | None = None
) -> tuple[float, float]:
    """The horizontal FOV range (degrees) of a scale range (``width_deg_from_scale``), clipped
    to where starnav searches: the default range when the scale range holds all of it (a
    client's catch-all 0.1-180° searches what the default search does), else the part inside
    the pinhole's limits for an image ``width_px`` x ``height_px`` (``fov_limits_deg``: a
    portrait image may be narrower across; a 4.3-5.3° hint is searched whole, not cut at the
    default's 5°). ``StarnavError`` when nothing is left."""
    ends = sorted(width_deg_from_scale(units, v, width_px) for v in (lower, upper))
    if ends[0] <= DEFAULT_FOV_RANGE_DEG[0] and ends[1] >= DEFAULT_FOV_RANGE_DEG[1]:
        return DEFAULT_FOV_RANGE_DEG
    shape = None if height_px is None else (width_px, height_px)
    lo, hi = fov_limits_deg("pinhole", shape)
    clipped = (max(ends[0], lo), min(ends[1], hi))
    if clipped[0] <= clipped[1]:
        if clipped[0] == clipped[1]:  # one value: search around it, within the limits
            clipped = (max(clipped[0] * 0.95, lo), min(clipped[1] * 1.05, hi))
        return clipped
    raise StarnavError(
        f"the scale range {ends[0]:.3g}-{ends[1]:.3g}° wide is outside the fields starnav "
        f"solves ({lo:.3g}-{hi:g}° wide{' for this image' if shape else ''}; "
        f"{FOV_LIMITS_DEG[0]:g}° at least along the longer side)"
    )


def scale_bounds(est: float, err_percent: float) -> tuple[float, float]:
    """astrometry.net's "ev" scale type: the estimate ± ``err_percent`` %."""
    est, err = _positive(est, "scale_est"), _positive(err_percent, "scale_err")
    return est * (1.0 - err / 100.0), est * (1.0 + err / 100.0)


def ra_deg_from_text(text: str) -> float:
    """Right ascension (degrees, [0, 360)) of solve-field's ``--ra``: degrees, or sexagesimal
    hours "HH:MM:SS.S" (``util/starutil.c``, ``atora``). ``StarnavError`` else."""
    return _angle_from_text(text, "RA", "hourangle") % 360.0


def dec_deg_from_text(text: str) -> float:
    """Declination (degrees) of solve-field's ``--dec``: degrees, or sexagesimal
    "[+-]DD:MM:SS.S" (``util/starutil.c``, ``atodec``). ``StarnavError`` else, or outside ±90°."""
    dec = _angle_from_text(text, "Dec", "deg")
    if not -90.0 <= dec <= 90.0:
        raise StarnavError(f"Dec must be within ±90°, got {text!r}")
    return dec


def _angle_from_text(text: str, what: str, sexagesimal_unit: str) -> float:
    value = str(text).strip()
    try:
        if ":" in value:  # the form astrometry.net's regex takes; astropy does the arithmetic
            from astropy.coordinates import Angle

            deg = float(Angle(value, unit=sexagesimal_unit).degree)
        else:
            deg = float(value)
    except ValueError:
        raise StarnavError(f"{what} must be degrees or sexagesimal, got {text!r}") from None
    if not math.isfinite(deg):
        raise StarnavError(f"{what} must be a finite number, got {text!r}")
    return deg


def _positive(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise StarnavError(f"{what} must be a number, got {shown(value)}") from None
    if not (math.isfinite(v) and v > 0):
        raise StarnavError(f"{what} must be a positive number, got {shown(value)}")
    return v


# a source list's brightness columns when none is named (``read_xylist``), in this order:
# (name, ascending); astrometry.net's image2xy writes FLUX, SExtractor FLUX_AUTO / MAG_AUTO
BRIGHTNESS_COLUMNS = (("FLUX", False), ("FLUX_AUTO", False), ("FLUX_ISO", False),
                      ("FLUX_APER", False), ("MAG_AUTO", True), ("MAG_ISO", True),
                      ("MAG_APER", True), ("MAG", True))  # fmt: skip
# a list whose consecutive rows step the same way in y (or x) this often was written in
# detection order (a scan of the image), not by brightness
DETECTION_ORDER_FRACTION = 0.9
# a list with no brightness column in no detection order is solved brightest first for this
# share of the time budget, then without brightness (``_solve_list``)
GIVEN_ORDER_SHARE = 0.3
UNRANKED_WHY = {False: "the list is in detection order with no brightness column",
                True: "the list has no brightness column"}  # fmt: skip


@dataclass(frozen=True)
class XYList:
    """A source list: FITS pixel coordinates (1-based) of stars in an image ``width`` x
    ``height`` px (astrometry.net's xylist). ``ordered``: whether the rows are brightest first
    (sorted by a brightness column, or given so; with no column that is not known); when
    False (detection order) the solve weighs no brightness (``pipeline.unordered``).
    ``sorted_by``: the column the rows were sorted by (None: as given; ``_solve_list``)."""

    x: np.ndarray
    y: np.ndarray
    width: int
    height: int
    ordered: bool = True
    sorted_by: str | None = None

    @classmethod
    def make(
        cls,
        x: Sequence[float],
        y: Sequence[float],
        width,
        height,
        *,
        sort_values: Sequence[float] | None = None,
        ascending: bool = False,
        sort_name: str | None = None,
    ) -> XYList:
        """Checked: same lengths, finite numbers, a positive size. ``StarnavError`` else.
        ``sort_values``: a brightness per row (a flux, largest first, or with ``ascending`` a
        magnitude, smallest first; NaN last), the rows are sorted by it (stable), named
        ``sort_name``; None: the rows stay as given, taken as brightest first unless they
        are in detection order (``in_detection_order``)."""
        try:
            xs, ys = (np.asarray([float(v) for v in a], dtype=float) for a in (x, y))
        except (TypeError, ValueError):
            raise StarnavError("x and y must be lists of numbers") from None
        if len(xs) != len(ys):
            raise StarnavError(f"x and y differ in length ({len(xs)} and {len(ys)})")
        if not (np.isfinite(xs).all() and np.isfinite(ys).all()):
            raise StarnavError("x and y must be finite numbers")
        w, h = (int(_positive(v, what)) for v, what in ((width, "image_width"),
                                                        (height, "image_height")))  # fmt: skip
        if sort_values is None:
            return cls(xs, ys, w, h, ordered=not in_detection_order(xs, ys))
        order = brightness_order(sort_values, ascending=ascending, count=len(xs))
        return cls(xs[order], ys[order], w, h, ordered=True, sorted_by=sort_name or "brightness")

    @property
    def xy(self) -> np.ndarray:
        """Our pixel coordinates (top-left corner origin): FITS - 0.5."""
        return np.column_stack([self.x, self.y]) - 0.5

    def solve_order(self) -> np.ndarray:
        """The rows in the order they are solved: as they are when ordered by brightness,
        else spread over the image (``uniform_order``)."""
        if self.ordered:
            return np.arange(len(self.x))
        return uniform_order(self.xy, self.width, self.height)


def brightness_order(values: Sequence[float], *, ascending: bool, count: int) -> np.ndarray:
    """Rows brightest first by a column's ``values`` (descending, as solve-field sorts a flux;
    ``ascending`` for a magnitude); rows whose value is not a number go last, in their order.
    ``StarnavError`` for a column of another length or not of numbers."""
    try:
        v = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise StarnavError("the sort column must hold numbers") from None
    if len(v) != count:
        raise StarnavError(f"the sort column has {len(v)} values for {count} sources")
    key = np.where(np.isfinite(v), v if ascending else -v, np.inf)
    return np.argsort(key, kind="stable")


def in_detection_order(x: np.ndarray, y: np.ndarray) -> bool:
    """Whether a list's rows were written in detection order, as image2xy and SExtractor
    write them (a scan of the image: y, or x, steps one way from row to row at least
    ``DETECTION_ORDER_FRACTION`` of the time), rather than by brightness."""
    if len(x) < 8:
        return False
    for v in (y, x):
        steps = np.diff(v)
        if max((steps >= 0).mean(), (steps <= 0).mean()) >= DETECTION_ORDER_FRACTION:
            return True
    return False


def read_xylist(
    path: str | Path,
    *,
    x_column: str = "X",
    y_column: str = "Y",
    sort_column: str | None = None,
    sort_ascending: bool = False,
    width: int | None = None,
    height: int | None = None,
    max_sources: int | None = None,
) -> XYList | None:
    """The source list of an xylist file: a FITS file whose primary HDU holds no image and
    whose first table has the ``x_column``, ``y_column`` columns (FITS pixels; names in any
    case); None for anything else (an image). Sorted by ``sort_column`` (descending, or
    ``sort_ascending``) when named (``StarnavError`` when the table lacks it), else by the
    first of ``BRIGHTNESS_COLUMNS`` it has, else as given (``XYList.make``). The size:
    ``width``, ``height``, else the header's IMAGEW, IMAGEH, else the largest x, y rounded up.
    ``max_sources``: only the first (brightest) this many (solve-field's ``--objs``)."""
    path = Path(path)
    if not is_fits(path):
        return None
    primary = primary_fits_header(path)  # an image's: no list (astropy would inflate a .gz)
    if primary is not None and str(primary.get("NAXIS", 0)).strip() not in ("0", ""):
        return None
    from astropy.io import fits

    try:
        with fits.open(path, memmap=False) as hdul:
            table = next((h for h in hdul if isinstance(h, fits.BinTableHDU | fits.TableHDU)),
                         None)  # fmt: skip
            if table is None or hdul[0].data is not None:
                return None
            names = {n.upper(): n for n in table.columns.names}

            def column(name: str) -> np.ndarray:
                if name.upper() not in names:
                    raise StarnavError(f"xylist {str(path)!r} has no column {name!r} "
                                       f"(columns: {', '.join(table.columns.names)})")  # fmt: skip
                return np.asarray(table.data[names[name.upper()]], dtype=float).reshape(-1)

            x, y = column(x_column), column(y_column)
            values, ascending, name = None, sort_ascending, sort_column
            if sort_column is not None:
                values = column(sort_column)
            else:
                name, ascending = next(((n, a) for n, a in BRIGHTNESS_COLUMNS if n in names),
                                       (None, False))  # fmt: skip
                values = None if name is None else column(name)
            header = hdul[0].header + table.header
    except OSError as exc:
        raise StarnavError(f"cannot read {str(path)!r} as FITS: {exc}") from None
    width = width or header.get("IMAGEW") or math.ceil(float(np.max(x, initial=1.0)))
    height = height or header.get("IMAGEH") or math.ceil(float(np.max(y, initial=1.0)))
    xylist = XYList.make(x, y, width, height, sort_values=values, ascending=ascending,
                         sort_name=name)  # fmt: skip
    if max_sources is not None:
        if max_sources < 1:
            raise StarnavError(f"the number of sources kept must be at least 1, got {max_sources}")
        xylist = replace(xylist, x=xylist.x[:max_sources], y=xylist.y[:max_sources])
    return xylist


@dataclass(frozen=True, eq=False)
class Plate:
    """A solved image in astrometry.net's terms (``net/api.py``'s calibration).

    ``ra_deg``, ``dec_deg``: the sky at the image centre (FITS pixel ((W+1)/2, (H+1)/2));
    ``radius_deg``: half the diagonal; ``pixscale_arcsec``: sqrt |det CD|; ``orientation_deg``:
    "up is X degrees E of N" of the WCS's +y axis (astrometry.net's raw orientation);
    ``parity``: nova's, +1.0 when det CD >= 0 (solve-field's "neg"), -1.0 else ("pos");
    ``wcs``: the WCS (astropy); ``width``, ``height``: px.
    """

    ra_deg: float
    dec_deg: float
    radius_deg: float
    pixscale_arcsec: float
    orientation_deg: float
    parity: float
    wcs: WCS
    width: int
    height: int

    @classmethod
    def from_wcs(cls, wcs: WCS, width: int, height: int) -> Plate:
        """astrometry.net's numbers of a WCS (``net/wcs.py``, ``util/sip.c``)."""
        cd = wcs.pixel_scale_matrix
        det = float(np.linalg.det(cd))
        parity = 1.0 if det >= 0 else -1.0
        t = parity * cd[0, 0] + cd[1, 1]
        a = parity * cd[1, 0] - cd[0, 1]
        orientation = -math.degrees(math.atan2(a, t))
        ra, dec = wcs.all_pix2world([[(width - 1) / 2.0, (height - 1) / 2.0]], 0)[0]
        scale = 3600.0 * math.sqrt(abs(det))
        radius = scale * math.hypot(width, height) / 2.0 / 3600.0
        return cls(float(ra) % 360.0, float(dec), radius, scale, orientation, parity, wcs,
                   width, height)  # fmt: skip

    @property
    def parity_name(self) -> str:
        """solve-field's word: "neg" for det CD >= 0, "pos" else (``solver/solve-field.c``:
        "negative determinant = positive parity")."""
        return "neg" if self.parity > 0 else "pos"

    def calibration(self, *, jpeglike: bool) -> dict:
        """nova's ``api/jobs/N/calibration`` JSON. For a JPEG or PNG (``jpeglike``) nova
        reports the orientation of the image as displayed, y down: (180 - X) mod 360
        (``net/models.py``, ``Calibration.get_orientation``)."""
        orient = (180.0 - self.orientation_deg) % 360.0 if jpeglike else self.orientation_deg
        return {
            "ra": self.ra_deg,
            "dec": self.dec_deg,
            "width_arcsec": self.pixscale_arcsec * self.width,
            "height_arcsec": self.pixscale_arcsec * self.height,
            "radius": self.radius_deg,
            "pixscale": self.pixscale_arcsec,
            "orientation": orient,
            "parity": self.parity,
        }


@dataclass(frozen=True, eq=False)
class PlateResult:
    """One plate solve: ``plate`` (None when unsolved, with the ``reason``), the starnav
    ``solution``, the image's ``pixels`` (None for a source list), the ``image`` result
    (detections, camera, times; None for a source list), the source ``xy`` (ours, px),
    ``jpeglike`` (not FITS), the solve's ``time_ms`` and the ``catalog`` matched in."""

    plate: Plate | None
    reason: str
    solution: Solution | None
    width: int
    height: int
    time_ms: float
    pixels: np.ndarray | None = None
    image: ImageSolveResult | None = None
    xy: np.ndarray | None = None
    jpeglike: bool = True
    catalog: Catalog | None = None


def parity_from_nova(value) -> int | None:
    """starnav's parity of nova's ``parity`` (0: "pos", 1: "neg", 2 or None: both) or of
    solve-field's word ("pos", "neg", "both")."""
    table = {0: -1, 1: 1, 2: None, "pos": -1, "neg": 1, "both": None, None: None}
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int | str | None) or value not in table:
        raise StarnavError(f"parity must be 0 (pos), 1 (neg) or 2 (both), got {shown(value)}")
    return table[value]


def solve_plate(
    source: str | Path | XYList,
    hints: PlateHints | Callable[[int, int], PlateHints] = PlateHints(),
    *,
    time_budget_s: float | None = None,
    max_pixels: int = MAX_PIXELS,
    budget_from: Deadline | None = None,
    on_budget: Callable[[float], None] | None = None,
) -> PlateResult:
    """Solve an image file (FITS, PNG, JPEG, TIFF) or a source list with a client's ``hints``
    (``PlateHints``, or a function of the image's width and height in px giving them, for
    scales in arcsec per pixel; they win over the FITS header's). ``time_budget_s``: the solve's
    (``starnav.runtime.budget`` defaults); with ``budget_from`` (when it started) the image's
    read and detection count against it (``solve_image``: ``on_budget`` is told what the
    solve gets). ``max_pixels``: the largest image read
    (``starnav.detect.read``). The WCS is fitted to the matched stars
    (``starnav.pipeline.image.fitted_wcs``)."""
    if isinstance(source, XYList):
        return _solve_plate(source, None, hints, time_budget_s)
    from starnav.detect.read import read_image

    pixels = read_image(source, max_pixels=max_pixels)
    return _solve_plate(Path(source), pixels, hints, time_budget_s, (budget_from, on_budget))


def _solve_plate(source, pixels, hints, time_budget_s, clock=(None, None)) -> PlateResult:
    if callable(hints):
        size = (source.width, source.height) if pixels is None else pixels.shape[::-1]
        hints = hints(*size)
    options: dict = {"time_budget_s": time_budget_s, "parity": hints.parity}
    if hints.fov_range_deg is not None:
        options["fov_range_deg"] = tuple(hints.fov_range_deg)
    if hints.positional_error_px is not None:
        options["sigma_px"] = _positive(hints.positional_error_px, "positional_error")
    if hints.max_false_match_probability is not None:
        options["max_false_match_probability"] = hints.max_false_match_probability
    if (hints.ra_deg is None) != (hints.dec_deg is None):
        raise StarnavError("a position hint needs both RA and Dec")
    if hints.ra_deg is not None:
        if not -90.0 <= float(hints.dec_deg) <= 90.0:
            raise StarnavError(f"Dec must be within ±90°, got {hints.dec_deg}")
        options["position_radius_deg"] = hints.radius_deg or DEFAULT_POSITION_RADIUS_DEG
    if isinstance(source, XYList):
        position = None
        if hints.ra_deg is not None:
            position = (float(hints.ra_deg), float(hints.dec_deg))
        xy = source.xy[source.solve_order()]  # the result's rows are these
        res = _solve_list(source, xy, options, position)
        sol = res.solution
        cam = None if sol is None else sol.camera
        reason = res.reason
        if sol is None and source.sorted_by is None:
            reason += (
                f" ({UNRANKED_WHY[source.ordered]}: solved without brightness, by the "
                "patterns of neighbouring points; name its flux or magnitude column to sort it)"
            )
        return _result(sol, cam, reason, source.width, source.height, res.time_ms,
                       hints.crpix_fits, xy=xy, catalog=res.catalog)  # fmt: skip
    path = source
    header = fits_hints(path)
    if hints.ra_deg is not None:
        header = replace(header, ra_deg=float(hints.ra_deg) % 360.0, dec_deg=float(hints.dec_deg),
                         sources=(*header.sources, "client"))  # fmt: skip
    res = solve_image(pixels, hints=header, downsample=hints.downsample,
                      budget_from=clock[0], on_budget=clock[1], **options)  # fmt: skip
    height, width = pixels.shape
    return _result(res.solution, res.camera, res.reason, width, height, res.total_ms,
                   hints.crpix_fits, pixels=pixels, image=res, xy=res.detections.xy,
                   jpeglike=not is_fits(path), catalog=res.catalog)  # fmt: skip


def _solve_list(source: XYList, xy: np.ndarray, options: dict, position) -> SolveResult:
    """A source list's solve: brightest first when sorted by a brightness column, without
    brightness (``solve_stars(ranked=False)``: ``pipeline.unordered``) when in detection
    order; a list with no brightness column in another order (brightest first, or shuffled:
    they cannot be told apart) is solved brightest first for ``GIVEN_ORDER_SHARE`` of the
    time budget, then without brightness for the rest."""

    def solve(ranked: bool, budget_s: float | None) -> SolveResult:
        opts = SolveOptions(fov_exact=False, **{**options, "time_budget_s": budget_s})
        return solve_stars(xy, opts, width=source.width, height=source.height,
                           position_hint_deg=position, images=True, ranked=ranked)  # fmt: skip

    budget_s = options.get("time_budget_s")
    if source.sorted_by is not None or not source.ordered:
        return solve(source.ordered, budget_s)
    total_s = check_budget(budget_s, default_budget_s(known=False, scan=False))
    first = solve(True, GIVEN_ORDER_SHARE * total_s)
    left_s = total_s - first.time_ms / 1e3
    if first.solution is not None or left_s <= 0:
        return first
    second = solve(False, left_s)
    return replace(second, time_ms=first.time_ms + second.time_ms)


def _result(sol, camera, reason, width, height, time_ms, crpix_fits, **kw) -> PlateResult:
    """The plate of a solve: its WCS fitted to the matched stars (``fitted_wcs``: TAN-SIP
    when the distortion is measurable), CRPIX at ``crpix_fits`` (FITS px; None: centre)."""
    plate = None
    if sol is not None:
        crpix = None if crpix_fits is None else tuple(float(c) - 0.5 for c in crpix_fits)
        wcs = fitted_wcs(sol, kw.get("catalog"), crpix_px=crpix, detections_xy=kw.get("xy"),
                         pixels=kw.get("pixels"))  # fmt: skip
        plate = Plate.from_wcs(wcs, width, height)
    return PlateResult(plate, reason, sol, width, height, time_ms, **kw)


SIDE_FILES = ("axy", "xyls", "rdls", "index_xyls", "corr", "match", "kmz")


def write_plate_files(
    result: PlateResult,
    source: str | Path | None,
    *,
    wcs: str | Path | None = None,
    new_fits: str | Path | None = None,
    annotate: str | Path | None = None,
    **side: str | Path | None,
) -> dict[str, str]:
    """Write a plate solve's files (each None: not written): ``wcs``, the WCS header
    (astrometry.net's ``.wcs``); ``new_fits``, the image with it (``.new``; a FITS ``source``
    keeps its data and header cards); ``annotate``, a PNG (solved or not; a source list is
    drawn on a black frame); and solve-field's side files by ``SIDE_FILES`` name
    (``starnav.output.sidefiles``): ``axy`` and ``xyls`` (the sources; written solved or not),
    ``rdls``, ``index_xyls``, ``corr``, ``match``, ``kmz`` (solved only; ``kmz`` for an image
    only). Returns the paths written, by kind (``starnav.pipeline.image.write_outputs``)."""
    unknown = set(side) - set(SIDE_FILES)
    if unknown:
        raise StarnavError(f"unknown plate file kinds: {', '.join(sorted(unknown))}")
    paths = {"wcs": wcs, "new_fits": new_fits, "annotate": annotate}
    paths = {k: Path(v) for k, v in paths.items() if v is not None}
    plate_wcs_ = None if result.plate is None else result.plate.wcs
    side_paths = {k: Path(v) for k, v in side.items() if v is not None}
    written = _write_side_files(result, side_paths, source)
    if result.image is not None:
        return {**write_outputs(paths, source, result.pixels, result.image, wcs=plate_wcs_),
                **written}  # fmt: skip
    from starnav.output.wcs import write_wcs

    if plate_wcs_ is not None and "wcs" in paths:
        write_wcs(paths["wcs"], plate_wcs_)
        written["wcs"] = str(paths["wcs"])
    if "annotate" in paths:
        _annotate_list(paths["annotate"], result)
        written["annotate"] = str(paths["annotate"])
    return written


def _sources(result: PlateResult) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The field's sources as solve-field lists them: FITS px (n, 2), flux and background
    (None for a source list: not known)."""
    if result.image is not None:
        found = result.image.detections
        background = np.full(len(found.xy), float(found.background))
        return found.xy + 0.5, np.asarray(found.flux, dtype=float), background
    xy = np.empty((0, 2)) if result.xy is None else np.asarray(result.xy, dtype=float)
    return xy + 0.5, None, None


def _field_stars(result: PlateResult, matched_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Catalog rows inside the solved image (brightest first), the matched ones added when
    outside, and their FITS pixels through the WCS."""
    plate, cat = result.plate, result.catalog
    from starnav.geometry import radec_to_unit

    centre = radec_to_unit(math.radians(plate.ra_deg), math.radians(plate.dec_deg))
    near = np.flatnonzero(cat.vectors @ centre >= math.cos(math.radians(plate.radius_deg * 1.1)))
    extra = cat.rows(matched_ids, missing=-1)
    rows = np.concatenate([near[np.argsort(cat.mag[near], kind="stable")], extra[extra >= 0]])
    xy = plate.wcs.all_world2pix(np.column_stack([cat.ra_deg[rows], cat.dec_deg[rows]]), 1,
                                 quiet=True)  # fmt: skip
    w, h = result.width, result.height
    inside = (xy[:, 0] >= 0.5) & (xy[:, 0] <= w + 0.5) & (xy[:, 1] >= 0.5) & (xy[:, 1] <= h + 0.5)
    inside[len(near) :] = True
    rows, first = np.unique(rows[inside], return_index=True)
    order = np.argsort(first)
    return rows[order], xy[inside][first][order]


def _write_side_files(result: PlateResult, paths: dict[str, Path], source) -> dict[str, str]:
    from starnav.output import sidefiles

    written: dict[str, str] = {}
    xy, flux, background = _sources(result)
    w, h = result.width, result.height
    if "axy" in paths:
        keywords = {f"AN{k.upper()}": (str(v), f"{k} output file")
                    for k, v in paths.items() if k in ("match", "rdls", "corr")}  # fmt: skip
        sidefiles.write_axy(paths["axy"], xy[:, 0], xy[:, 1], w, h, flux=flux,
                            background=background, keywords=keywords)  # fmt: skip
    if "xyls" in paths:
        zeros = np.zeros(len(xy))
        sidefiles.write_xyls(paths["xyls"], xy[:, 0], xy[:, 1], w, h,
                             flux=zeros if flux is None else flux,
                             background=zeros if background is None else background)  # fmt: skip
    written.update({k: str(paths[k]) for k in ("axy", "xyls") if k in paths})
    sol, plate, cat = result.solution, result.plate, result.catalog
    if sol is None or plate is None or cat is None:
        return written
    table = sol.star_table
    matched = np.flatnonzero(table.catalog_id >= 0)
    ids = table.catalog_id[matched]
    rows, index_xy = _field_stars(result, ids)
    if "rdls" in paths:
        sidefiles.write_rdls(paths["rdls"], cat.ra_deg[rows], cat.dec_deg[rows])
        written["rdls"] = str(paths["rdls"])
    if "index_xyls" in paths:
        sidefiles.write_xyls(paths["index_xyls"], index_xy[:, 0], index_xy[:, 1], w, h)
        written["index_xyls"] = str(paths["index_xyls"])
    if "corr" in paths:
        position = {int(r): i for i, r in enumerate(rows)}
        cat_rows = cat.rows(ids, missing=-1)
        keep = cat_rows >= 0
        matched, cat_rows = matched[keep], cat_rows[keep]
        index_id = np.array([position[int(r)] for r in cat_rows], dtype=np.int32)
        field_xy = table.xy[matched] + 0.5
        # the field's row of each solved point: the sources are the points solved, in order
        gap = np.linalg.norm(xy[None, : len(table.xy)] - (table.xy + 0.5)[:, None], axis=2)
        field_id = np.argmin(gap, axis=1)[matched] if len(xy) else np.zeros(0, dtype=int)
        sky = plate.wcs.all_pix2world(field_xy, 1) if len(field_xy) else np.empty((0, 2))
        weight = np.ones(len(matched))
        if table.match_probability is not None:
            weight = np.nan_to_num(table.match_probability[matched], nan=1.0)
        n = len(matched)
        sidefiles.write_corr(paths["corr"], {
            "field_x": field_xy[:, 0], "field_y": field_xy[:, 1],
            "field_ra": sky[:, 0] % 360.0, "field_dec": sky[:, 1],
            "index_x": index_xy[index_id, 0], "index_y": index_xy[index_id, 1],
            "index_ra": cat.ra_deg[cat_rows], "index_dec": cat.dec_deg[cat_rows],
            "index_id": index_id, "field_id": field_id.astype(np.int32),
            "match_weight": weight,
            "FLUX": np.zeros(n) if flux is None else flux[field_id],
            "BACKGROUND": np.zeros(n) if background is None else background[field_id],
        })  # fmt: skip
        written["corr"] = str(paths["corr"])
    if "match" in paths:
        p_false = min(max(float(sol.false_match_probability), 1e-300), 0.5)
        from starnav.geometry import radec_to_unit

        centre = radec_to_unit(math.radians(plate.ra_deg), math.radians(plate.dec_deg))
        name = "" if source is None else Path(source).name[:31]
        sidefiles.write_match(paths["match"], {
            "CENTERXYZ": centre, "RADIUS": plate.radius_deg, "NMATCH": len(matched),
            "NDISTRACT": int(len(table.xy) - len(matched)), "NCONFLICT": 0,
            "NFIELD": len(xy), "NINDEX": len(rows),
            "CRVAL": plate.wcs.wcs.crval, "CRPIX": plate.wcs.wcs.crpix,
            "CD": plate.wcs.pixel_scale_matrix.ravel(), "WCS_VALID": True, "FIELDNUM": 1,
            "FIELDID": 0, "FIELDNAME": name, "PARITY": plate.parity > 0,
            "TIMEUSED": result.time_ms / 1e3, "LOGODDS": math.log((1.0 - p_false) / p_false),
        })  # fmt: skip
        written["match"] = str(paths["match"])
    if "kmz" in paths and result.pixels is not None:
        corners = np.array([[0.5, h + 0.5], [w + 0.5, h + 0.5], [w + 0.5, 0.5], [0.5, 0.5]])
        sky = plate.wcs.all_pix2world(corners, 1)
        name = "starnav solve" if source is None else Path(source).name
        sidefiles.write_kmz(paths["kmz"], sky, _png(result.pixels), name)
        written["kmz"] = str(paths["kmz"])
    return written


def _png(pixels: np.ndarray) -> bytes:
    """The image as an 8-bit grey PNG, stretched between its 0.5 and 99.5 percentiles."""
    import io

    from matplotlib.image import imsave

    lo, hi = np.nanpercentile(pixels, [0.5, 99.5])
    grey = np.clip((np.asarray(pixels, dtype=float) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    out = io.BytesIO()
    imsave(out, grey, cmap="gray", vmin=0.0, vmax=1.0, format="png")
    return out.getvalue()


def _annotate_list(path_out: Path, result: PlateResult) -> None:
    """A source list's picture: its points on a black frame of the image's size, identified
    (``starnav.output.annotate``) when solved."""
    from starnav.output.annotate import save_figure, unsolved_figure

    frame = np.zeros((result.height, result.width), dtype=np.float32)
    s, xy = result.solution, result.xy
    if s is None:
        fig = unsolved_figure(frame, detected_xy=xy, used=min(len(xy), DEFAULT_PATTERN_STARS),
                              lines=[f"not solved: {result.reason}"])  # fmt: skip
        save_figure(fig, path_out)
        return
    annotate_solution(path_out, frame, xy, s, s.camera, result.catalog)
