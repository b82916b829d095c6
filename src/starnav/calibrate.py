"""Camera calibration from star images: focal length, principal point and the lens model's
coefficients (the sky is the calibration target).

Each image is solved on its own first (the focal length searched; a pinhole's k1/k2 fitted
when enough stars match; a fisheye model starts from its coefficients at zero, so
Kannala-Brandt from the equidistant lens). Then one least-squares fit takes every frame's
matched stars together: an attitude per frame and the shared camera (log focal length, cx,
cy and the model's coefficients, ``cls.coefficients``), the projection being the camera's
own (``camera.kernels``). The first fit takes the stars each image's solve identified;
after each fit the detections are matched again against the catalog with the new camera
(stars near the corners join once the distortion is known) and the fit is repeated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from starnav.attitude.refine import rotate_by
from starnav.camera import CameraModel, model_class
from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.pipeline.image import ImageSolveResult, solve_image
from starnav.simulate import project_catalog

_ROUNDS = 3  # fits on re-matched stars after the first (on the solves' own matches)
_MATCH_RADIUS_PX = 2.0
_CATALOG_MAG = 8.0  # the deepest catalog the detections are matched against
_MAG_STEP = 0.1
# the catalog is cut where a random point of the sky has this chance of a catalog star
# within the match radius (a fisheye pixel spans ~100 times a narrow field's sky)
_CHANCE_MATCH = 0.02
_SPARE_STARS = 3  # stars beyond the number of fitted parameters


@dataclass(frozen=True, eq=False)
class Calibration:
    """The fitted ``camera``; ``sigma``: 1-sigma of its parameters (focal_px, cx, cy, then
    the model's coefficients, same units); residual ``rms_px`` over ``n_stars`` stars in
    the ``frames`` solved; ``failed``: (image name, reason) of the images left out."""

    camera: CameraModel
    sigma: dict[str, float]
    rms_px: float
    n_stars: int
    frames: tuple[str, ...]
    failed: tuple[tuple[str, str], ...]


def _camera(cls: type, width: int, height: int, intrinsics: np.ndarray) -> CameraModel:
    """The camera of the fit's intrinsics (log focal_px, cx, cy, coefficients...)."""
    return cls.from_params(width, height, [math.exp(intrinsics[0]), *intrinsics[1:]])


def _joint_residuals(params, frames, cls, width, height, n_frames):
    cam = _camera(cls, width, height, params[3 * n_frames :])
    out = []
    for i, (R0, icrs, xy) in enumerate(frames):
        R = rotate_by(params[3 * i : 3 * i + 3], R0)
        out.append((cam.bearings_to_pixels(icrs @ R.T) - xy).ravel())
    return np.concatenate(out)


def match_catalog(cat: Catalog, camera: CameraModel) -> Catalog:
    """The catalog cut to the depth at which a random point has ``_CHANCE_MATCH`` chance of
    a star within the match radius at the lens's coarsest scale (at most ``_CATALOG_MAG``)."""
    radius_rad = _MATCH_RADIUS_PX / camera.scale_px_per_rad
    allowed = _CHANCE_MATCH * 4.0 / radius_rad**2  # stars on the whole sky: n π r² / 4π
    mags = np.sort(cat.mag)
    if len(mags) <= allowed:
        return cat
    limit = math.floor(mags[int(allowed)] / _MAG_STEP) * _MAG_STEP
    return cat.brighter_than(min(limit, _CATALOG_MAG))


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
    model: str = "pinhole",
    fov_deg: float | None = None,
    fov_range_deg: tuple[float, float] | None = None,
    catalog: Catalog | str | Path | None = None,
    progress=None,
    **options,
) -> Calibration:
    """Fit one camera of lens ``model`` (``starnav.camera.MODELS``) to several images of the
    same camera (at least one must solve). ``fov_deg`` / ``fov_range_deg``: the horizontal
    field searched by each image's solve (degrees; a fisheye's e.g. 150-200).

    ``progress``: optional callable run after each image (e.g. a tqdm ``update``). Other
    keywords go to ``solve_image``.
    """
    cls = model_class(model)
    names = [
        str(im) if not isinstance(im, np.ndarray) else f"array {k}" for k, im in enumerate(images)
    ]
    if not names:
        raise StarnavError("calibration needs at least one image")
    cat = load_catalog(catalog, mag_limit=_CATALOG_MAG, epoch_year=options.get("epoch_year"))
    solved, failed = _solve_each(
        names, images, progress, lens=model, fov_deg=fov_deg, fov_range_deg=fov_range_deg,
        catalog=catalog, **options,
    )  # fmt: skip
    camera, fit = _joint_fit(solved, cat, cls)
    camera.check_monotonic("the calibrated camera")
    res = fit.fun
    r = res.reshape(-1, 2)
    return Calibration(
        camera=camera,
        sigma=_sigmas(fit, camera, len(solved)),
        rms_px=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
        n_stars=len(r),
        frames=tuple(name for name, _ in solved),
        failed=tuple(failed),
    )


