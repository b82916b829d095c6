"""The public surface: ``solve()`` a star list into a verified attitude, and its results."""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from starnav.attitude import refine_attitude
from starnav.attitude.refine import free_focal_step
from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import CatalogError, StarnavError
from starnav.geometry import radec_roll_from_attitude
from starnav.identify import (
    DEFAULT_ALGORITHM,
    MatchSettings,
    PairDatabase,
    build_database,
    make_identifier,
)
from starnav.identify.base import Identification
from starnav.identify.database import database_angle_deg
from starnav.identify.tracking import Tracking
from starnav.identify.verify import match_catalog
from starnav.pointing import Pointing, best_triple, three_star
from starnav.results import Solution, SolveResult, StarMatch
from starnav.simulate import project_catalog
from starnav.starlist import StarList, check_star_list

DEFAULT_SIGMA_PX = 1.0
DEFAULT_MAX_FALSE_MATCH_PROBABILITY = 1e-4
DEFAULT_MIN_MATCHED_FRACTION = 0.5
MAX_PAIRS = 3e7  # largest pair database built (about 0.5 GB)
_MAX_REMATCH = 5
_MIN_FIT_STARS = 4  # outliers are only looked for when a fit keeps at least this many stars
_OUTLIER_ALPHA = 1e-3  # chance of dropping a right pair somewhere in a frame
_MIN_STARS_SCALE_CHECK = 6
_SCALE_TOLERANCE = 0.005  # relative focal-length error tolerated without --fit-focal


_DATABASES: dict[tuple[str, float], PairDatabase] = {}  # in-memory, per process

# glibc's malloc serves blocks above its mmap threshold (128 KiB) with a fresh mmap, page
# faults and all, until the process frees one large block, which raises the threshold to that
# size. Numpy temporaries of the searches are often larger: the voting search ran 2x slower in
# a process that had never freed a large block (it depended on how the catalog was loaded).
# Freeing one 16 MiB block here makes timings independent of that history.
np.empty(16 << 20, dtype=np.uint8)


def get_database(catalog: Catalog, camera: Camera) -> PairDatabase:
    """The pair database for this catalog and field (memory, then disk cache, then built)."""
    max_angle_deg = float(np.degrees(2.0 * camera.half_diagonal_rad))
    # pairs expected for n stars spread over the sky: n^2 (1 - cos angle) / 4
    expected_pairs = len(catalog) ** 2 * (1.0 - np.cos(np.radians(max_angle_deg))) / 4.0
    if expected_pairs > MAX_PAIRS:
        raise CatalogError(
            f"{len(catalog)} catalog stars in a {camera.fov_deg:.3g}° field make about "
            f"{expected_pairs:.2g} star pairs (limit {MAX_PAIRS:.0e}): use a brighter "
            "magnitude limit"
        )
    key = (catalog.fingerprint, database_angle_deg(max_angle_deg))
    if key not in _DATABASES:
        _DATABASES[key] = build_database(catalog, max_angle_deg)
    return _DATABASES[key]


def make_camera(*, width: float, height: float | None, fov_deg: float) -> Camera:
    """Camera from the user's numbers (height defaults to width)."""
    return Camera.from_fov(fov_deg, width, height)


def check_solve_options(
    sigma_px: float,
    parity: int | None,
    max_false_match_probability: float,
    min_matched_fraction: float,
) -> None:
    """One-line errors for the options every solve shares."""
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise StarnavError(f"sigma_px must be a positive number of pixels, got {sigma_px!r}")
    if parity not in (None, 1, -1):
        raise StarnavError(f"parity must be +1, -1 or None, got {parity!r}")
    if not 0.0 <= min_matched_fraction <= 1.0:
        raise StarnavError(f"min_matched_fraction must be in [0, 1], got {min_matched_fraction!r}")
    if not 0.0 < max_false_match_probability < 1.0:
        raise StarnavError(
            f"max_false_match_probability must be in (0, 1), got {max_false_match_probability!r}"
        )


