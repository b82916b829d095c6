"""One star list to a verified attitude: the one place that decides how it is solved.

``solve_stars`` looks at the ``SolveOptions`` once: a field given exactly (``fov_deg`` or a
``camera``) is identified through a prepared ``Solver`` (tracking first when a prior is
given); otherwise the pinhole FOV search, or a fisheye's focal scan, runs
(``pipeline.fov``), and with a prior and a camera, tracking with that camera.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from starnav.camera import CameraModel, model_class
from starnav.catalog import load_catalog
from starnav.errors import CameraError, StarnavError
from starnav.identify import DEFAULT_ALGORITHM
from starnav.pipeline.fov import known_field_depth, solve_unknown_field
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.solver import Solver, SolveSettings, check_prior
from starnav.pipeline.unordered import solve_unordered
from starnav.results import Solution, SolveResult
from starnav.runtime.budget import Deadline, check_budget, default_budget_s
from starnav.runtime.caches import process_cache
from starnav.starlist import StarList, check_star_list

if TYPE_CHECKING:  # the detection stack (sep) is not loaded for a star list's solve
    from starnav.detect.circle import ImageCircle

_SOLVERS = process_cache("prepared solvers", max_items=32)  # of recent options


def make_camera(
    *,
    width: float | None = None,
    height: float | None = None,
    fov_deg: float | None = None,
    camera: CameraModel | None = None,
    lens: str = "pinhole",
) -> CameraModel:
    """The camera of the user's numbers: ``camera`` (``width``/``height`` must then agree
    with it), or the ``lens`` model with the horizontal ``fov_deg`` across ``width`` px
    (height defaults to width)."""
    if camera is not None:
        for name, given in (("width", width), ("height", height)):
            if given is not None and given != getattr(camera, name):
                raise CameraError(
                    f"{name} {given:g} disagrees with the camera's {getattr(camera, name)} px"
                )
        return camera
    if fov_deg is None or width is None:
        raise StarnavError("give the field of view and the image width, or a camera file")
    return model_class(lens).from_fov(fov_deg, width, height)


def known_budget_s(camera: CameraModel) -> float:
    """The default time budget (s) of a solve through a known ``camera``
    (``starnav.runtime.budget``: longer for a field wider than ``WIDE_FIELD_DEG``)."""
    return default_budget_s(known=True, scan=False, field_deg=camera.diagonal_deg)


def prepare_solver(
    options: SolveOptions, *, width: float | None = None, height: float | None = None
) -> Solver:
    """The prepared ``Solver`` of a known field (``options.fov_deg`` across ``width`` px, or
    ``options.camera``), kept per process so repeated solves do not prepare it again."""
    camera = make_camera(
        width=width,
        height=height,
        fov_deg=options.fov_deg,
        camera=options.camera,
        lens=options.lens_model,
    )
    mag_limit, deep_mag_limit = known_field_depth(camera, options)
    settings = SolveSettings.from_options(options, deep_mag_limit=deep_mag_limit)
    catalog = load_catalog(options.catalog, mag_limit=mag_limit, epoch_year=options.epoch_year)
    key = (
        camera,
        catalog.fingerprint,
        settings,
        options.algorithm,
        repr(options.algorithm_options),
    )
    solver = _SOLVERS.get(key)
    if solver is None:
        solver = Solver(
            camera,
            catalog,
            options.algorithm,
            settings,
            algorithm_options=options.algorithm_kwargs,
        )
        _SOLVERS[key] = solver
    return solver


def exact_field(options: SolveOptions, *, images: bool = False) -> bool:
    """Whether the field is identified as given (a known camera through ``Solver``) rather
    than searched: a ``fov_deg`` or ``camera`` given, and ``fov_exact`` (default: exact for
    star lists, approximate for ``images``)."""
    exact = options.fov_exact if options.fov_exact is not None else not images
    return options.field_known and exact


def check_searched(options: SolveOptions, *, prior: bool = False) -> None:
    """A one-line error for the options a searched field cannot take: the FOV search and the
    focal scan identify in their own way, on their own catalogs (another ``algorithm`` or its
    options, a pinhole ``mag_limit``), and tracking needs a field (a ``prior`` without one).
    Called before any work on a field that will be searched."""
    needing = {
        "prior": prior and not options.field_known,
        "algorithm": options.algorithm != DEFAULT_ALGORITHM,
        "algorithm_options": bool(options.algorithm_options),
        "mag_limit": options.mag_limit is not None and not options.scans_focal,
    }
    if any(needing.values()):
        names = ", ".join(name for name, given in needing.items() if given)
        raise StarnavError(
            f"{names} need fov_deg or a camera taken as exact (the FOV search chooses its own)"
        )


def solve_stars(
    xy: np.ndarray | StarList,
    options: SolveOptions,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: np.ndarray | None = None,
    labels: list[str] | tuple[str, ...] | None = None,
    prior: Solution | np.ndarray | None = None,
    position_hint_deg: tuple[float, float] | None = None,
    images: bool = False,
    image_circle: ImageCircle | None = None,
    ranked: bool = True,
) -> SolveResult:
    """Solve one star list (``xy`` (n, 2) px with ``brightness``, larger is brighter, and
    ``labels``, or a ``StarList``) in a ``width`` x ``height`` px image with ``options``.
    ``prior``: the previous attitude (a ``Solution`` or ``R_cam_from_icrs``), good to
    ``options.prior_sigma_deg``; ``position_hint_deg``: (RA, Dec) of the boresight, roughly
    (the FOV search looks near it first); ``images``: whether the list was detected in an
    image (its given field is then approximate unless ``options.fov_exact``); ``image_circle``:
    a circular fisheye's image circle (``detect.circle``), where a focal scan starts. Options the
    FOV search cannot take (another algorithm, a magnitude limit, a prior without a field)
    are refused, not ignored. ``ranked``: whether the rows are brightest first when no
    ``brightness`` is given; False (a source list in no brightness order): a searched field
    is identified by the patterns of neighbouring points (``pipeline.unordered``)."""
    if isinstance(xy, StarList):
        xy, brightness, labels = xy.xy, xy.brightness, xy.labels
    R_prior = check_prior(prior)
    if exact_field(options, images=images):
        solver = prepare_solver(options, width=width, height=height)
        budget_s = check_budget(options.time_budget_s, known_budget_s(solver.camera))
        cam = solver.camera
        stars = check_star_list(
            xy, width=cam.width, height=cam.height, brightness=brightness, labels=labels
        )
        return solver.solve(
            stars,
            prior=R_prior,
            prior_sigma_deg=options.prior_sigma_deg,
            deadline=Deadline.after(budget_s),
        )
    check_searched(options, prior=R_prior is not None)
    if not ranked and brightness is None and R_prior is None and not options.scans_focal:
        return solve_unordered(
            xy, options, width=width, height=height, position_hint_deg=position_hint_deg
        )
    return solve_unknown_field(
        xy,
        options,
        width=width,
        height=height,
        brightness=brightness,
        labels=labels,
        prior=R_prior,
        position_hint_deg=position_hint_deg,
        image_circle=image_circle,
    )
