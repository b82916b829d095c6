"""The public surface: ``solve()`` a star list into a verified attitude, and its results.

Every solve goes through ``starnav.pipeline.Solver``; this module checks the user's numbers,
loads the catalog and keeps the prepared solvers of a process.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from starnav.camera import MODELS, CameraModel, load_camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import CameraError, StarnavError
from starnav.identify import DEFAULT_ALGORITHM
from starnav.pipeline import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    DEFAULT_MIN_MATCHED_FRACTION,
    DEFAULT_SIGMA_PX,
    Solver,
    SolveSettings,
    get_database,
)
from starnav.pipeline.batch import solve_many
from starnav.pipeline.deep import deep_catalog
from starnav.pipeline.solver import check_prior
from starnav.pointing import Pointing, best_triple, three_star
from starnav.results import Solution, SolveResult, StarMatch
from starnav.runtime.budget import Deadline, check_budget, default_budget_s
from starnav.starlist import check_star_list

__all__ = [
    "DEFAULT_MAX_FALSE_MATCH_PROBABILITY",
    "DEFAULT_MIN_MATCHED_FRACTION",
    "DEFAULT_SIGMA_PX",
    "Solution",
    "SolveResult",
    "StarMatch",
    "best_three_star",
    "get_database",
    "make_camera",
    "prepare_solver",
    "solve",
    "solve_batch",
    "solve_verbose",
]

_SOLVERS: dict[tuple, Solver] = {}  # per process: the prepared solvers of recent options
_MAX_SOLVERS = 32


def make_camera(
    *,
    width: float | None = None,
    height: float | None = None,
    fov_deg: float | None = None,
    camera: CameraModel | str | Path | None = None,
    lens: str = "pinhole",
) -> CameraModel:
    """The camera of the user's numbers: a ``camera`` (a camera model or a camera file;
    ``width``/``height`` must then agree with it), or the ``lens`` model (``MODELS``; default
    pinhole) with the horizontal ``fov_deg`` across ``width`` px (height defaults to
    width)."""
    if camera is not None:
        cam = load_camera(camera) if isinstance(camera, str | Path) else camera
        for name, given in (("width", width), ("height", height)):
            if given is not None and given != getattr(cam, name):
                raise CameraError(
                    f"{name} {given:g} disagrees with the camera's {getattr(cam, name)} px"
                )
        return cam
    if lens not in MODELS:
        raise CameraError(f"unknown lens model {lens!r}; known: {', '.join(MODELS)}")
    if fov_deg is None or width is None:
        raise StarnavError("give the field of view and the image width, or a camera file")
    return MODELS[lens].from_fov(fov_deg, width, height)


def known_budget_s(camera: CameraModel) -> float:
    """The default time budget (s) of a solve through a known ``camera``
    (``starnav.runtime.budget``: longer for a field wider than ``WIDE_FIELD_DEG``)."""
    return default_budget_s(known=True, scan=False, field_deg=camera.diagonal_deg)


def solver_for(
    camera: CameraModel,
    catalog: Catalog,
    settings: SolveSettings,
    algorithm: str,
    algorithm_options: Mapping[str, object] | None,
) -> Solver:
    """A prepared ``Solver`` for these options (kept per process, so repeated solves do not
    prepare it again)."""
    options = tuple(sorted(dict(algorithm_options or {}).items()))
    key = (camera, catalog.fingerprint, settings, algorithm, repr(options))
    solver = _SOLVERS.get(key)
    if solver is None:
        if len(_SOLVERS) >= _MAX_SOLVERS:
            _SOLVERS.clear()
        solver = Solver(camera, catalog, algorithm, settings, algorithm_options=dict(options))
        _SOLVERS[key] = solver
    return solver


def solve_verbose(
    xy: np.ndarray,
    *,
    width: float | None = None,
    height: float | None = None,
    fov_deg: float | None = None,
    camera: CameraModel | str | Path | None = None,
    lens: str = "pinhole",
    brightness: np.ndarray | None = None,
    labels: list[str] | tuple[str, ...] | None = None,
    catalog: Catalog | str | Path | None = None,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
    parity: int | None = None,
    sigma_px: float | None = None,
    fit_focal: bool = False,
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    min_matched_fraction: float = DEFAULT_MIN_MATCHED_FRACTION,
    algorithm: str = DEFAULT_ALGORITHM,
    algorithm_options: Mapping[str, object] | None = None,
    prior: Solution | np.ndarray | None = None,
    prior_sigma_deg: float = 1.0,
    time_budget_s: float | None = None,
    deep_mag_limit: float | None = None,
) -> SolveResult:
    """Like ``solve`` but always returns a ``SolveResult`` with the reason when unsolved.

    The camera: ``camera`` (a camera model or a camera file), or the ``lens`` model's
    (``starnav.camera.MODELS``, default pinhole) with the horizontal ``fov_deg`` across
    ``width`` px (``height`` defaults to width).
    ``labels``: a name per star (default "1", "2", ...); ``mag_limit``, ``epoch_year``: for
    the embedded Hipparcos catalog (see ``load_catalog``); ``parity``: +1 / -1 when known;
    ``sigma_px``: 1-sigma centroid error (px), which sets the matching tolerances (None:
    not known; the tolerances allow ``DEFAULT_SIGMA_PX`` and the false-match probability
    takes the sigma the residuals fit best);
    ``fit_focal``: fit the focal length with the attitude;
    ``max_false_match_probability``: refuse less certain identifications;
    ``min_matched_fraction``: refuse when fewer of the stars that should be seen (the smaller
    of the number of points and of catalog stars inside the image) agree;
    ``algorithm``: identification algorithm by name (``starnav.identify.ALGORITHMS``);
    ``algorithm_options``: keyword options of that algorithm's class (e.g.
    ``{"selection": "brightest"}`` for ``triangle``); ``prior``: the previous attitude (a
    ``Solution`` or ``R_cam_from_icrs``), good to ``prior_sigma_deg`` (1-sigma): tracking mode
    matches the catalog stars near it only, and falls back to ``algorithm`` when that fails
    (``Solution.algorithm`` says which answered); ``time_budget_s``: give up after this many
    seconds of identification, "time budget spent" (default ``known_budget_s``;
    ``math.inf``: no limit; preparing the catalog and database is not counted);
    ``deep_mag_limit``: after the fit, match every point to the same catalog down to this
    magnitude (e.g. 12 for a 6° star tracker; no pair table of it is built), which gives ids
    to stars fainter than ``mag_limit`` with a per-star ``match_probability`` and an
    unresolved ``double`` flag in the star table (``starnav.pipeline.deep``); None (the
    default): no deep stage.
    """
    cam = make_camera(width=width, height=height, fov_deg=fov_deg, camera=camera, lens=lens)
    budget_s = check_budget(time_budget_s, known_budget_s(cam))
    stars = check_star_list(
        xy, width=cam.width, height=cam.height, brightness=brightness, labels=labels
    )
    R_prior = check_prior(prior, prior_sigma_deg)
    solver = prepare_solver(
        camera=cam,
        catalog=catalog,
        mag_limit=mag_limit,
        epoch_year=epoch_year,
        parity=parity,
        sigma_px=sigma_px,
        fit_focal=fit_focal,
        max_false_match_probability=max_false_match_probability,
        min_matched_fraction=min_matched_fraction,
        algorithm=algorithm,
        algorithm_options=algorithm_options,
        deep_mag_limit=deep_mag_limit,
    )
    deadline = Deadline.after(budget_s)
    return solver.solve(stars, prior=R_prior, prior_sigma_deg=prior_sigma_deg, deadline=deadline)


def prepare_solver(
    *,
    width: float | None = None,
    height: float | None = None,
    fov_deg: float | None = None,
    camera: CameraModel | str | Path | None = None,
    lens: str = "pinhole",
    catalog: Catalog | str | Path | None = None,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
    algorithm: str = DEFAULT_ALGORITHM,
    algorithm_options: Mapping[str, object] | None = None,
    deep_mag_limit: float | None = None,
    **settings,
) -> Solver:
    """The prepared ``Solver`` of ``solve_verbose``'s options (checked, one-line errors):
    the camera (``make_camera``), catalog and algorithm, and ``settings``, the fields of
    ``SolveSettings`` (``sigma_px``, ``parity``, ``fit_focal``, ...); ``deep_mag_limit``:
    the deep stage's catalog depth (``solve_verbose``). Kept per process, so repeated solves
    do not prepare it again."""
    cam = make_camera(width=width, height=height, fov_deg=fov_deg, camera=camera, lens=lens)
    deep = deep_catalog(catalog, deep_mag_limit, epoch_year)
    try:
        solve_settings = SolveSettings(**settings, deep_catalog=deep)
    except TypeError as exc:  # an option solve does not have
        raise StarnavError(f"unknown solve option: {exc}") from None
    cat = load_catalog(catalog, mag_limit=mag_limit, epoch_year=epoch_year)
    return solver_for(cam, cat, solve_settings, algorithm, algorithm_options)


def solve(
    xy: np.ndarray,
    *,
    width: float | None = None,
    height: float | None = None,
    fov_deg: float | None = None,
    brightness: np.ndarray | None = None,
    catalog: Catalog | str | Path | None = None,
    **options,
) -> Solution | None:
    """Identify the stars at pixel positions ``xy`` (n, 2) and return the verified attitude.

    ``width``/``height``: image size (px; height defaults to width); ``fov_deg``: horizontal
    field of view (or ``camera=``: a camera model or file, see ``solve_verbose``);
    ``brightness``: optional, larger is brighter (only the order is used);
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
    prior = options.pop("prior", None)
    prior_sigma_deg = options.pop("prior_sigma_deg", 1.0)
    time_budget_s = options.pop("time_budget_s", None)
    R_prior = check_prior(prior, prior_sigma_deg)
    solver = prepare_solver(**options)
    budget_s = check_budget(time_budget_s, known_budget_s(solver.camera))
    lights = brightness if brightness is not None else [None] * len(frames)
    jobs = [(np.asarray(xy, dtype=float), b) for xy, b in zip(frames, lights, strict=True)]
    return solve_many(
        solver,
        jobs,
        workers=workers,
        progress=progress,
        prior=R_prior,
        prior_sigma_deg=prior_sigma_deg,
        time_budget_s=budget_s,
    )