def solve_verbose(
    xy: np.ndarray,
    *,
    width: float,
    height: float | None = None,
    fov_deg: float,
    brightness: np.ndarray | None = None,
    labels: list[str] | tuple[str, ...] | None = None,
    catalog: Catalog | str | Path | None = None,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
    parity: int | None = None,
    sigma_px: float = DEFAULT_SIGMA_PX,
    fit_focal: bool = False,
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    min_matched_fraction: float = DEFAULT_MIN_MATCHED_FRACTION,
    algorithm: str = DEFAULT_ALGORITHM,
    algorithm_options: Mapping[str, object] | None = None,
    prior: Solution | np.ndarray | None = None,
    prior_sigma_deg: float = 1.0,
    compiled: bool = True,
) -> SolveResult:
    """Like ``solve`` but always returns a ``SolveResult`` with the reason when unsolved.

    ``labels``: a name per star (default "1", "2", ...); ``mag_limit``, ``epoch_year``: for
    the embedded Hipparcos catalog (see ``load_catalog``); ``parity``: +1 / -1 when known;
    ``sigma_px``: 1-sigma centroid error, which sets the matching tolerances;
    ``fit_focal``: fit the focal length with the attitude;
    ``max_false_match_probability``: refuse less certain identifications;
    ``min_matched_fraction``: refuse when fewer of the stars that should be seen (the smaller
    of the number of points and of catalog stars inside the image) agree;
    ``algorithm``: identification algorithm by name (``starnav.identify.ALGORITHMS``);
    ``algorithm_options``: keyword options of that algorithm's class (e.g.
    ``{"selection": "brightest"}`` for ``triangle``); ``prior``: the previous attitude (a
    ``Solution`` or ``R_cam_from_icrs``), good to ``prior_sigma_deg`` (1-sigma): tracking mode
    matches the catalog stars near it only, and falls back to ``algorithm`` when that fails
    (``Solution.algorithm`` says which answered); ``compiled``: run the numba-compiled path
    (``starnav.compiled``) where it applies - the identification of the ``pyramid`` algorithm
    and of tracking, and the attitude fit - False runs the numpy path, which gives the same
    answers several times slower.
    """
    camera = make_camera(width=width, height=height, fov_deg=fov_deg)
    stars = check_star_list(
        xy, width=camera.width, height=camera.height, brightness=brightness, labels=labels
    )
    check_solve_options(sigma_px, parity, max_false_match_probability, min_matched_fraction)
    try:
        identifier = make_identifier(algorithm, **dict(algorithm_options or {}))
    except TypeError as exc:  # an option the algorithm does not have
        raise StarnavError(f"algorithm {algorithm!r}: {exc}") from None
    R_prior = None
    if prior is not None:
        R_prior = np.asarray(
            prior.R_cam_from_icrs if isinstance(prior, Solution) else prior, dtype=float
        )
        if R_prior.shape != (3, 3) or not np.allclose(R_prior @ R_prior.T, np.eye(3), atol=1e-6):
            raise StarnavError("prior must be a Solution or a 3x3 rotation (R_cam_from_icrs)")
        if not (np.isfinite(prior_sigma_deg) and 0.0 < prior_sigma_deg <= 30.0):
            raise StarnavError(
                f"prior_sigma_deg must be in (0, 30] degrees, got {prior_sigma_deg!r}"
            )
    cat = load_catalog(catalog, mag_limit=mag_limit, epoch_year=epoch_year)
    database = get_database(cat, camera)

    t0 = time.perf_counter()
    bearings = camera.pixels_to_bearings(stars.xy)
    settings = MatchSettings.for_focal(
        sigma_px,
        camera.focal_px,
        max_false_match_probability=max_false_match_probability,
        parity=parity,
    )
    order = (
        np.argsort(-stars.brightness, kind="stable")
        if stars.brightness is not None
        else np.arange(len(bearings))
    )
    if compiled:  # imported here: numba takes ~0.2 s to import, which other commands skip
        from starnav import compiled as fast
    outcome = None
    if R_prior is not None:
        if compiled:
            outcome = fast.identify(
                bearings,
                order,
                database,
                settings,
                R_prior=R_prior,
                prior_sigma_deg=prior_sigma_deg,
            )
        if outcome is None:  # not compiled, or the compiled path deferred to the numpy one
            tracker = Tracking(R_prior=R_prior, sigma_deg=prior_sigma_deg)
            outcome = tracker.identify(bearings, order, database, settings)
        if outcome.identification is not None:
            algorithm = Tracking.name
    if outcome is None or outcome.identification is None:  # lost in space
        outcome = None
        if compiled and algorithm == "pyramid":
            outcome = fast.identify(bearings, order, database, settings)
        if outcome is None:
            outcome = identifier.identify(bearings, order, database, settings)
    found = outcome.identification
    if found is None:
        ms = (time.perf_counter() - t0) * 1e3
        return SolveResult(None, outcome.reason, ms, outcome.hypotheses, database)
    return conclude(
        found,
        stars,
        camera,
        cat,
        database,
        settings,
        t0=t0,
        sigma_px=sigma_px,
        fit_focal=fit_focal,
        algorithm=algorithm,
        min_matched_fraction=min_matched_fraction,
        compiled=compiled,
    )


