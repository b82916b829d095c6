"""The identification interface: bearing vectors in, verified star matches out."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from starnav.identify.database import PairDatabase
from starnav.runtime.budget import Deadline

# a measured angle carries two centroid errors: PAIR_TOL_SIGMAS sigma of their sum, at least
# MIN_PAIR_TOL_PX
PAIR_TOL_SIGMAS = 3.0
MIN_PAIR_TOL_PX = 1.0
# radial distance of a 2-D Gaussian error: beyond 3.5 sigma in 0.2 % of cases; points are
# paired with catalog stars within MATCH_RADIUS_SIGMAS sigma, at least MIN_MATCH_RADIUS_PX
MATCH_RADIUS_SIGMAS = 3.5
MIN_MATCH_RADIUS_PX = 1.0
# with no centroid sigma told, the tolerances are made for SEARCH_SIGMA_PX and the false-match
# probability takes the best of these fractions of it (an estimate from the data, paid for by
# the factor 4 on the probability)
SEARCH_SIGMA_PX = 1.0
SIGMA_FRACTIONS = (0.125, 0.25, 0.5, 1.0)


@dataclass(frozen=True)
class MatchSettings:
    """Tolerances and limits of an identification.

    ``pair_tol_rad``: how far a measured inter-star angle may be from the catalog's
    (radians); ``match_radius_rad``: how close a reprojected catalog star must be to pair with
    a point (radians); ``sigmas_rad``: the centroid sigmas (radians) the false-match
    probability is evaluated at, the best taken (one when the sigma is known);
    ``max_false_match_probability``: refuse any answer less certain than this; ``parity``:
    +1 or -1 when known, None to find it; ``max_stars``: triangles are made of the first
    (brightest) this many stars; ``max_screen_stars``: identification uses the first this
    many (the attitude fit then takes in the rest); ``max_hypotheses``: give up after testing
    this many; ``deadline``: give up when it passes (``starnav.runtime.budget``); ``point_mag``: the
    points' magnitudes (rows as the bearings an identifier is given, NaN: not measured;
    ``StarList.magnitudes``), None when their brightness is not known: then the
    ``order`` an identifier is given is not the brightness order (``ranked``), and the
    false-match probability weighs no brightness.
    """

    pair_tol_rad: float
    match_radius_rad: float
    sigmas_rad: tuple[float, ...]
    max_false_match_probability: float = 1e-4
    parity: int | None = None
    max_stars: int = 25
    max_screen_stars: int = 50
    max_hypotheses: int = 20000
    pixel_rad: float | None = None
    deadline: Deadline | None = None
    point_mag: np.ndarray | None = field(default=None, compare=False)

    @property
    def ranked(self) -> bool:
        """Whether the points' brightness is known and their ``order`` is by it."""
        return self.point_mag is not None

    @classmethod
    def for_focal(
        cls,
        sigma_px: float | None,
        focal_px: float,
        *,
        max_false_match_probability: float = 1e-4,
        parity: int | None = None,
    ) -> MatchSettings:
        """Tolerances for centroids good to ``sigma_px`` (1-sigma, px) seen with a focal
        length of ``focal_px``; ``sigma_px`` None: not known, the tolerances are
        ``SEARCH_SIGMA_PX``'s and the false-match probability takes the best of
        ``SIGMA_FRACTIONS`` of it."""
        fractions = SIGMA_FRACTIONS if sigma_px is None else (1.0,)
        sigma_px = SEARCH_SIGMA_PX if sigma_px is None else sigma_px
        return cls(
            pair_tol_rad=max(PAIR_TOL_SIGMAS * np.sqrt(2.0) * sigma_px, MIN_PAIR_TOL_PX) / focal_px,
            match_radius_rad=max(MATCH_RADIUS_SIGMAS * sigma_px, MIN_MATCH_RADIUS_PX) / focal_px,
            sigmas_rad=tuple(f * sigma_px / focal_px for f in fractions),
            max_false_match_probability=max_false_match_probability,
            parity=parity,
            pixel_rad=1.0 / focal_px,
        )

    def kernel_args(self) -> tuple[float, np.ndarray]:
        """``(match_radius_rad, sigmas_rad)`` as the verification kernels take them."""
        return self._kernel_args

    @functools.cached_property
    def _kernel_args(self) -> tuple[float, np.ndarray]:
        sigmas = np.asarray(self.sigmas_rad, dtype=np.float64)
        sigmas.flags.writeable = False
        return float(self.match_radius_rad), sigmas

    def replaced(self, **changes) -> MatchSettings:
        """``dataclasses.replace(self, **changes)`` in a sixth of the time (these settings
        have no checks to rerun; a solve replaces a field or two), the cached kernel
        arguments kept when the changes leave them as they are."""
        unknown = changes.keys() - self.__dataclass_fields__.keys()
        if unknown:
            raise TypeError(f"MatchSettings has no field {sorted(unknown)[0]!r}")
        out = object.__new__(MatchSettings)
        out.__dict__.update(self.__dict__, **changes)
        if "match_radius_rad" in changes or "sigmas_rad" in changes:
            out.__dict__.pop("_kernel_args", None)
        return out


@dataclass(frozen=True)
class Identification:
    """A verified identification.

    ``obs_index``/``cat_index``: matched bearing rows and catalog rows; ``R_cam_from_icrs``:
    the attitude of the accepted hypothesis (from its star triangle); ``parity``;
    ``false_match_probability``: the chance that the identification is wrong (over the
    ``hypotheses`` tried); ``log_sides``: the natural-log likelihood ratio of its star
    triangle's sides (0 when it was not a triangle looked up within a tolerance), which the
    fit's false-match probability counts again; ``bright_drop``: how many of its pairs'
    brightness scores that probability leaves out (the stars that built it, when they came
    from tables of bright stars; 0 when from a pair table of the whole catalog).
    """

    obs_index: np.ndarray
    cat_index: np.ndarray
    R_cam_from_icrs: np.ndarray
    parity: int
    false_match_probability: float
    hypotheses: int
    log_sides: float = 0.0
    bright_drop: int = 4


@dataclass(frozen=True)
class IdentifyOutcome:
    """What an identifier returns: an ``Identification`` or the reason there is none."""

    identification: Identification | None
    reason: str
    hypotheses: int


class Identifier(Protocol):
    """Lost-in-space identification of camera-frame bearing vectors."""

    name: str

    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify ``bearings`` (n, 3); ``order`` lists rows best-first (e.g. brightest)."""
        ...

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the tables this algorithm searches (the pair database and its own)."""
        ...


def screen_stars_only(identify: Callable[..., IdentifyOutcome]) -> Callable[..., IdentifyOutcome]:
    """Decorate an ``identify`` method so it sees only the first ``settings.max_screen_stars``
    stars of ``order`` (the caller matches the rest once the attitude is known); the rows of
    its answer are mapped back to the full list."""

    @functools.wraps(identify)
    def wrapper(self, bearings, order, database, settings):
        used = np.asarray(order)[: settings.max_screen_stars]
        if len(used) >= len(bearings):
            return identify(self, bearings, np.asarray(order), database, settings)
        if settings.point_mag is not None:
            settings = settings.replaced(point_mag=settings.point_mag[used])
        outcome = identify(self, bearings[used], np.arange(len(used)), database, settings)
        found = outcome.identification
        if found is not None:
            found = replace(found, obs_index=used[found.obs_index])
        return replace(outcome, identification=found)

    return wrapper