def _sigmas(fit, camera: CameraModel, n_frames: int) -> dict[str, float]:
    """1-sigma of the camera's parameters from the fit's Jacobian, scaled by its residuals."""
    res = fit.fun
    dof = max(len(res) - len(fit.x), 1)
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(fit.jac.T @ fit.jac)
        sd = np.sqrt(np.maximum(np.diag(cov)[3 * n_frames :], 0.0))
    except np.linalg.LinAlgError:
        sd = np.full(len(fit.x) - 3 * n_frames, np.inf)
    names = ("cx", "cy", *type(camera).coefficients)
    return {"focal_px": float(camera.focal_px * sd[0])} | {
        name: float(s) for name, s in zip(names, sd[1:], strict=True)
    }


def _solve_each(names, images, progress, *, lens, **options):
    """Each image solved with the focal length searched (the pinhole's distortion fitted;
    a fisheye's coefficients left at zero: one image's k1..k4 are a poor start): the solved
    ones of the first solved image's size (name, result) and the others (name, reason)."""
    pinhole = model_class(lens).kind == "pinhole"
    solved: list[tuple[str, ImageSolveResult]] = []
    failed = []
    shape = None
    for name, image in zip(names, images, strict=True):
        res = solve_image(image, lens=lens, fit_distortion=pinhole, **options)
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


def _solved_matches(res: ImageSolveResult, cat: Catalog):
    """The attitude, catalog vectors and pixels of the stars an image's solve identified."""
    s = res.solution
    matched = [m for m in s.stars if m.catalog_id is not None]
    xy = np.array([(m.x, m.y) for m in matched]).reshape(-1, 2)
    return s.R_cam_from_icrs, cat.vectors[cat.rows([m.catalog_id for m in matched])], xy


def _joint_fit(solved, cat: Catalog, cls: type):
    """One camera of model ``cls`` and an attitude per image, fitted to all their matched
    stars (the solves' own matches first, then matched again after each round); from the
    median of the images' own cameras about the image centre. Returns the camera and
    scipy's last fit."""
    width, height = solved[0][1].detections.width, solved[0][1].detections.height
    cams = [r.camera for _, r in solved]
    coefficients = [float(np.median([getattr(c, k) for c in cams])) for k in cls.coefficients]
    focal = float(np.median([c.focal_px for c in cams]))
    camera = cls.from_params(width, height, [focal, width / 2.0, height / 2.0, *coefficients])
    frames = [_solved_matches(r, cat) for _, r in solved]
    n = len(solved)
    n_intrinsic = 3 + len(cls.coefficients)
    fit = None
    for round_ in range(_ROUNDS + 1):
        if round_ > 0:  # matched again with the last fit's camera and attitudes
            near = match_catalog(cat, camera)
            attitudes = [rotate_by(fit.x[3 * i : 3 * i + 3], f[0]) for i, f in enumerate(frames)]
            frames = []
            for (_, res), R in zip(solved, attitudes, strict=True):
                det, rows = _match(res.detections.xy, R, camera, near)
                frames.append((R, near.vectors[rows], res.detections.xy[det]))
        n_stars = sum(len(f[2]) for f in frames)
        if n_stars < 3 * n + n_intrinsic + _SPARE_STARS:
            raise StarnavError(f"only {n_stars} matched stars: too few to calibrate")
        x0 = np.concatenate(
            [np.zeros(3 * n), [math.log(camera.focal_px)], camera.params[1:n_intrinsic]]
        )
        fit = least_squares(
            _joint_residuals, x0, args=(frames, cls, width, height, n), method="lm", x_scale="jac"
        )
        camera = _camera(cls, width, height, fit.x[3 * n :])
    return camera, fit
