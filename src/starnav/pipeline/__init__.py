"""The solve pipeline: the ``Solver`` object and the fit policy every solve shares."""

from starnav.pipeline.solver import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    DEFAULT_MIN_MATCHED_FRACTION,
    DEFAULT_SIGMA_PX,
    Solver,
    SolveSettings,
    get_database,
)

__all__ = [
    "DEFAULT_MAX_FALSE_MATCH_PROBABILITY",
    "DEFAULT_MIN_MATCHED_FRACTION",
    "DEFAULT_SIGMA_PX",
    "SolveSettings",
    "Solver",
    "get_database",
]
