"""The kinds of frame an evaluation can make: the simulated sky (``true``) and adversarial
frames that test whether the solver refuses what it cannot know.

Every frame is made from its boresight and its own random generator (``frame_rng(seed,
index)``), so a frame is the same in any worker. Each kind returns a ``SimulatedFrame`` whose
``R_cam_from_icrs`` is the attitude a right answer must equal (its determinant is the parity
a right answer must report) and whose ``camera`` is the one that made the points (the solver
is always given the configured camera):

- ``true``: the simulated frame (noise, false stars, missing stars of the configuration).
- ``random``: points uniform over the image (inside a fisheye's image circle), as many as
  the true frame at that boresight has (at least 3), magnitudes uniform between its
  brightest star and the magnitude limit. No right answer exists: any solution is wrong.
- ``scrambled``: the true frame with each point's x and y drawn independently, without
  replacement, from the points' x and y (its brightness kept), so the geometry is gone. A
  point whose x and y both come from one star is that star; the truth is unchanged, so a
  solution is correct only if it is genuinely the true attitude.
- ``mirrored``: the true frame with x mirrored about the principal point (x -> 2 cx - x,
  = width - x for a centred one). The sky then fits only a mirrored attitude: the truth is
  ``diag(-1, 1, 1) R``, and a solution is correct only if it reports parity -1 and that
  attitude (mapped back through the mirror it is the true one).
- ``fov-off``: the true frame seen through a focal length 2-10 % off (sign and size drawn
  per frame) from the configured one, which the solver keeps (no focal fit): its answer
  must be right within the usual tolerance, or a refusal.
- ``crowded``: the true frame with as many false stars as true stars among its points
  (instead of the configured number).
- ``few``: the true frame with only 3 to 6 (drawn per frame) of its true stars kept, at
  random, and the configured false stars.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable

import numpy as np

from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.errors import StarnavError
from starnav.simulate import FALSE_STAR_ID, SimulatedFrame, simulate_frame

KINDS = ("true", "random", "scrambled", "mirrored", "fov-off", "crowded", "few")
NO_ANSWER_KINDS = frozenset({"random"})  # any solution of these is wrong
MIRROR = np.diag([-1.0, 1.0, 1.0])  # x -> -x in the camera frame
FOV_OFF_RANGE = (0.02, 0.10)  # fractional focal-length error of fov-off frames
FEW_STARS = (3, 6)  # true stars kept in a few-star frame (inclusive)


def parse_kinds(values: Iterable[str] | str) -> tuple[str, ...]:
    """Kind names from strings like ``"random,true"`` (each may hold a comma list), in the
    order given, duplicates dropped; ``StarnavError`` naming an unknown one."""
    if isinstance(values, str):
        values = [values]
    kinds: list[str] = []
    for value in values:
        for name in str(value).split(","):
            name = name.strip().lower()
            if not name:
                continue
            if name not in KINDS:
                raise StarnavError(f"unknown frame kind {name!r}: choose from {', '.join(KINDS)}")
            if name not in kinds:
                kinds.append(name)
    if not kinds:
        raise StarnavError(f"no frame kind given: choose from {', '.join(KINDS)}")
    return tuple(kinds)


def make_frame(
    kind: str,
    catalog: Catalog,
    camera: CameraModel,
    rng: np.random.Generator,
    *,
    ra_deg: float,
    dec_deg: float,
    roll_deg: float,
    noise_px: float,
    false_stars: int,
    missing_frac: float,
    mag_noise: float,
    mag_limit: float,
) -> tuple[SimulatedFrame, float]:
    """Frame of ``kind`` at the boresight, drawn from ``rng``, and the factor by which the
    focal length that made it differs from ``camera``'s (1 but for ``fov-off``)."""

    def simulate(lens: CameraModel, n_false: int, generator: np.random.Generator):
        return simulate_frame(
            catalog,
            lens,
            ra_deg=ra_deg,
            dec_deg=dec_deg,
            roll_deg=roll_deg,
            noise_px=noise_px,
            false_stars=n_false,
            missing_frac=missing_frac,
            mag_noise=mag_noise,
            seed=generator,
        )

    if kind == "fov-off":
        lo, hi = FOV_OFF_RANGE
        factor = 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi)
        return simulate(camera.with_focal(camera.focal_px * factor), false_stars, rng), factor
    if kind == "crowded":
        # the true stars are drawn before the false ones: a copy of the generator counts them
        n_true = len(simulate(camera, 0, copy.deepcopy(rng)).xy)
        return simulate(camera, n_true, rng), 1.0
    frame = simulate(camera, false_stars, rng)
    if kind == "true":
        return frame, 1.0
    if kind == "random":
        return _random_points(frame, camera, rng, mag_limit), 1.0
    if kind == "scrambled":
        return _scrambled(frame, camera, rng), 1.0
    if kind == "mirrored":
        return _mirrored(frame, camera), 1.0
    if kind == "few":
        return _few(frame, rng), 1.0
    raise StarnavError(f"unknown frame kind {kind!r}: choose from {', '.join(KINDS)}")


