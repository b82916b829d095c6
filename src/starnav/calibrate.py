"""Camera calibration from star images: focal length, principal point and radial distortion.

Each image is solved on its own first (FOV searched, k1/k2 fitted when enough stars match).
Then one least-squares fit takes every frame's matched stars together: an attitude per frame
and the shared camera (log focal length, cx, cy, k1, k2). After the fit, each frame's
detections are matched again against the catalog with the new camera (stars near the corners
join once the distortion is known) and the fit is repeated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from starnav.attitude.refine import rotate_by
from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.fov import DEFAULT_FOV_RANGE_DEG
from starnav.image import ImageSolveResult, solve_image
from starnav.simulate import project_catalog

_ROUNDS = 3
_MATCH_RADIUS_PX = 2.0
_CATALOG_MAG = 8.0


@dataclass(frozen=True, eq=False)
class Calibration:
    """The fitted ``camera``; ``sigma`` of its parameters (focal_px, cx, cy, k1, k2, same
    units); residual ``rms_px`` over ``n_stars`` stars in the ``frames`` solved; ``failed``:
    (image name, reason) of the images left out."""

    camera: Camera
    sigma: dict[str, float]
    rms_px: float
    n_stars: int
    frames: tuple[str, ...]
    failed: tuple[tuple[str, str], ...]


def _joint_residuals(params, frames, width, height, n_frames):
    log_f, cx, cy, k1, k2 = params[3 * n_frames :]
    cam = Camera(width, height, float(np.exp(log_f)), cx, cy, k1, k2)
    out = []
    for i, (R0, icrs, xy) in enumerate(frames):
        R = rotate_by(params[3 * i : 3 * i + 3], R0)
        out.append((cam.bearings_to_pixels(icrs @ R.T) - xy).ravel())
    return np.concatenate(out)


def _match(detected_xy, R, camera, cat) -> tuple[np.ndarray, np.ndarray]:
    """Detections paired one-to-one with the catalog stars projected within the match radius."""
    rows, xy = project_catalog(cat, R, camera)
    if len(rows) == 0:
        return np.empty(0, int), np.empty(0, int)
    dist, nearest = cKDTree(xy).query(detected_xy, distance_upper_bound=_MATCH_RADIUS_PX)
    ok = np.flatnonzero(np.isfinite(dist))
    ok = ok[np.argsort(dist[ok], kind="stable")]  # nearest pairs first
    _, first = np.unique(nearest[ok], return_index=True)  # a catalog star pairs once
    det = np.sort(ok[first])
    return det, rows[nearest[det]]


def calibrate(
    images: Sequence[str | Path | np.ndarray],
    *,
    fov_deg: float | None = None,
    fov_range_deg: tuple[float, float] = DEFAULT_FOV_RANGE_DEG,
    catalog: Catalog | str | Path | None = None,
    progress=None,
    **options,
) -> Calibration:
    """Fit one camera to several images of the same camera (at least one must solve).

    ``progress``: optional callable run after each image (e.g. a tqdm ``update``). Other
    keywords go to ``solve_image``.
    """
    names = [
        str(im) if not isinstance(im, np.ndarray) else f"array {k}" for k, im in enumerate(images)
    ]
    if not names:
        raise StarnavError("calibration needs at least one image")
    cat = load_catalog(catalog, mag_limit=_CATALOG_MAG, epoch_year=options.get("epoch_year"))
    solved, failed = _solve_each(
        names, images, progress, fov_deg=fov_deg, fov_range_deg=fov_range_deg,
        catalog=catalog, **options,
    )  # fmt: skip
    camera, fit = _joint_fit(solved, cat)
    n = len(solved)
    res = fit.fun
    dof = max(len(res) - len(fit.x), 1)
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(fit.jac.T @ fit.jac)
        sd = np.sqrt(np.maximum(np.diag(cov)[3 * n :], 0.0))
    except np.linalg.LinAlgError:
        sd = np.full(5, np.inf)
    sigma = {
        "focal_px": float(camera.focal_px * sd[0]),
        "cx": float(sd[1]),
        "cy": float(sd[2]),
        "k1": float(sd[3]),
        "k2": float(sd[4]),
    }
    r = res.reshape(-1, 2)
    return Calibration(
        camera=camera,
        sigma=sigma,
        rms_px=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
        n_stars=len(r),
        frames=tuple(name for name, _ in solved),
        failed=tuple(failed),
    )


def _solve_each(names, images, progress, **options):
    """Each image solved with the FOV searched and the distortion fitted: the solved ones
    of the first solved image's size (name, result) and the others (name, reason)."""
    solved: list[tuple[str, ImageSolveResult]] = []
    failed = []
    shape = None
    for name, image in zip(names, images, strict=True):
        res = solve_image(image, fit_distortion=True, **options)
        if progress is not None:
            progress()
        size = (res.detections.width, res.detections.height)
        if res.solution is None:
            failed.append((name, res.reason))
        elif shape is not None and size != shape:
            failed.append((name, f"{size[0]} x {size[1]} px, not {shape[0]} x {shape[1]} px"))
        else:
            shape = size  # the first image solved sets the size
            solved.append((name, res))
    if not solved:
        raise StarnavError("no image could be solved: " + "; ".join(f"{n}: {r}" for n, r in failed))
    return solved, failed


def _joint_fit(solved, cat):
    """One camera and an attitude per image, fitted to all their matched stars (matched
    again after each round); from the median of the images' own fits. Returns the camera
    and scipy's last fit."""
    width, height = solved[0][1].detections.width, solved[0][1].detections.height
    cams = [r.camera for _, r in solved]
    camera = Camera(
        width,
        height,
        float(np.median([c.focal_px for c in cams])),
        width / 2.0,
        height / 2.0,
        float(np.median([c.k1 for c in cams])),
        float(np.median([c.k2 for c in cams])),
    )
    attitudes = [r.solution.R_cam_from_icrs for _, r in solved]
    n = len(solved)
    fit = None
    for _ in range(_ROUNDS):
        frames = []
        for (_, res), R in zip(solved, attitudes, strict=True):
            det, rows = _match(res.detections.xy, R, camera, cat)
            frames.append((R, cat.vectors[rows], res.detections.xy[det]))
        n_stars = sum(len(f[2]) for f in frames)
        if n_stars < 8 + 3 * n:
            raise StarnavError(f"only {n_stars} matched stars: too few to calibrate")
        x0 = np.concatenate(
            [np.zeros(3 * n), [np.log(camera.focal_px), camera.cx, camera.cy, camera.k1, camera.k2]]
        )
        fit = least_squares(
            _joint_residuals, x0, args=(frames, width, height, n), method="lm", x_scale="jac"
        )
        log_f, cx, cy, k1, k2 = fit.x[3 * n :]
        camera = Camera(
            width, height, float(np.exp(log_f)), float(cx), float(cy), float(k1), float(k2)
        )
        attitudes = [rotate_by(fit.x[3 * i : 3 * i + 3], R) for i, R in enumerate(attitudes)]
    return camera, fit
