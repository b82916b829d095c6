"""The solver object: bearings -> identify -> fit -> refuse, timed per stage.

``Solver(camera, catalog, identifier, settings)`` holds what a solve needs prepared (the
pair database, the tolerances, the identifier); ``solve(stars)`` takes the data. Every way
of solving (``api.solve`` and friends, images, batches, the evaluation, positioning,
calibration) goes through it; the FOV search yields identifications that ``conclude`` fits
the same way.
"""

from __future__ import annotations

import copy
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.errors import CatalogError, StarnavError
from starnav.identify import DEFAULT_ALGORITHM, MatchSettings, PairDatabase, make_identifier
from starnav.identify.base import Identification, Identifier, IdentifyOutcome
from starnav.identify.database import build_database, database_angle_deg
from starnav.identify.tracking import Tracking
from starnav.pipeline.conclude import conclude, elapsed_ms
from starnav.pipeline.deep import deep_catalog, deep_match
from starnav.pipeline.options import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    DEFAULT_MIN_MATCHED_FRACTION,
    DEFAULT_SIGMA_PX,
    SolveOptions,
    check_settings,
)
from starnav.results import Solution, SolveResult
from starnav.runtime.budget import Deadline, compiled_s, expired
from starnav.runtime.caches import process_cache
from starnav.starlist import StarList

MAX_PAIRS = 3e7  # largest pair database built (about 0.5 GB)
MAX_PAIR_DEG = 60.0  # wider fields identify on star triangles of sides up to this (degrees)
WIDE_PAIR_CANDIDATES = 2000  # catalog pairs a measured side of a wide field may match
_DATABASES = process_cache("pair databases")
_LOADED = process_cache("first uses")  # what this process has run once (machine code loaded)


@dataclass(frozen=True)
class SolveSettings:
    """Options of a solve. ``sigma_px``: 1-sigma centroid error (px; sets the tolerances;
    None: not known, the tolerances are ``DEFAULT_SIGMA_PX``'s and the false-match
    probability takes the sigma the data fit best, ``identify.base.SIGMA_FRACTIONS`` of it);
    ``parity``: +1 / -1 when known; ``fit_focal``: fit the focal length with the attitude;
    ``fit_distortion``: and the distortion coefficients (from 12 matched stars on);
    ``max_false_match_probability``: refuse less certain identifications;
    ``min_matched_fraction``: refuse when fewer of the stars that should be seen agree;
    ``deep_catalog``: match every point to this (fainter) catalog after the fit
    (``pipeline.deep``; None: no deep stage)."""

    sigma_px: float | None = None
    parity: int | None = None
    fit_focal: bool = False
    fit_distortion: bool = False
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY
    min_matched_fraction: float = DEFAULT_MIN_MATCHED_FRACTION
    deep_catalog: Catalog | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        check_settings(
            self.sigma_px,
            self.parity,
            self.max_false_match_probability,
            self.min_matched_fraction,
        )

    @classmethod
    def from_options(
        cls,
        options: SolveOptions,
        *,
        fit_focal: bool | None = None,
        deep_mag_limit: float | str | None = None,
    ) -> SolveSettings:
        """The settings of ``options`` (``fit_focal`` and ``deep_mag_limit`` overriding the
        options'), with the deep stage's catalog loaded."""
        deep = options.deep_mag_limit if deep_mag_limit is None else deep_mag_limit
        return cls(
            sigma_px=options.sigma_px,
            parity=options.parity,
            fit_focal=options.fit_focal if fit_focal is None else fit_focal,
            fit_distortion=options.fit_distortion,
            max_false_match_probability=options.max_false_match_probability,
            min_matched_fraction=options.min_matched_fraction,
            deep_catalog=deep_catalog(options.catalog, deep, options.epoch_year),
        )

    @property
    def search_sigma_px(self) -> float:
        """The centroid sigma the tolerances are made for (px): the one told, or
        ``DEFAULT_SIGMA_PX``."""
        return DEFAULT_SIGMA_PX if self.sigma_px is None else self.sigma_px

    def match_settings(self, camera: CameraModel) -> MatchSettings:
        """The identification's tolerances through ``camera`` (its coarsest angular scale)."""
        return MatchSettings.for_focal(
            self.sigma_px,
            camera.scale_px_per_rad,
            max_false_match_probability=self.max_false_match_probability,
            parity=self.parity,
        )


