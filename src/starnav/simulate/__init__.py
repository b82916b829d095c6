"""The truth generator: simulated frames (centroids with their true catalog ids) and images
rendered from them. It shares nothing with the solver (pyproject's import-linter contract), so
the solver is scored against an independent model of the sky and the sensor."""

from starnav.simulate.frames import (
    FALSE_STAR_ID,
    MAX_FALSE_STARS,
    SimulatedFrame,
    draw_radec_roll,
    project_catalog,
    simulate_frame,
    write_frame_csv,
)

__all__ = [
    "FALSE_STAR_ID",
    "MAX_FALSE_STARS",
    "SimulatedFrame",
    "draw_radec_roll",
    "project_catalog",
    "simulate_frame",
    "write_frame_csv",
]
