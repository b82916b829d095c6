"""starnav: star identification, attitude and celestial navigation from star cameras."""

from starnav.api import (
    Solution,
    SolveResult,
    StarMatch,
    best_three_star,
    solve,
    solve_batch,
    solve_verbose,
)
from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import CameraError, CatalogError, StarListError, StarnavError
from starnav.simulate import SimulatedFrame, simulate_frame

__version__ = "0.1.0"

__all__ = [
    "Camera",
    "CameraError",
    "Catalog",
    "CatalogError",
    "SimulatedFrame",
    "Solution",
    "SolveResult",
    "StarListError",
    "StarMatch",
    "StarnavError",
    "best_three_star",
    "load_catalog",
    "simulate_frame",
    "solve",
    "solve_batch",
    "solve_verbose",
]
