"""Many frames through one prepared ``Solver``, here or on a pool of processes.

Workers are forked after the solver is prepared and its machine code loaded (the parent solves
the first frame), so they share its catalog, database and code instead of loading them again.
A frame with bad input gets its one-line error as data (``FrameResult.error``); it never
stops the batch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from starnav.errors import StarnavError
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.solver import Solver, check_prior
from starnav.pipeline.stars import exact_field, known_budget_s, prepare_solver
from starnav.results import FrameResult, Solution
from starnav.runtime.budget import Deadline, check_budget
from starnav.runtime.pools import process_pool, worker_count
from starnav.starlist import check_star_list

Frame = tuple[np.ndarray, np.ndarray | None]  # centroids (n, 2, px) and brightness or None
_WORKER: dict[str, object] = {}  # the solver and prior of a worker process


def _init(
    solver: Solver, prior: np.ndarray | None, prior_sigma_deg: float, time_budget_s: float
) -> None:
    _WORKER.update(
        solver=solver, prior=prior, prior_sigma_deg=prior_sigma_deg, time_budget_s=time_budget_s
    )


def _solve_one(frame: Frame) -> FrameResult:
    solver: Solver = _WORKER["solver"]  # type: ignore[assignment]
    xy, brightness = frame
    camera = solver.camera
    try:
        stars = check_star_list(xy, width=camera.width, height=camera.height, brightness=brightness)
    except StarnavError as exc:
        return FrameResult(None, str(exc), 0.0, error=str(exc))
    r = solver.solve(
        stars,
        prior=_WORKER["prior"],
        prior_sigma_deg=_WORKER["prior_sigma_deg"],
        deadline=Deadline.after(_WORKER["time_budget_s"]),
    )
    return FrameResult(r.solution, r.reason, r.time_ms)


def solve_many(
    solver: Solver,
    frames: Sequence[Frame],
    *,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    prior: np.ndarray | None = None,
    prior_sigma_deg: float = 1.0,
    time_budget_s: float = math.inf,
) -> list[FrameResult]:
    """The ``FrameResult`` of each frame, in order, on ``workers``
    processes (default: all cores; 1: here); ``progress`` is called with the number of frames
    finished; ``time_budget_s``: each frame's (``starnav.runtime.budget``)."""
    _init(solver, prior, prior_sigma_deg, time_budget_s)
    workers = worker_count(workers)
    out = []
    todo = list(frames)
    if workers == 1 or len(todo) < 2:
        for frame in todo:
            out.append(_solve_one(frame))
            if progress:
                progress(1)
        return out
    out.append(_solve_one(todo[0]))  # loads the machine code, which forked workers share
    if progress:
        progress(1)
    todo = todo[1:]
    with process_pool(
        workers,
        initializer=_init,
        initargs=(solver, prior, prior_sigma_deg, time_budget_s),
    ) as pool:
        chunk = max(1, len(todo) // (8 * workers))
        for result in pool.map(_solve_one, todo, chunksize=chunk):
            out.append(result)
            if progress:
                progress(1)
    return out


def solve_frames(
    frames: Sequence[np.ndarray],
    options: SolveOptions,
    *,
    width: float | None = None,
    height: float | None = None,
    brightness: Sequence[np.ndarray | None] | None = None,
    prior: Solution | np.ndarray | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[FrameResult]:
    """Many star lists (each (n, 2) px) of one known field (``options.fov_deg`` across
    ``width`` px, or ``options.camera``) through one prepared solver (``solve_many``);
    ``prior``: every frame's prior attitude (a ``Solution`` or ``R_cam_from_icrs``)."""
    if not exact_field(options):
        raise StarnavError("a batch of star lists needs fov_deg or a camera")
    prior = check_prior(prior)
    solver = prepare_solver(options, width=width, height=height)
    budget_s = check_budget(options.time_budget_s, known_budget_s(solver.camera))
    lights = brightness if brightness is not None else [None] * len(frames)
    jobs = [(np.asarray(xy, dtype=float), b) for xy, b in zip(frames, lights, strict=True)]
    return solve_many(
        solver,
        jobs,
        workers=workers,
        progress=progress,
        prior=prior,
        prior_sigma_deg=options.prior_sigma_deg,
        time_budget_s=budget_s,
    )
