"""starnav: star identification, attitude and celestial navigation from star cameras."""

from starnav.api import (
    FrameResult,
    ImageSolveResult,
    Solution,
    SolveOptions,
    SolveResult,
    StarMatch,
    best_three_star,
    solve,
    solve_batch,
    solve_fov,
    solve_image,
    solve_stars,
    solve_stars_batch,
    solve_verbose,
)
from starnav.calibrate import Calibration, calibrate
from starnav.camera import Camera, load_camera, save_camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import CameraError, CatalogError, ImageError, StarListError, StarnavError
from starnav.simulate import SimulatedFrame, simulate_frame

__version__ = "0.1.0"

__all__ = [
    "Calibration",
    "Camera",
    "CameraError",
    "Catalog",
    "CatalogError",
    "FrameResult",
    "ImageError",
    "ImageSolveResult",
    "SimulatedFrame",
    "Solution",
    "SolveOptions",
    "SolveResult",
    "StarListError",
    "StarMatch",
    "StarnavError",
    "best_three_star",
    "calibrate",
    "load_camera",
    "load_catalog",
    "save_camera",
    "simulate_frame",
    "solve",
    "solve_batch",
    "solve_fov",
    "solve_image",
    "solve_stars",
    "solve_stars_batch",
    "solve_verbose",
]
