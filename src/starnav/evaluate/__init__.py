"""Whole-sky evaluation: sampling of boresights, runners (processes / Dask), the scoring rule
(``score``, which the benchmarks share), metrics, reports."""

from starnav.evaluate.kinds import KINDS, make_frame, parse_kinds
from starnav.evaluate.runner import (
    EvalConfig,
    FrameResult,
    OutcomeCounts,
    Summary,
    camera_items,
    evaluate,
    run_evaluation,
    solve_frame,
    summarize,
)
from starnav.evaluate.sampling import Boresights, grid_boresights, uniform_boresights
from starnav.evaluate.score import (
    CORRECT_BORESIGHT_DEG,
    CORRECT_ROLL_DEG,
    CORRECT_SIGMAS,
    AttitudeScore,
    score_attitude,
    score_solution,
)

__all__ = [
    "CORRECT_BORESIGHT_DEG",
    "CORRECT_ROLL_DEG",
    "CORRECT_SIGMAS",
    "KINDS",
    "AttitudeScore",
    "Boresights",
    "EvalConfig",
    "FrameResult",
    "OutcomeCounts",
    "Summary",
    "camera_items",
    "evaluate",
    "grid_boresights",
    "make_frame",
    "parse_kinds",
    "run_evaluation",
    "score_attitude",
    "score_solution",
    "solve_frame",
    "summarize",
    "uniform_boresights",
]
