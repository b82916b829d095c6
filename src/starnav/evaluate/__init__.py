"""Whole-sky evaluation: sampling of boresights, runners (processes / Dask), metrics, reports."""

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

__all__ = [
    "KINDS",
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
    "solve_frame",
    "summarize",
    "uniform_boresights",
]