def get_database(catalog: Catalog, camera: CameraModel) -> PairDatabase:
    """The pair database for this catalog and field (memory, then disk cache, then built):
    pairs up to the field's diagonal, or ``MAX_PAIR_DEG`` for wider fields (a 180° field
    holds every pair of its half of the sky; its triangles are looked up among the nearer
    stars, and verified over the whole field). In wide fields the pairs join only the
    brightest catalog stars, as many as keep about ``WIDE_PAIR_CANDIDATES`` catalog pairs
    within the tolerance of a side measured to 1 px."""
    field_deg = camera.diagonal_deg
    max_angle_deg = min(field_deg, MAX_PAIR_DEG)
    pair_stars = len(catalog)
    if field_deg > MAX_PAIR_DEG:
        angle = np.radians(max_angle_deg)
        window = 2.0 * MatchSettings.for_focal(1.0, camera.scale_px_per_rad).pair_tol_rad
        # pairs within the window: n^2 (1 - cos angle) / 4 spread over the angle
        n = np.sqrt(4.0 * WIDE_PAIR_CANDIDATES * angle / (window * (1.0 - np.cos(angle))))
        pair_stars = min(len(catalog), int(n))
    # pairs expected for n stars spread over the sky: n^2 (1 - cos angle) / 4
    expected_pairs = pair_stars**2 * (1.0 - np.cos(np.radians(max_angle_deg))) / 4.0
    if expected_pairs > MAX_PAIRS:
        raise CatalogError(
            f"{pair_stars} catalog stars in a {camera.fov_deg:.3g}° field make about "
            f"{expected_pairs:.2g} star pairs (limit {MAX_PAIRS:.0e}): use a brighter "
            "magnitude limit"
        )
    key = (catalog.fingerprint, database_angle_deg(max_angle_deg), pair_stars)
    if key not in _DATABASES:
        _DATABASES[key] = build_database(catalog, max_angle_deg, pair_stars=pair_stars)
    return _DATABASES[key]


def check_prior(prior: Solution | np.ndarray | None) -> np.ndarray | None:
    """The prior attitude (a ``Solution`` or ``R_cam_from_icrs``) as a 3x3 rotation, None
    for no prior, or a one-line error (its 1-sigma is ``SolveOptions.prior_sigma_deg``,
    checked with the options)."""
    if prior is None:
        return None
    R = np.asarray(prior.R_cam_from_icrs if isinstance(prior, Solution) else prior, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
        raise StarnavError("prior must be a Solution or a 3x3 rotation (R_cam_from_icrs)")
    return R


def _say_compiling() -> None:
    if "notice" not in _LOADED:  # once per process
        _LOADED["notice"] = True
        print(
            "starnav: compiling the solver's machine code (once per installation, about 1-4 min)",
            file=sys.stderr,
            flush=True,
        )


@contextmanager
def first_use(what: str) -> Iterator[None]:
    """Around the first run of ``what`` in a process: it loads the cached machine code
    (~0.1-0.3 s), or compiles it, the first time after installing. Once a second has gone
    to compiling, say why on stderr (a slow load, or a small compile, says nothing)."""
    if what in _LOADED:
        yield
        return
    before = compiled_s()
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.5):
            if compiled_s() - before > 1.0:
                _say_compiling()
                return

    threading.Thread(target=watch, daemon=True).start()
    try:
        yield
    finally:
        done.set()
        _LOADED[what] = True


def steady_malloc() -> None:
    """Free one 16 MiB block once per process. glibc's malloc serves blocks above its mmap
    threshold (128 KiB) with a fresh mmap, page faults and all, until the process frees one
    large block, which raises the threshold to that size; numpy temporaries of the searches
    are often larger (the voting search ran 2x slower in a process that had never freed a
    large block), so timings would depend on the process's history."""
    if "malloc" not in _LOADED:
        _LOADED["malloc"] = True
        np.empty(16 << 20, dtype=np.uint8)