def conclude(
    found: Identification,
    stars: StarList,
    camera: Camera,
    cat: Catalog,
    database: PairDatabase,
    settings: MatchSettings,
    *,
    t0: float,
    sigma_px: float,
    fit_focal: bool,
    algorithm: str,
    min_matched_fraction: float,
    fit_distortion: bool = False,
    compiled: bool = True,
) -> SolveResult:
    """From an identification to the reported solution: the attitude fit (least squares on
    the image, outliers dropped, the stars the better attitude brings in range taken in),
    the final false-match probability and the refusals. ``t0``: ``time.perf_counter()`` at
    the start of the solve (for ``time_ms``); ``compiled``: the numba-compiled fit
    (``starnav.compiled``) for a camera without distortion, False: the numpy one."""
    if compiled and not fit_distortion and not (camera.k1 or camera.k2):
        from starnav import compiled as fast  # imported on first use (numba: ~0.2 s)

        done = fast.conclude(
            found,
            stars.xy,
            camera,
            database,
            settings,
            sigma_px=sigma_px,
            min_matched_fraction=min_matched_fraction,
            fit_focal=fit_focal,
        )
        if done is not None:
            if done.refusal != fast.ACCEPTED:
                if done.refusal == fast.WRONG_SCALE:
                    reason = _wrong_scale(done.scale_focal_px, camera)
                elif done.refusal == fast.UNCONVINCING:
                    reason = _unconvincing(done.false_match_probability)
                else:
                    reason = _too_few(len(done.obs), done.expected, min_matched_fraction)
                ms = (time.perf_counter() - t0) * 1e3
                return SolveResult(None, reason, ms, found.hypotheses, database)
            return _report(
                stars,
                done.obs,
                done.cat,
                cat,
                camera.with_focal(done.focal_px),
                done.R_cam_from_icrs,
                done.residuals_px,
                (
                    done.rms_px,
                    done.sigma_boresight_arcsec,
                    done.sigma_roll_arcsec,
                    done.sigma_focal_px,
                ),
                done.false_match_probability,
                t0=t0,
                algorithm=algorithm,
                hypotheses=found.hypotheses,
                database=database,
            )
    max_false_match_probability = settings.max_false_match_probability
    # least squares on the image, taking in the stars the better attitude brings in range
    fitter = _Fitter(cat, stars.xy, camera, database, settings, sigma_px, fit_focal, fit_distortion)
    obs, cat_rows, fit, ver = fitter.converge(
        found.obs_index, found.cat_index, found.R_cam_from_icrs
    )
    # a wrong star of a close pair in the first match can bend the fit so that the far stars
    # fall just outside the radius; a wide search from the result finds them. The other set
    # wins when it explains more stars and fits the stars both share about as well (a point
    # pulled in from far bends the fit away from the shared stars instead)
    wide = fitter.match(fit, 3.0 * settings.match_radius_rad)
    if len(wide.obs_index) > len(obs):
        other = fitter.converge(wide.obs_index, wide.cat_index, fit.R_cam_from_icrs)
        shared_rms = _shared_rms((obs, cat_rows, fit), other)
        if len(other[0]) > len(obs) and shared_rms[1] <= 1.5 * shared_rms[0] + 0.1 * sigma_px:
            obs, cat_rows, fit, ver = other
    R = fit.R_cam_from_icrs
    # score the final pairs (the last verification may hold a slightly different set)
    final = replace(
        ver,
        obs_index=obs,
        cat_index=cat_rows,
        distance_rad=np.linalg.norm(  # chord, as match_catalog measures it
            fit.camera.pixels_to_bearings(stars.xy[obs])
            - cat.vectors[cat_rows] @ fit.R_cam_from_icrs.T,
            axis=1,
        ),
    )
    p_false = final.false_match_probability(
        len(stars.xy), 3, found.hypotheses, settings.match_radii_rad
    )
    refusal = _refusal(
        fit,
        cat,
        cat_rows,
        stars.xy[obs],
        camera,
        fit_focal=fit_focal,
        p_false=p_false,
        max_p=max_false_match_probability,
        n_points=len(stars.xy),
        min_matched_fraction=min_matched_fraction,
    )
    if refusal:
        ms = (time.perf_counter() - t0) * 1e3
        return SolveResult(None, refusal, ms, found.hypotheses, database)
    return _report(
        stars,
        obs,
        cat_rows,
        cat,
        fit.camera,
        R,
        fit.residuals_px,
        (fit.rms_px, fit.sigma_boresight_arcsec, fit.sigma_roll_arcsec, fit.sigma_focal_px),
        p_false,
        t0=t0,
        algorithm=algorithm,
        hypotheses=found.hypotheses,
        database=database,
    )


