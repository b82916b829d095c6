"""Whole-sky evaluation: sampling of boresights, runners (processes / Dask), metrics, reports."""

from starnav.evaluate.runner import (
    EvalConfig,
    FrameResult,
    Summary,
    camera_items,
    evaluate,
    run_evaluation,
    solve_frame,
    summarize,
)
from starnav.evaluate.sampling import Boresights, grid_boresights, uniform_boresights

__all__ = [
    "Boresights",
    "EvalConfig",
    "FrameResult",
    "Summary",
    "camera_items",
    "evaluate",
    "grid_boresights",
    "run_evaluation",
    "solve_frame",
    "summarize",
    "uniform_boresights",
]
