"""Simulated star-tracker frames (centroids) from a catalog at a known attitude.

Stars are projected with the pinhole model (``starnav.camera``); those landing inside the image
are kept, brightest first. Errors: Gaussian centroid noise, a fraction of stars dropped, false
stars at random positions, Gaussian magnitude noise. The true catalog id of every point is
carried beside it (-1 for a false star) so every stage can be scored.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from starnav.camera import Camera
from starnav.catalog import Catalog
from starnav.errors import StarnavError, shown
from starnav.geometry import (
    attitude_difference_deg,
    attitude_from_radec_roll,
    radec_roll_from_attitude,
)
from starnav.runtime.csvrows import write_rows

if TYPE_CHECKING:
    from starnav.results import Solution

FALSE_STAR_ID = -1
MAX_FALSE_STARS = 10000


@dataclass(frozen=True, eq=False)
class SimulatedFrame:
    """Centroids ``xy`` (n, 2, px), ``mag`` and ``brightness`` (10**(-0.4 mag)) per point,
    ``true_id`` (catalog id, -1 for false stars), the true attitude and the camera.
    ``n_in_view``: catalog stars (within the magnitude limit) inside the image before drops."""

    xy: np.ndarray
    mag: np.ndarray
    true_id: np.ndarray
    R_cam_from_icrs: np.ndarray
    camera: Camera
    n_in_view: int

    @property
    def brightness(self) -> np.ndarray:
        return 10.0 ** (-0.4 * self.mag)

    @property
    def truth(self) -> tuple[float, float, float, int]:
        """(ra_deg, dec_deg, roll_deg, parity) of the true attitude."""
        return radec_roll_from_attitude(self.R_cam_from_icrs)

    def to_dict(self) -> dict:
        """The truth as a JSON-ready dict: attitude, focal length, matrix (nested lists),
        ``n_points`` given, ``n_in_view`` catalog stars in the image, ``n_false`` false stars."""
        ra, dec, roll, parity = self.truth
        return {
            "ra_deg": ra,
            "dec_deg": dec,
            "roll_deg": roll,
            "parity": parity,
            "focal_px": self.camera.focal_px,
            "R_cam_from_icrs": self.R_cam_from_icrs.tolist(),
            "n_points": len(self.xy),
            "n_in_view": self.n_in_view,
            "n_false": int(np.sum(self.true_id == FALSE_STAR_ID)),
        }

    def compare(self, solution: Solution | None) -> dict | None:
        """How a ``Solution`` of this frame compares with the truth (None for no solution):
        attitude errors (arcsec) and the points identified right, identified wrong (a catalog
        id other than their own) and false stars left unidentified."""
        if solution is None:
            return None
        ids = solution.star_table.catalog_id
        boresight_deg, roll_deg = attitude_difference_deg(
            solution.R_cam_from_icrs, self.R_cam_from_icrs
        )
        return {
            "boresight_error_arcsec": boresight_deg * 3600.0,
            "roll_error_arcsec": roll_deg * 3600.0,
            "ids_correct": int(np.sum((ids == self.true_id) & (ids != -1))),
            "ids_wrong": int(np.sum((ids != self.true_id) & (ids != -1))),
            "false_stars_refused": int(np.sum((ids == -1) & (self.true_id == FALSE_STAR_ID))),
        }


def write_frame_csv(path: str | Path, frame: SimulatedFrame) -> None:
    """The frame as a star list CSV (``label,x,y,mag,true_catalog_id``; the id empty for a
    false star) that ``starnav identify`` reads; ``StarnavError`` when it cannot be written."""
    rows = [
        [n + 1, f"{x:.4f}", f"{y:.4f}", f"{mag:.3f}", "" if cid == FALSE_STAR_ID else int(cid)]
        for n, ((x, y), mag, cid) in enumerate(zip(frame.xy, frame.mag, frame.true_id, strict=True))
    ]
    write_rows(path, ["label", "x", "y", "mag", "true_catalog_id"], rows)


def draw_radec_roll(
    rng: np.random.Generator,
    ra_deg: float | None = None,
    dec_deg: float | None = None,
    roll_deg: float | None = None,
) -> tuple[float, float, float]:
    """(ra_deg, dec_deg, roll_deg) with each missing value drawn from ``rng``, in that order:
    the boresight uniform on the sky, the roll uniform in 0..360."""
    if ra_deg is None:
        ra_deg = rng.uniform(0.0, 360.0)
    if dec_deg is None:
        dec_deg = np.degrees(np.arcsin(rng.uniform(-1.0, 1.0)))
    if roll_deg is None:
        roll_deg = rng.uniform(0.0, 360.0)
    return ra_deg, dec_deg, roll_deg


def project_catalog(
    catalog: Catalog, R_cam_from_icrs: np.ndarray, camera: Camera
) -> tuple[np.ndarray, np.ndarray]:
    """Catalog rows inside the image and their exact pixel positions (no noise)."""
    c = catalog.vectors @ np.asarray(R_cam_from_icrs).T
    rows = np.flatnonzero(camera.sees(c))
    return rows, camera.bearings_to_pixels(c[rows])


def simulate_frame(
    catalog: Catalog,
    camera: Camera,
    *,
    ra_deg: float | None = None,
    dec_deg: float | None = None,
    roll_deg: float | None = None,
    parity: int = 1,
    R_cam_from_icrs: np.ndarray | None = None,
    mag_limit: float | None = None,
    noise_px: float = 0.0,
    false_stars: int = 0,
    missing_frac: float = 0.0,
    mag_noise: float = 0.0,
    seed: int | np.random.Generator | None = None,
) -> SimulatedFrame:
    """One frame at the attitude given by (ra_deg, dec_deg, roll_deg, parity) or by
    ``R_cam_from_icrs``; missing values of the former are drawn at random (uniform sky)."""
    for name, value in (("noise_px", noise_px), ("mag_noise", mag_noise)):
        if not (np.isfinite(value) and value >= 0):
            raise StarnavError(f"{name} must be >= 0, got {shown(value)}")
    if not 0.0 <= missing_frac < 1.0:
        raise StarnavError(f"missing_frac must be in [0, 1), got {shown(missing_frac)}")
    if not 0 <= false_stars <= MAX_FALSE_STARS:
        raise StarnavError(f"false_stars must be in 0..{MAX_FALSE_STARS}, got {shown(false_stars)}")
    if parity not in (1, -1):
        raise StarnavError(f"parity must be +1 or -1, got {shown(parity)}")
    rng = np.random.default_rng(seed)
    if R_cam_from_icrs is None:
        ra_deg, dec_deg, roll_deg = draw_radec_roll(rng, ra_deg, dec_deg, roll_deg)
        if not -90.0 <= dec_deg <= 90.0:
            raise StarnavError(f"dec_deg must be within ±90, got {shown(dec_deg)}")
        for name, value in (("ra_deg", ra_deg), ("roll_deg", roll_deg)):
            if not -360.0 <= value <= 720.0:
                raise StarnavError(
                    f"{name} must be an angle in degrees (0..360), got {shown(value)}"
                )
        R_cam_from_icrs = attitude_from_radec_roll(ra_deg, dec_deg, roll_deg, parity)
    R = np.asarray(R_cam_from_icrs, dtype=float)
    if mag_limit is not None:
        catalog = catalog.brighter_than(mag_limit)
    rows, xy = project_catalog(catalog, R, camera)
    mag = (
        catalog.mag[rows] + rng.normal(0.0, mag_noise, len(rows))
        if mag_noise
        else (catalog.mag[rows].copy())
    )
    ids = catalog.ids[rows]
    n_in_view = len(rows)
    n_drop = round(missing_frac * n_in_view)
    if n_drop:
        keep = np.sort(rng.choice(n_in_view, n_in_view - n_drop, replace=False))
        xy, mag, ids = xy[keep], mag[keep], ids[keep]
    if noise_px:
        xy = xy + rng.normal(0.0, noise_px, xy.shape)
    if false_stars:
        faint = float(catalog.mag.max()) if mag_limit is None else float(mag_limit)
        bright = float(np.min(mag)) if len(mag) else faint - 2.0
        corner = [camera.width, camera.height]
        fxy = rng.uniform([0.0, 0.0], corner, (false_stars, 2))
        # where the lens images the sky only (inside a fisheye's image circle)
        outside = ~camera.sees(camera.pixels_to_bearings(fxy))
        while outside.any():
            fxy[outside] = rng.uniform([0.0, 0.0], corner, (int(outside.sum()), 2))
            outside = ~camera.sees(camera.pixels_to_bearings(fxy))
        fmag = rng.uniform(bright, faint, false_stars)
        xy = np.vstack([xy, fxy])
        mag = np.concatenate([mag, fmag])
        ids = np.concatenate([ids, np.full(false_stars, FALSE_STAR_ID)])
    inside = camera.contains(xy)
    xy, mag, ids = xy[inside], mag[inside], ids[inside]
    order = np.argsort(mag, kind="stable")
    return SimulatedFrame(xy[order], mag[order], ids[order], R, camera, n_in_view)
