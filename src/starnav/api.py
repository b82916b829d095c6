"""The public surface: ``solve_stars`` / ``solve`` a star list, ``solve_image`` an image,
``solve_stars_batch`` many lists, each with one ``SolveOptions``; their results.

Every solve goes through ``starnav.pipeline`` (``pipeline.stars.solve_stars`` decides once how
a list is solved); this module takes the user's arguments and keeps the old names working,
with a ``DeprecationWarning``, for one release.

``solve_image`` and ``ImageSolveResult`` are imported from ``pipeline.image`` on first use
(module ``__getattr__``), and ``best_three_star`` imports ``starnav.pointing`` when called: a
star-list solve loads neither the image stack (astropy, sep, scipy.ndimage) nor scipy.optimize.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.pipeline import stars as _stars
from starnav.pipeline.batch import solve_frames
from starnav.pipeline.options import (
    DEFAULT_FOV_RANGE_DEG,
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    DEFAULT_MIN_MATCHED_FRACTION,
    DEFAULT_SIGMA_PX,
    SolveOptions,
)
from starnav.pipeline.solver import Solver, get_database
from starnav.pipeline.stars import make_camera
from starnav.results import FrameResult, Solution, SolveResult, StarMatch
from starnav.starlist import StarList

if TYPE_CHECKING:
    from starnav.pipeline.image import ImageSolveResult, solve_image
    from starnav.pointing import Pointing

__all__ = [
    "DEFAULT_MAX_FALSE_MATCH_PROBABILITY",
    "DEFAULT_MIN_MATCHED_FRACTION",
    "DEFAULT_SIGMA_PX",
    "FrameResult",
    "ImageSolveResult",
    "Solution",
    "SolveOptions",
    "SolveResult",
    "StarMatch",
    "best_three_star",
    "get_database",
    "make_camera",
    "prepare_solver",
    "solve",
    "solve_batch",
    "solve_fov",
    "solve_image",
    "solve_stars",
    "solve_stars_batch",
    "solve_verbose",
]

_IMAGE_NAMES = ("ImageSolveResult", "solve_image")  # from starnav.pipeline.image, on first use


def __getattr__(name: str):
    if name not in _IMAGE_NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from starnav.pipeline import image

    value = getattr(image, name)
    globals()[name] = value  # the next lookup is a plain attribute
    return value


def solve_stars(
    xy: np.ndarray | StarList,
    options: SolveOptions | None = None,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: np.ndarray | None = None,
    labels: Sequence[str] | None = None,
    prior: Solution | np.ndarray | None = None,
    position_hint_deg: tuple[float, float] | None = None,
    **option_fields: Any,
) -> SolveResult:
    """Identify the stars at pixel positions ``xy`` (n, 2; origin top-left) and fit the
    attitude; the ``SolveResult`` holds the ``Solution`` or the reason there is none.

    ``options``: a ``SolveOptions`` (keyword ``option_fields`` override its fields, e.g.
    ``fov_deg=12``); ``width``/``height``: the image size (px; height defaults to width; a
    camera gives its own); ``brightness``: larger is brighter (only the order and the
    magnitude differences are used); ``labels``: a name per star (default "1", "2", ...);
    ``prior``: the previous attitude (a ``Solution`` or ``R_cam_from_icrs``), good to
    ``options.prior_sigma_deg``: tracking, falling back to lost in space;
    ``position_hint_deg``: (RA, Dec) of the boresight, roughly, searched first when the
    field of view is searched. With ``fov_deg`` or a ``camera`` the field is taken as given
    (``fov_exact=False``: searched near it); without either it is searched in
    ``fov_range_deg`` (a fisheye lens's focal length is scanned). Raises ``StarnavError`` (a
    ``ValueError``) with a one-line message on bad input.
    """
    return _stars.solve_stars(
        xy,
        SolveOptions.make(options, **option_fields),
        width=width,
        height=height,
        brightness=brightness,
        labels=labels,
        prior=prior,
        position_hint_deg=position_hint_deg,
    )


def solve(
    xy: np.ndarray | StarList,
    options: SolveOptions | None = None,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: np.ndarray | None = None,
    **keywords: Any,
) -> Solution | None:
    """``solve_stars(...).solution``: the verified attitude of the stars at ``xy`` (n, 2,
    px), or None when no identification is convincing. Arguments as ``solve_stars``."""
    return solve_stars(
        xy, options, width=width, height=height, brightness=brightness, **keywords
    ).solution


def prepare_solver(
    options: SolveOptions | None = None,
    *,
    width: float | None = None,
    height: float | None = None,
    **option_fields: Any,
) -> Solver:
    """The prepared ``Solver`` of a known field (``fov_deg`` across ``width`` px, or a
    ``camera``) and ``options``, kept per process: what ``solve_stars`` uses, for callers
    that solve many lists themselves (``Solver.solve``)."""
    opts = SolveOptions.make(options, **option_fields)
    return _stars.prepare_solver(opts, width=width, height=height)


def solve_stars_batch(
    frames: Sequence[np.ndarray],
    options: SolveOptions | None = None,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: Sequence[np.ndarray | None] | None = None,
    prior: Solution | np.ndarray | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    **option_fields: Any,
) -> list[FrameResult]:
    """Solve many frames (each an (n, 2) array of centroids, px) of one camera with the same
    ``options`` (the field given: ``fov_deg`` or ``camera``), on ``workers`` processes
    (default: all cores; 1: here). Returns one ``FrameResult`` per frame in order; a frame
    with bad input gets its message as ``error`` instead of stopping the batch.
    ``progress`` is called with the number of frames finished."""
    opts = SolveOptions.make(options, **option_fields)
    return solve_frames(
        frames,
        opts,
        width=width,
        height=height,
        brightness=brightness,
        prior=prior,
        workers=workers,
        progress=progress,
    )


def _deprecated(old: str, new: str) -> None:
    warnings.warn(
        f"starnav.{old} is deprecated and will be removed in the next release: use {new}",
        DeprecationWarning,
        stacklevel=3,
    )


def solve_verbose(xy: np.ndarray, **keywords: Any) -> SolveResult:
    """Deprecated: ``solve_stars`` (the same arguments)."""
    _deprecated("solve_verbose", "starnav.solve_stars")
    return solve_stars(xy, **keywords)


def solve_fov(
    xy: np.ndarray,
    *,
    width: float,
    height: float | None = None,
    brightness: np.ndarray | None = None,
    labels: Sequence[str] | None = None,
    fov_range_deg: tuple[float, float] | None = None,
    prior: np.ndarray | None = None,
    position_hint_deg: tuple[float, float] | None = None,
    **option_fields: Any,
) -> SolveResult:
    """Deprecated: ``solve_stars`` without ``fov_deg`` searches the field of view
    (``fov_exact=False`` searches near a given ``fov_deg`` or ``camera``, as this did)."""
    _deprecated("solve_fov", "starnav.solve_stars (fov_exact=False near a given field)")
    if fov_range_deg is not None and tuple(fov_range_deg) == DEFAULT_FOV_RANGE_DEG:
        fov_range_deg = None  # this function's default: the lens model's own range
    options = SolveOptions.make(fov_range_deg=fov_range_deg, fov_exact=False, **option_fields)
    return _stars.solve_stars(
        xy,
        options,
        width=width,
        height=height,
        brightness=brightness,
        labels=labels,
        prior=prior,
        position_hint_deg=position_hint_deg,
        images=True,
    )


def solve_batch(
    frames: Sequence[np.ndarray], **keywords: Any
) -> list[tuple[Solution | None, str, float]]:
    """Deprecated: ``solve_stars_batch``, which returns ``FrameResult`` records; this gives
    ``(solution or None, reason, time_ms)`` tuples, a bad frame's reason "error: ..."."""
    _deprecated("solve_batch", "starnav.solve_stars_batch")
    return [
        (r.solution, f"error: {r.error}" if r.bad_input else r.reason, r.time_ms)
        for r in solve_stars_batch(frames, **keywords)
    ]


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
    from starnav.pointing import best_triple, three_star

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