def _report(
    stars: StarList,
    obs: np.ndarray,
    cat_rows: np.ndarray,
    cat: Catalog,
    camera: Camera,
    R: np.ndarray,
    residuals_px: np.ndarray,
    spread: tuple[float, float, float, float],
    p_false: float,
    *,
    t0: float,
    algorithm: str,
    hypotheses: int,
    database: PairDatabase,
) -> SolveResult:
    """The reported solution of a fitted identification: matched ``obs`` rows of ``stars``
    and ``cat_rows`` of ``cat``, the fitted ``camera`` and attitude, the residuals (n, 2, px),
    ``spread`` = (rms px, 1-sigma boresight and roll arcsec, focal px)."""
    residual = np.sqrt(np.sum(residuals_px**2, axis=1)).tolist()
    matched_id = cat.ids[cat_rows].tolist()
    catalog_id: list[int | None] = [None] * len(stars.xy)
    residual_px: list[float | None] = [None] * len(stars.xy)
    for k, n in enumerate(obs.tolist()):
        catalog_id[n], residual_px[n] = matched_id[k], residual[k]
    xy = stars.xy.tolist()
    star_matches = tuple(
        StarMatch(stars.labels[n], xy[n][0], xy[n][1], catalog_id[n], residual_px[n])
        for n in range(len(xy))
    )
    ra, dec, roll, par = radec_roll_from_attitude(R)
    rms, sigma_boresight, sigma_roll, sigma_focal = spread
    ms = (time.perf_counter() - t0) * 1e3
    solution = Solution(
        ra_deg=ra,
        dec_deg=dec,
        roll_deg=roll,
        parity=par,
        focal_px=camera.focal_px,
        fov_deg=camera.fov_deg,
        rms_px=float(rms),
        sigma_boresight_arcsec=float(sigma_boresight),
        sigma_roll_arcsec=float(sigma_roll),
        sigma_focal_px=float(sigma_focal),
        false_match_probability=float(p_false),
        time_ms=ms,
        R_cam_from_icrs=R,
        stars=star_matches,
        n_matched=len(obs),
        algorithm=algorithm,
        catalog=cat.name,
        k1=camera.k1,
        k2=camera.k2,
    )
    return SolveResult(solution, "", ms, hypotheses, database)


def _shared_rms(a, b) -> tuple[float, float]:
    """Residual rms (px) of the pairs two fits ``(obs, cat_rows, fit, ...)`` share, under
    each fit (inf when they share none)."""
    keys = [
        {pair: n for n, pair in enumerate(zip(x[0].tolist(), x[1].tolist(), strict=True))}
        for x in (a, b)
    ]
    shared = [k for k in keys[0] if k in keys[1]]
    if not shared:
        return float("inf"), float("inf")
    out = []
    for x, key in zip((a, b), keys, strict=True):
        r = x[2].residuals_px[[key[k] for k in shared]]
        out.append(float(np.sqrt(np.mean(np.sum(r**2, axis=1)))))
    return out[0], out[1]


