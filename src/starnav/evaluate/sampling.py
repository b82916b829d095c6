"""Where the simulated frames of an evaluation point: a regular RA/Dec grid or uniform on the
sphere. Every frame is reproducible from (seed, index) alone, so a frame can be remade in any
worker process without shipping it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.errors import StarnavError, shown


@dataclass(frozen=True)
class Boresights:
    """Boresight ``ra_deg``, ``dec_deg`` and ``roll_deg`` of every frame (arrays, degrees)."""

    ra_deg: np.ndarray
    dec_deg: np.ndarray
    roll_deg: np.ndarray

    def __len__(self) -> int:
        return len(self.ra_deg)


def grid_boresights(step_deg: float = 3.0, *, seed: int = 0) -> Boresights:
    """RA 0, step, ... < 360 and Dec from -90 + step/2 to 90 - step/2 in ``step_deg`` steps
    (3°: 120 x 60 = 7200 boresights, the published grid); roll uniform at random from ``seed``."""
    if not (np.isfinite(step_deg) and 0.1 <= step_deg <= 90.0):
        raise StarnavError(f"grid step must be between 0.1 and 90 degrees, got {shown(step_deg)}")
    ra = np.arange(0.0, 360.0 - 1e-9, step_deg)
    dec = np.arange(-90.0 + step_deg / 2.0, 90.0, step_deg)
    dec_grid, ra_grid = np.meshgrid(dec, ra, indexing="ij")
    rng = np.random.default_rng([seed, 1])
    return Boresights(ra_grid.ravel(), dec_grid.ravel(), rng.uniform(0.0, 360.0, ra_grid.size))


def uniform_boresights(frames: int, *, seed: int = 0) -> Boresights:
    """``frames`` boresights uniform on the sphere with uniform random roll, from ``seed``."""
    if frames < 1:
        raise StarnavError(f"the number of frames must be at least 1, got {shown(frames)}")
    rng = np.random.default_rng([seed, 2])
    ra = rng.uniform(0.0, 360.0, frames)
    dec = np.degrees(np.arcsin(rng.uniform(-1.0, 1.0, frames)))
    return Boresights(ra, dec, rng.uniform(0.0, 360.0, frames))


def frame_rng(seed: int, index: int) -> np.random.Generator:
    """The random generator of frame ``index`` (noise, false and missing stars)."""
    return np.random.default_rng([seed, 3, index])
