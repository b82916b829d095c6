"""starnav: star identification, attitude and celestial navigation from star cameras.

The public names below are imported on first use (PEP 562): ``import starnav`` loads none of
numpy, scipy, astropy or numba, and a star-list solve never loads the image stack.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

__version__ = "0.1.0"

# the module each name of __all__ lives in
_HOMES = {
    "FrameResult": "starnav.api",
    "ImageSolveResult": "starnav.api",
    "Solution": "starnav.api",
    "SolveOptions": "starnav.api",
    "SolveResult": "starnav.api",
    "StarMatch": "starnav.api",
    "best_three_star": "starnav.api",
    "solve": "starnav.api",
    "solve_batch": "starnav.api",
    "solve_fov": "starnav.api",
    "solve_image": "starnav.api",
    "solve_stars": "starnav.api",
    "solve_stars_batch": "starnav.api",
    "solve_verbose": "starnav.api",
    "Calibration": "starnav.calibrate",
    "calibrate": "starnav.calibrate",
    "Camera": "starnav.camera",
    "load_camera": "starnav.camera",
    "save_camera": "starnav.camera",
    "Catalog": "starnav.catalog",
    "load_catalog": "starnav.catalog",
    "CameraError": "starnav.errors",
    "CatalogError": "starnav.errors",
    "ImageError": "starnav.errors",
    "StarListError": "starnav.errors",
    "StarnavError": "starnav.errors",
    "SimulatedFrame": "starnav.simulate",
    "simulate_frame": "starnav.simulate",
}

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

if TYPE_CHECKING:
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
    from starnav.errors import (
        CameraError,
        CatalogError,
        ImageError,
        StarListError,
        StarnavError,
    )
    from starnav.simulate import SimulatedFrame, simulate_frame


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'starnav' has no attribute {name!r}")
    value = getattr(import_module(home), name)
    globals()[name] = value  # the next lookup is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