class _Fitter:
    """The attitude fit of an identification: least squares on the matched stars, outliers
    dropped, and the stars the better attitude brings within range taken in, until the set of
    matches stops changing."""

    def __init__(
        self, cat, xy, camera, database, settings, sigma_px, fit_focal, fit_distortion=False
    ) -> None:
        self.cat, self.xy, self.camera, self.database = cat, xy, camera, database
        self.settings, self.sigma_px, self.fit_focal = settings, sigma_px, fit_focal
        self.fit_distortion = fit_distortion

    def fit(self, obs, cat_rows, R):
        return refine_attitude(
            R,
            self.cat.vectors[cat_rows],
            self.xy[obs],
            self.camera,
            fit_focal=self.fit_focal,
            fit_distortion=self.fit_distortion,
        )

    def match(self, fit, radius_rad: float, *, gate: bool = False):
        """Pairs within ``radius_rad`` of the fitted attitude; with ``gate``, each catalog
        star's radius also grows with the attitude's uncertainty (at least the told sigma's)."""
        cov = None
        if gate:
            scale = max(1.0, self.sigma_px**2 / fit.variance_px2) if fit.variance_px2 > 0 else 1
            cov = fit.rotation_cov_rad2 * scale
        return match_catalog(
            fit.camera.pixels_to_bearings(self.xy),
            fit.R_cam_from_icrs,
            self.database,
            radius_rad,
            rotation_cov_rad2=cov,
        )

    def drop_outliers(self, obs, cat_rows, fit):
        """Drop, one at a time, the pair whose studentized residual is beyond what the told
        sigma allows (chi-square, 2 degrees of freedom, 1e-3 over all pairs), refitting each
        time. A wide gate can let in a false star near a real one; the fit then bends
        towards it and its plain residual looks small, its studentized residual does not."""
        while len(obs) > _MIN_FIT_STARS:
            t = fit.studentized(self.sigma_px)
            worst = int(np.argmax(t))
            if t[worst] <= 2.0 * np.log(len(obs) / _OUTLIER_ALPHA):  # P(chi2_2 > x) = e^(-x/2)
                break
            keep = np.arange(len(obs)) != worst
            obs, cat_rows = obs[keep], cat_rows[keep]
            fit = self.fit(obs, cat_rows, fit.R_cam_from_icrs)
        return obs, cat_rows, fit

    def converge(self, obs, cat_rows, R):
        """Fit, drop outliers, rematch; repeat until the matches stop changing. Returns the
        pairs, the fit and the last verification."""
        fit = self.fit(obs, cat_rows, R)
        obs, cat_rows, fit = self.drop_outliers(obs, cat_rows, fit)
        ver = None
        for _ in range(_MAX_REMATCH):
            ver = self.match(fit, self.settings.match_radius_rad, gate=True)
            same = np.array_equal(ver.obs_index, obs) and np.array_equal(ver.cat_index, cat_rows)
            if same or len(ver.obs_index) < len(obs):
                break
            fit = self.fit(ver.obs_index, ver.cat_index, fit.R_cam_from_icrs)
            obs, cat_rows, fit = self.drop_outliers(ver.obs_index, ver.cat_index, fit)
        return obs, cat_rows, fit, ver


def _refusal(
    fit,
    cat,
    cat_rows,
    xy_matched,
    camera,
    *,
    fit_focal,
    p_false,
    max_p,
    n_points,
    min_matched_fraction,
) -> str:
    """Why a fitted identification must not be reported ("" when it may)."""
    R = fit.R_cam_from_icrs
    n_matched = len(xy_matched)
    if not fit_focal and n_matched >= _MIN_STARS_SCALE_CHECK:
        # a wrong focal length biases the attitude beyond its error bars: test the scale
        focal, sigma = free_focal_step(R, cat.vectors[cat_rows], xy_matched, camera)
        df = focal - camera.focal_px
        if abs(df) > 5.0 * sigma and abs(df) > _SCALE_TOLERANCE * camera.focal_px:
            return _wrong_scale(focal, camera)
    if p_false > max_p:
        return _unconvincing(p_false)
    # stars the solution says should be measurable: catalog stars inside the image
    expected = min(n_points, len(project_catalog(cat, R, fit.camera)[0]))
    if n_matched < min_matched_fraction * expected:
        return _too_few(n_matched, expected, min_matched_fraction)
    return ""


def _wrong_scale(focal: float, camera: Camera) -> str:
    return (
        f"the stars fit a focal length of {focal:.1f} px (FOV "
        f"{camera.with_focal(focal).fov_deg:.3f}°), not the {camera.focal_px:.1f} px "
        f"given: correct the field of view or fit the focal length"
    )


def _unconvincing(p_false: float) -> str:
    return f"false-match probability {p_false:.2g} after the fit"


def _too_few(n_matched: int, expected: int, min_matched_fraction: float) -> str:
    return (
        f"only {n_matched} of {expected} stars agree with the best attitude (need "
        f"{min_matched_fraction:.0%}): is the field of view right?"
    )