class Solver:
    """Star lists of one camera to verified attitudes.

    ``camera``: the camera model; ``catalog``: the stars to identify against; ``identifier``:
    an identification algorithm (default Pyramid) or its name; ``settings``: ``SolveSettings``.
    The pair database is loaded (or built) here, once, unless ``database`` (built for this
    ``catalog`` and field) is given.
    """

    def __init__(
        self,
        camera: CameraModel,
        catalog: Catalog,
        identifier: Identifier | str = DEFAULT_ALGORITHM,
        settings: SolveSettings | None = None,
        *,
        algorithm_options: dict | None = None,
        database: PairDatabase | None = None,
    ) -> None:
        if isinstance(identifier, str):
            try:
                identifier = make_identifier(identifier, **dict(algorithm_options or {}))
            except TypeError as exc:  # an option the algorithm does not have
                raise StarnavError(f"algorithm {identifier!r}: {exc}") from None
        steady_malloc()
        self.camera = camera
        self.catalog = catalog
        self.identifier = identifier
        self.settings = settings or SolveSettings()
        self.database = get_database(catalog, camera) if database is None else database
        self.match_settings = self.settings.match_settings(camera)

    def with_camera(self, camera: CameraModel, max_hypotheses: int | None = None) -> Solver:
        """This solver through another ``camera`` of the same lens (a trial focal length of
        a search), on the same database; ``max_hypotheses``: another budget of the
        identification."""
        other = copy.copy(self)
        other.camera = camera
        other.match_settings = self.settings.match_settings(camera)
        if max_hypotheses is not None:
            other.match_settings = replace(other.match_settings, max_hypotheses=max_hypotheses)
        return other

    def solve(
        self,
        stars: StarList,
        *,
        prior: np.ndarray | None = None,
        prior_sigma_deg: float = 1.0,
        deadline: Deadline | None = None,
    ) -> SolveResult:
        """Identify checked ``stars`` and fit the attitude. ``prior``: the previous attitude
        (``R_cam_from_icrs``), good to ``prior_sigma_deg`` (1-sigma): tracking mode matches
        the catalog stars near it only, and falls back to lost in space when that fails
        (``Solution.algorithm`` says which answered). ``deadline``: stop identifying when it
        passes (``starnav.runtime.budget``; None: no time limit)."""
        with first_use("solve"):
            t0 = time.perf_counter()
            bearings = self.camera.pixels_to_bearings(stars.xy)
            order = stars.order
            t1 = time.perf_counter()
            settings = self.match_settings.replaced(point_mag=stars.magnitudes, deadline=deadline)
            outcome, algorithm = self._identify(bearings, order, prior, prior_sigma_deg, settings)
            t2 = time.perf_counter()
            stages = {"bearings": (t1 - t0) * 1e3, "identify": (t2 - t1) * 1e3}
            found = outcome.identification
            if found is None:
                return SolveResult(
                    None,
                    outcome.reason,
                    elapsed_ms(t0),
                    outcome.hypotheses,
                    self.database.catalog,
                    stages,
                )
            return self.fit(found, stars, t0=t0, t_fit=t2, algorithm=algorithm, stages=stages)

    def _identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        prior,
        prior_sigma_deg: float,
        settings: MatchSettings,
    ) -> tuple[IdentifyOutcome, str]:
        if prior is not None:
            tracker = Tracking(R_prior=prior, sigma_deg=prior_sigma_deg)
            outcome = tracker.identify(bearings, order, self.database, settings)
            if outcome.identification is not None or expired(settings.deadline):
                return outcome, Tracking.name
        outcome = self.identifier.identify(bearings, order, self.database, settings)
        return outcome, self.identifier.name

    def fit(
        self,
        found: Identification,
        stars: StarList,
        *,
        t0: float,
        t_fit: float,
        algorithm: str,
        stages: dict[str, float],
    ) -> SolveResult:
        """Fit an identification of ``stars`` and decide (``fit_identification``)."""
        return fit_identification(
            found,
            stars,
            self.camera,
            self.database,
            self.settings,
            self.match_settings,
            t0=t0,
            t_fit=t_fit,
            algorithm=algorithm,
            stages=stages,
        )