def _frame(frame: SimulatedFrame, xy, mag, true_id, R=None, camera=None) -> SimulatedFrame:
    order = np.argsort(mag, kind="stable")
    return SimulatedFrame(
        np.asarray(xy, dtype=float)[order],
        np.asarray(mag, dtype=float)[order],
        np.asarray(true_id)[order],
        frame.R_cam_from_icrs if R is None else R,
        frame.camera if camera is None else camera,
        frame.n_in_view,
    )


def _random_points(frame, camera, rng, mag_limit: float) -> SimulatedFrame:
    n = max(len(frame.xy), 3)
    corner = [camera.width, camera.height]
    xy = rng.uniform([0.0, 0.0], corner, (n, 2))
    outside = ~camera.sees(camera.pixels_to_bearings(xy))  # a fisheye's image circle
    while outside.any():
        xy[outside] = rng.uniform([0.0, 0.0], corner, (int(outside.sum()), 2))
        outside = ~camera.sees(camera.pixels_to_bearings(xy))
    bright = float(np.min(frame.mag)) if len(frame.mag) else mag_limit - 2.0
    mag = rng.uniform(min(bright, mag_limit - 0.5), mag_limit, n)
    return _frame(frame, xy, mag, np.full(n, FALSE_STAR_ID))


def _scrambled(frame, camera, rng) -> SimulatedFrame:
    n = len(frame.xy)
    px, py = rng.permutation(n), rng.permutation(n)
    xy = np.column_stack([frame.xy[px, 0], frame.xy[py, 1]])
    true_id = np.where(px == py, frame.true_id[px], FALSE_STAR_ID)
    inside = camera.contains(xy) & camera.sees(camera.pixels_to_bearings(xy))
    return _frame(frame, xy[inside], frame.mag[inside], true_id[inside])


def _mirrored(frame, camera) -> SimulatedFrame:
    cx = getattr(camera, "cx", None)
    cx = camera.width / 2.0 if cx is None else float(cx)
    xy = frame.xy.copy()
    xy[:, 0] = 2.0 * cx - xy[:, 0]
    inside = camera.contains(xy)
    return _frame(
        frame, xy[inside], frame.mag[inside], frame.true_id[inside], MIRROR @ frame.R_cam_from_icrs
    )


def _few(frame, rng) -> SimulatedFrame:
    real = np.flatnonzero(frame.true_id != FALSE_STAR_ID)
    k = int(rng.integers(FEW_STARS[0], FEW_STARS[1] + 1))
    keep = np.sort(
        np.concatenate(
            [
                rng.choice(real, min(k, len(real)), replace=False),
                np.flatnonzero(frame.true_id == FALSE_STAR_ID),
            ]
        )
    )
    return _frame(frame, frame.xy[keep], frame.mag[keep], frame.true_id[keep])