def solve(
    xy: np.ndarray,
    *,
    width: float,
    height: float | None = None,
    fov_deg: float,
    brightness: np.ndarray | None = None,
    catalog: Catalog | str | Path | None = None,
    **options,
) -> Solution | None:
    """Identify the stars at pixel positions ``xy`` (n, 2) and return the verified attitude.

    ``width``/``height``: image size (px; height defaults to width); ``fov_deg``: horizontal
    field of view; ``brightness``: optional, larger is brighter (only the order is used);
    ``catalog``: a ``Catalog``, a CSV path (``id,ra_deg,dec_deg,mag``) or None for the
    embedded Hipparcos. Other keywords: see ``solve_verbose``. Returns None when no
    identification is convincing. Raises ``StarnavError`` (a ``ValueError``) on bad input.
    """
    return solve_verbose(
        xy,
        width=width,
        height=height,
        fov_deg=fov_deg,
        brightness=brightness,
        catalog=catalog,
        **options,
    ).solution


def best_three_star(
    solution: Solution,
    *,
    width: float,
    height: float | None = None,
    catalog: Catalog | str | Path | None = None,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
    sigma_px: float = 1.0,
) -> tuple[Pointing, tuple[str, ...]]:
    """Three-star pointing with the best triple of a solution's identified stars.

    Picks the three matched stars whose boresight has the smallest predicted error (analytic
    covariance) and solves with them at the solution's focal length; ``sigma_px`` sets the
    reported 1-sigma. Returns the ``Pointing`` and the labels of the stars used.
    ``catalog``, ``mag_limit``, ``epoch_year``: as given to the solve that made ``solution``.
    """
    cat = load_catalog(catalog, mag_limit=mag_limit, epoch_year=epoch_year)
    height = width if height is None else height
    matched = [m for m in solution.stars if m.catalog_id is not None]
    if len(matched) < 3:
        raise StarnavError(f"the solution has {len(matched)} identified stars; 3 are needed")
    rows = cat.rows([m.catalog_id for m in matched])
    xy = np.array([[m.x, m.y] for m in matched])
    triple = list(
        best_triple(
            cat.ra_deg[rows],
            cat.dec_deg[rows],
            xy,
            focal_px=solution.focal_px,
            width=width,
            height=height,
        )
    )
    pointing = three_star(
        cat.ra_deg[rows][triple],
        cat.dec_deg[rows][triple],
        xy=xy[triple],
        width=width,
        height=height,
        focal_px=solution.focal_px,
        sigma_px=sigma_px,
        parity=solution.parity,
    )
    return pointing, tuple(matched[k].label for k in triple)


def _solve_one(job: tuple[np.ndarray, np.ndarray | None, dict]) -> tuple:
    xy, brightness, options = job
    try:
        r = solve_verbose(xy, brightness=brightness, **options)
    except StarnavError as exc:
        return None, f"error: {exc}", 0.0, 0
    return r.solution, r.reason, r.time_ms, r.hypotheses


def solve_batch(
    frames: Sequence[np.ndarray],
    *,
    brightness: Sequence[np.ndarray | None] | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    **options,
) -> list[tuple[Solution | None, str, float]]:
    """Solve many frames (each an (n, 2) array of centroids) with the same camera and options
    (those of ``solve_verbose``), on ``workers`` processes (default: all cores; 1: here).

    Returns, per frame in order, ``(solution or None, reason, time_ms)``; a frame with bad
    input gets None and a reason starting with "error:" instead of stopping the batch.
    ``progress`` is called with the number of frames finished.
    """
    if isinstance(options.get("catalog"), str | Path) or options.get("catalog") is None:
        # load once here, so the workers inherit it (and the database) instead of each loading
        options["catalog"] = load_catalog(
            options.get("catalog"),
            mag_limit=options.pop("mag_limit", None),
            epoch_year=options.pop("epoch_year", None),
        )
    camera = make_camera(
        width=options["width"], height=options.get("height"), fov_deg=options["fov_deg"]
    )
    get_database(options["catalog"], camera)
    lights = brightness if brightness is not None else [None] * len(frames)
    jobs = [(np.asarray(xy, dtype=float), b, options) for xy, b in zip(frames, lights, strict=True)]
    workers = workers or os.cpu_count() or 1
    out = []
    if workers == 1 or len(jobs) < 2:
        for job in jobs:
            out.append(_solve_one(job))
            if progress:
                progress(1)
    else:
        # the first frame here: it loads the compiled code, which forked workers then share
        out.append(_solve_one(jobs[0]))
        if progress:
            progress(1)
        jobs = jobs[1:]
        context = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            for result in pool.map(_solve_one, jobs, chunksize=max(1, len(jobs) // (8 * workers))):
                out.append(result)
                if progress:
                    progress(1)
    return [(solution, reason, ms) for solution, reason, ms, _ in out]