@dataclass(frozen=True, eq=False)
class Candidate:
    """What a search offers the fit: an ``identification`` made through ``camera`` on
    ``database`` by ``algorithm``; or, with ``identification`` None, the search's last word:
    its ``reason`` and ``hypotheses``, and whether it ended ``ambiguous`` (then a candidate
    the fit refused before it does not stand as the answer)."""

    identification: Identification | None
    camera: CameraModel | None = None
    database: PairDatabase | None = None
    algorithm: str = ""
    reason: str = ""
    hypotheses: int = 0
    ambiguous: bool = False


def fit_first(
    candidates: Iterable[Candidate],
    stars: StarList,
    settings: SolveSettings,
    catalog: Catalog,
    *,
    t0: float,
) -> SolveResult:
    """The first of a search's ``candidates`` the fit accepts (``fit_identification``), or
    why none was: a verified identification that the fit then refuses (too few of the stars
    it predicts agree, ...) does not end the search, the next may be the right one.
    ``catalog``: the one searched (for an answer without a fit); ``t0``: when the solve
    began (``time.perf_counter()``); the search's own time is stage ``search``."""
    refused: SolveResult | None = None
    t_search = time.perf_counter()
    for found in candidates:
        if found.identification is None:
            if refused is not None and not found.ambiguous:
                return replace(refused, time_ms=elapsed_ms(t0))
            stages = {"search": elapsed_ms(t_search)}
            return SolveResult(
                None, found.reason, elapsed_ms(t0), found.hypotheses, catalog, stages
            )
        result = fit_identification(
            found.identification,
            stars,
            found.camera,
            found.database,
            settings,
            settings.match_settings(found.camera),
            t0=t0,
            t_fit=time.perf_counter(),
            algorithm=found.algorithm,
            stages={"search": elapsed_ms(t_search)},
        )
        if result.solution is not None:
            return result
        refused = result
    return refused or SolveResult(None, "nothing searched", elapsed_ms(t0), 0, catalog)


def fit_identification(
    found: Identification,
    stars: StarList,
    camera: CameraModel,
    database: PairDatabase,
    settings: SolveSettings,
    match_settings: MatchSettings,
    *,
    t0: float,
    t_fit: float,
    algorithm: str,
    stages: dict[str, float],
) -> SolveResult:
    """The ``SolveResult`` of an identification made with ``camera`` on ``database``: fitted
    and decided by ``pipeline.conclude``, then matched to ``settings.deep_catalog`` when it
    is given (``pipeline.deep``, stage ``deep``), timed from ``t0`` (the fit from ``t_fit``;
    ``time.perf_counter()`` values), ``stages`` the times so far."""
    solution, reason = conclude(
        found,
        stars,
        camera,
        database,
        match_settings,
        sigma_px=settings.search_sigma_px,
        known_sigma_px=settings.sigma_px,
        fit_focal=settings.fit_focal,
        fit_distortion=settings.fit_distortion,
        min_matched_fraction=settings.min_matched_fraction,
        algorithm=algorithm,
        t0=t0,
    )
    stages = {**stages, "fit": elapsed_ms(t_fit)}
    if solution is not None and settings.deep_catalog is not None:
        t_deep = time.perf_counter()
        solution = deep_match(
            solution, stars, settings.deep_catalog, sigma_px=settings.search_sigma_px
        )
        stages["deep"] = elapsed_ms(t_deep)
        solution = replace(solution, time_ms=elapsed_ms(t0))
    ms = elapsed_ms(t0) if solution is None else solution.time_ms
    return SolveResult(solution, reason, ms, found.hypotheses, database.catalog, stages)
