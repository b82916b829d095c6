"""``SolveOptions``: every option of a solve in one frozen object, checked once.

Every entry (``starnav.solve_stars`` and ``solve`` for star lists, ``solve_image``, batches,
plates, positioning) takes one; keyword options given beside it override its fields
(``SolveOptions.make``). What belongs to one frame rather than to the camera and the method —
the points, their brightness, a prior attitude, a position hint — is passed with the call.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from starnav.camera import Camera, CameraModel, Fisheye, load_camera, model_class
from starnav.catalog import Catalog
from starnav.catalog.sky import Site, parse_utc
from starnav.errors import CameraError, ImageError, StarnavError, shown
from starnav.identify import ALGORITHMS, DEFAULT_ALGORITHM
from starnav.identify.base import SEARCH_SIGMA_PX
from starnav.runtime.budget import check_budget

DEFAULT_SIGMA_PX = SEARCH_SIGMA_PX  # the tolerances' sigma when none is told
DEFAULT_MAX_FALSE_MATCH_PROBABILITY = 1e-4
DEFAULT_MIN_MATCHED_FRACTION = 0.5
# the ranges searched when none is given: the lens model classes say (``default_fov_range_deg``)
DEFAULT_FOV_RANGE_DEG = Camera.default_fov_range_deg  # the pinhole FOV search's
DEFAULT_LENS_FOV_RANGE_DEG = Fisheye.default_fov_range_deg  # a fisheye focal scan's
DEFAULT_PATTERN_STARS = 15  # the brightest this many stars make the 4-star patterns
POSITION_HINT_RADIUS_DEG = 10.0  # a position hint's boresight is searched first within this
DEFAULT_MAX_STARS = 50  # an image's brightest detections solved
FISHEYE_MAX_STARS = 100  # a whole sky's brightest detections hold horizon lights and glow
DEFAULT_THRESHOLD_SIGMA = 5.0  # detection threshold over the background noise
# ``lens="fisheye"``: not a model, the common fisheye models of all-sky and meteor cameras,
# each scanned (most common first)
FISHEYE = "fisheye"
FISHEYE_MODELS = ("equidistant", "equisolid", "stereographic", "orthographic")


@dataclass(frozen=True, kw_only=True)
class SolveOptions:
    """The options of a solve (all keyword, all with defaults; units in the names).

    The field: ``fov_deg`` (horizontal field of view, degrees) or ``camera`` (a camera model
    or a camera file), or neither, when ``fov_range_deg`` (horizontal, degrees; None: the
    lens model's default, 5-40° for the pinhole, 100-200° for a fisheye, or the image circle's
    140-230° when one is found) is searched for a pinhole or a fisheye's focal length is
    scanned. ``fov_exact``: whether a given ``fov_deg``
    / ``camera`` is taken as it is (True) or searched within 5 % / 1 % with the focal length
    fitted (False); None: exact for star lists, approximate for images. ``lens``: the lens
    model without a camera (``starnav.camera.MODELS``, or ``"fisheye"``: each of the common
    fisheye models, ``FISHEYE_MODELS``); ``fit_focal``, ``fit_distortion``:
    fit the focal length (and k1, k2, from 12 matched stars) with the attitude.

    The catalog: ``catalog`` (a ``Catalog``, a CSV path, or None for the embedded
    Hipparcos), ``mag_limit`` (None: the field's default), ``epoch_year`` (proper motion;
    None: now), ``deep_mag_limit`` (match every point to the catalog down to this magnitude
    after the fit, with a per-star ``match_probability``; None: the field's default, ``"off"``:
    none). The field's defaults, for the embedded Hipparcos through a known camera
    (``pipeline.fov.known_field_depth``): identification on Hp 6 where that holds 15 stars
    in an average image (fields of about 12° and wider), else as deep as the FOV search's
    band of the field, and on those narrower fields a deep stage to Hp 12 where the pixels
    are fine enough that a false star rarely lands on a catalog star (a 6° star tracker's);
    a searched field identifies on its bands' catalogs and runs no deep stage unless told.

    The identification: ``algorithm`` (``starnav.identify.ALGORITHMS``) and its
    ``algorithm_options``; ``sigma_px`` (1-sigma centroid error, px; None: not known, the
    tolerances allow ``DEFAULT_SIGMA_PX`` and the false-match probability takes the sigma the
    residuals fit best); ``parity`` (+1 / -1 when known); ``max_false_match_probability``
    and ``min_matched_fraction`` (refuse less certain answers); ``pattern_stars`` (the FOV
    search's brightest stars); ``prior_sigma_deg`` (1-sigma of a prior attitude);
    ``position_radius_deg`` (a position hint is searched first within this).

    ``time_budget_s``: give up after this many seconds ("time budget spent"; None: the
    default of the field, ``starnav.runtime.budget``; ``math.inf``: no limit).

    Images only: ``max_stars`` (the brightest detections solved; None: 50, 100 for a
    fisheye), ``threshold_sigma`` (detection threshold over the background noise),
    ``downsample`` (detect on the image binned by this factor; None: binned to at most
    4.2 MP, ``pipeline.image.detection_binning``).

    Where and when: ``site`` (``catalog.sky.Site``, or (latitude, longitude degrees, height
    m)) and ``utc`` (ISO 8601 or an astropy ``Time``; an image's own time when None): with
    both, a fisheye's scan looks for the stars above the horizon and the planets
    (``catalog.sky.sky_at``). A fisheye's scale, roughly (searched ±5 %): ``circle_fov_deg``
    (the field across the image circle found in the image, degrees) or ``focal_px`` (the
    focal length in pixels: focal length in mm over the pixel pitch in mm).
    """

    fov_deg: float | None = None
    fov_range_deg: tuple[float, float] | None = None
    fov_exact: bool | None = None
    camera: CameraModel | None = None
    lens: str = "pinhole"
    fit_focal: bool = False
    fit_distortion: bool = False
    catalog: Catalog | str | Path | None = field(default=None, repr=False)
    mag_limit: float | None = None
    epoch_year: float | None = None
    deep_mag_limit: float | str | None = None
    algorithm: str = DEFAULT_ALGORITHM
    algorithm_options: tuple[tuple[str, Any], ...] = ()
    sigma_px: float | None = None
    parity: int | None = None
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY
    min_matched_fraction: float = DEFAULT_MIN_MATCHED_FRACTION
    pattern_stars: int = DEFAULT_PATTERN_STARS
    prior_sigma_deg: float = 1.0
    position_radius_deg: float = POSITION_HINT_RADIUS_DEG
    time_budget_s: float | None = None
    max_stars: int | None = None
    threshold_sigma: float = DEFAULT_THRESHOLD_SIGMA
    downsample: int | None = None
    site: Site | None = None
    utc: str | None = None
    circle_fov_deg: float | None = None
    focal_px: float | None = None

    def __post_init__(self) -> None:
        if self.site is not None and not isinstance(self.site, Site):
            object.__setattr__(self, "site", Site(*self.site))
        for name in ("circle_fov_deg", "focal_px"):
            v = getattr(self, name)
            top = 360.0 if name == "circle_fov_deg" else 1e7
            if v is not None and not (_number(v) and math.isfinite(v) and 0.0 < v <= top):
                raise StarnavError(f"{name} must be in (0, {top:g}], got {shown(v)}")
            if v is not None and self.camera is None and not self.lens_class.scans_focal:
                raise StarnavError(
                    f"{name} is a fisheye's scale: give a fisheye --lens, or the pinhole's FOV"
                )
        if self.utc is not None:
            object.__setattr__(self, "utc", parse_utc(self.utc).utc.isot)
        if isinstance(self.camera, str | Path):
            object.__setattr__(self, "camera", load_camera(self.camera))
        elif self.camera is not None and not hasattr(self.camera, "pixels_to_bearings"):
            given = type(self.camera).__name__
            raise CameraError(f"camera must be a camera model or a camera file, got a {given}")
        if isinstance(self.algorithm_options, Mapping):
            items = tuple(sorted(self.algorithm_options.items()))
            object.__setattr__(self, "algorithm_options", items)
        if self.fov_range_deg is not None:
            object.__setattr__(self, "fov_range_deg", tuple(self.fov_range_deg))
        if self.lens != FISHEYE:
            model_class(self.lens)  # a one-line error for an unknown model
        if self.algorithm not in ALGORITHMS:
            known = ", ".join(ALGORITHMS)
            raise StarnavError(f"unknown algorithm {self.algorithm!r}; known: {known}")
        check_budget(self.time_budget_s, 1.0)
        check_settings(
            self.sigma_px,
            self.parity,
            self.max_false_match_probability,
            self.min_matched_fraction,
        )
        d = self.prior_sigma_deg
        if not (_number(d) and math.isfinite(d) and 0.0 < d <= 30.0):
            raise StarnavError(f"prior_sigma_deg must be in (0, 30] degrees, got {shown(d)}")
        r = self.position_radius_deg
        if not (_number(r) and math.isfinite(r) and 0 < r <= 180):
            raise StarnavError(
                f"the position hint's radius must be in (0, 180] degrees, got {shown(r)}"
            )
        m = self.max_stars
        if m is not None and not (isinstance(m, int) and not isinstance(m, bool) and m >= 4):
            raise ImageError(f"max_stars must be an integer >= 4, got {shown(m)}")
        k = self.downsample
        if k is not None and not (isinstance(k, int) and not isinstance(k, bool) and k >= 1):
            raise ImageError(f"downsample must be an integer >= 1 or None, got {shown(k)}")

    @classmethod
    def make(cls, options: SolveOptions | None = None, **overrides: Any) -> SolveOptions:
        """``options`` (default: all defaults) with the fields in ``overrides`` replaced; a
        one-line error naming an option that does not exist."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise StarnavError(
                f"unknown solve option{'s' if len(unknown) > 1 else ''}: {', '.join(unknown)}"
            )
        base = options if options is not None else cls()
        if not isinstance(base, SolveOptions):
            raise StarnavError(f"options must be a SolveOptions, got {type(base).__name__}")
        return replace(base, **overrides) if overrides else base

    @property
    def lens_model(self) -> str:
        """The lens model solved with: the camera's, or ``lens`` (``FISHEYE``: the first of
        ``FISHEYE_MODELS``, whose facts are all of theirs)."""
        return self.camera.model if self.camera is not None else facts_model(self.lens)

    @property
    def lens_models(self) -> tuple[str, ...]:
        """The lens models a focal scan tries: ``FISHEYE_MODELS`` for ``lens="fisheye"``
        without a camera, else ``lens_model``."""
        if self.camera is None and self.lens == FISHEYE:
            return FISHEYE_MODELS
        return (self.lens_model,)

    @property
    def lens_class(self) -> type:
        """The lens model's class (``starnav.camera.model_class``), which holds its facts."""
        return model_class(self.lens_model)

    @property
    def scans_focal(self) -> bool:
        """Whether the lens model's unknown focal length is scanned (the fisheye models) rather
        than its field of view searched (the pinhole)."""
        return self.lens_class.scans_focal

    @property
    def field_known(self) -> bool:
        """Whether the field of view is given (``fov_deg`` or ``camera``)."""
        return self.fov_deg is not None or self.camera is not None

    @property
    def search_range_deg(self) -> tuple[float, float]:
        """The horizontal FOV range searched when the field is not given: ``fov_range_deg``
        or the lens model's default."""
        if self.fov_range_deg is not None:
            return self.fov_range_deg
        return default_fov_range_deg(self.lens_model)

    @property
    def searched_ranges_deg(self) -> tuple[tuple[float, float], ...]:
        """The horizontal FOV ranges searched in turn when the field is not given: the range
        given, or the lens model's default and then its extended ranges while the time
        budget lasts (``Lens.extended_fov_ranges_deg``)."""
        if self.fov_range_deg is not None:
            return (self.fov_range_deg,)
        return (self.search_range_deg, *self.lens_class.extended_fov_ranges_deg)

    @property
    def algorithm_kwargs(self) -> dict[str, Any]:
        """``algorithm_options`` as keyword arguments."""
        return dict(self.algorithm_options)


def check_settings(
    sigma_px: float | None,
    parity: int | None,
    max_false_match_probability: float,
    min_matched_fraction: float,
) -> None:
    """A one-line error for a bad setting of the identification and fit, the ones both
    ``SolveOptions`` and the solver's ``SolveSettings`` hold (checked here once)."""
    s = sigma_px
    if s is not None and not (_number(s) and math.isfinite(s) and s > 0):
        raise StarnavError(f"sigma_px must be a positive number of pixels, got {shown(s)}")
    if parity not in (None, 1, -1):
        raise StarnavError(f"parity must be +1, -1 or None, got {shown(parity)}")
    f = min_matched_fraction
    if not (_number(f) and 0.0 <= f <= 1.0):
        raise StarnavError(f"min_matched_fraction must be in [0, 1], got {shown(f)}")
    p = max_false_match_probability
    if not (_number(p) and 0.0 < p < 1.0):
        raise StarnavError(f"max_false_match_probability must be in (0, 1), got {shown(p)}")


def facts_model(lens: str) -> str:
    """The lens model whose facts (kind, ranges, limits) ``lens`` has: itself, or for
    ``FISHEYE`` the first of ``FISHEYE_MODELS``."""
    return FISHEYE_MODELS[0] if lens == FISHEYE else lens


def default_fov_range_deg(lens: str) -> tuple[float, float]:
    """The horizontal FOV range (degrees) searched for the ``lens`` model when none is given:
    its class's ``default_fov_range_deg`` (5-40° for the pinhole's FOV search, 100-200° for a
    fisheye model's focal scan)."""
    return tuple(model_class(facts_model(lens)).default_fov_range_deg)


def _number(value: object) -> bool:
    """A real number (numpy's scalars too), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)
