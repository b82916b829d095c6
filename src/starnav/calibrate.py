"""Camera calibration from star images: lens model, focal length, principal point and the
model's coefficients (the sky is the calibration target); for a fixed camera with its site and
the frames' UTCs, also its orientation relative to the horizon (``navigation.mount``).

Each image is solved on its own first: through a starting camera when one is given, else with
the lens model (the focal length scanned; a pinhole's k1/k2 fitted when enough stars match).
Kannala-Brandt and ``auto`` solve with the fixed fisheye models in turn (equisolid,
equidistant, stereographic, orthographic) until one solves the first image, and start from it:
Kannala-Brandt's k1..k4 are fitted to that lens's r(θ) over the stars' angles, so a lens
between two fixed models starts close. Then one least-squares fit per candidate model takes
every frame's matched stars together: an attitude per frame (a mirrored frame keeps its
parity) and the shared camera (log focal length, cx, cy and the model's coefficients), the
projection being the camera's own (``camera.kernels``); the principal point starts at the
image circle's centre when the frames show one (a tilted or decentred lens). The first fit
takes the stars each image's solve identified; after each fit the detections are matched
again with the new camera and the fit is repeated. ``auto`` keeps the candidate of lowest
Bayesian information criterion, all candidates refitted on the same matched stars.

A circular fisheye's camera records its image circle (``image_circle_deg``): its r(θ) need
only increase up to there (and beyond the farthest star), not into the dark corners.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from starnav.attitude.refine import rotate_by
from starnav.camera import CameraModel, model_class
from starnav.camera.lens import kernels
from starnav.catalog import Catalog, load_catalog
from starnav.detect.circle import find_image_circle
from starnav.detect.read import read_image
from starnav.errors import StarnavError
from starnav.navigation.mount import Mount, fit_mount
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
# the fixed fisheye models, in the order Kannala-Brandt and auto try them on the first image
FIXED_FISHEYES = ("equisolid", "equidistant", "stereographic", "orthographic")
AUTO = "auto"
_R_SAMPLES = 200  # angles at which one model's r(θ) is fitted to another's
_TURN_SAMPLES = 2048  # angles at which a fitted r(θ) is checked to increase
_CIRCLE_INSIDE_PX = 1.0  # stars this far inside the image circle's edge at most


@dataclass(frozen=True)
class ModelFit:
    """One candidate model's fit: ``model``, residual ``rms_px`` over ``n_stars`` stars of the
    common set, its number of parameters ``n_params`` and Bayesian information criterion
    ``bic`` (lower is better)."""

    model: str
    rms_px: float
    n_stars: int
    n_params: int
    bic: float


@dataclass(frozen=True, eq=False)
class Calibration:
    """The fitted ``camera``; ``sigma``: 1-sigma of its parameters (focal_px, cx, cy, then
    the model's coefficients, same units); residual ``rms_px`` over ``n_stars`` stars in
    the ``frames`` solved, ``frame_rms_px`` and ``frame_stars`` per frame; ``failed``: (image
    name, reason) of the images left out; ``models``: each candidate's fit (``auto``; one
    entry otherwise); ``parity``: -1 for a mirrored camera; ``attitudes``: R_cam_from_icrs
    per frame; ``mount``: the fixed orientation (with site and UTCs; else None);
    ``residuals``: (frame index, x, y, dx, dy) px per matched star, ``star_icrs`` its
    catalog direction (ICRS unit vector); ``circle``: the image circle found (px);
    ``start_lens``: what solved the images first; ``refused``: the candidate models that
    could not be fitted, with why."""

    camera: CameraModel
    sigma: dict[str, float]
    rms_px: float
    n_stars: int
    frames: tuple[str, ...]
    failed: tuple[tuple[str, str], ...]
    frame_rms_px: tuple[float, ...] = ()
    frame_stars: tuple[int, ...] = ()
    models: tuple[ModelFit, ...] = ()
    parity: int = 1
    attitudes: tuple[np.ndarray, ...] = ()
    mount: Mount | None = None
    residuals: np.ndarray | None = None
    star_icrs: np.ndarray | None = None
    circle: _Circle | None = None
    start_lens: str = ""
    refused: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The JSON of ``starnav calibrate``."""
        return {
            **self.camera.to_dict(),
            "sigma": self.sigma,
            "rms_px": self.rms_px,
            "n_stars": self.n_stars,
            "parity": self.parity,
            "frames": [
                {"image": name, "rms_px": rms, "n_stars": n}
                for name, rms, n in zip(
                    self.frames, self.frame_rms_px, self.frame_stars, strict=True
                )
            ],
            "failed": [{"image": n, "reason": r} for n, r in self.failed],
            "models": [dataclasses.asdict(m) for m in self.models],
            "models_refused": list(self.refused),
            "start_lens": self.start_lens,
            "image_circle_px": None
            if self.circle is None
            else {"cx": self.circle.cx, "cy": self.circle.cy, "radius_px": self.circle.radius_px},
            "mount": None if self.mount is None else self.mount.to_dict(),
        }


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
    lens: str | None = None,
    camera: CameraModel | str | Path | None = None,
    fov_deg: float | None = None,
    fov_range_deg: tuple[float, float] | None = None,
    catalog: Catalog | str | Path | None = None,
    times: Sequence | None = None,
    site: tuple[float, float, float] | None = None,
    progress=None,
    **options,
) -> Calibration:
    """Fit one camera of lens ``model`` (``starnav.camera.MODELS``, or ``"auto"``: the fixed
    fisheye models and Kannala-Brandt, the best kept) to several images of the same camera
    (at least one must solve). ``lens``: the model each image is solved with first (default:
    ``model``; for Kannala-Brandt and auto the fixed fisheyes in turn); ``camera``: a starting
    camera (model or camera file) the images are solved through instead. ``fov_deg`` /
    ``fov_range_deg``: the horizontal field searched by each image's solve (degrees; a
    fisheye's e.g. 150-200). ``times``: each image's UTC (astropy ``Time`` or ISO 8601 text;
    None entries: unknown) and ``site``: (latitude, longitude degrees, height m): with both,
    the camera's fixed orientation (``Calibration.mount``) is fitted too.

    ``progress``: optional callable run after each image solve (e.g. a tqdm ``update``). Other
    keywords go to ``solve_image``.
    """
    candidates = _candidates(model)
    names = [
        str(im) if not isinstance(im, np.ndarray) else f"array {k}" for k, im in enumerate(images)
    ]
    if not names:
        raise StarnavError("calibration needs at least one image")
    if times is not None and len(times) != len(names):
        raise StarnavError(f"{len(times)} times for {len(names)} images")
    cat = load_catalog(catalog, mag_limit=_CATALOG_MAG, epoch_year=options.get("epoch_year"))
    circle = None
    if camera is None and (model == AUTO or model_class(lens or model).kind == "fisheye"):
        circle = _circle(images[0])
    starts = _starts(model, lens, camera, circle)
    solved, failed, start_lens = _solve_each(
        names, images, progress, starts, fov_deg=fov_deg, fov_range_deg=fov_range_deg,
        catalog=catalog, **options,
    )  # fmt: skip
    if camera is not None and getattr(solved[0][1].camera, "kind", "") == "fisheye":
        circle = _circle(images[names.index(solved[0][0])])
    fits, refused = {}, []
    for name in candidates:
        try:
            fits[name] = _joint_fit(solved, cat, model_class(name), circle, camera is not None)
        except StarnavError as exc:  # auto: a candidate that cannot fit is left out
            if len(candidates) == 1:
                raise
            refused.append(f"{name}: {exc}")
    if not fits:
        raise StarnavError("no lens model could be fitted: " + "; ".join(refused))
    models = _compare(fits, solved) if len(fits) > 1 else ()
    best = min(models, key=lambda m: m.bic).model if models else next(iter(fits))
    cam, fit, frames = fits[best]
    if not models:
        models = (_model_fit(best, fit),)
    cam = _bounded(cam, fit, frames, circle)
    res = fit.fun.reshape(-1, 2)
    n = len(solved)
    per_frame = np.cumsum([0] + [len(f[2]) for f in frames])
    frame_rms = tuple(
        float(np.sqrt(np.mean(np.sum(res[a:b] ** 2, axis=1)))) if b > a else math.nan
        for a, b in itertools.pairwise(per_frame)
    )
    attitudes = tuple(rotate_by(fit.x[3 * i : 3 * i + 3], f[0]) for i, f in enumerate(frames))
    xy = np.vstack([f[2] for f in frames])
    which = np.repeat(np.arange(n), [len(f[2]) for f in frames])
    mount = _mount(attitudes, solved, names, times, site)
    return Calibration(
        camera=cam,
        sigma=_sigmas(fit, cam, n),
        rms_px=float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
        n_stars=len(res),
        frames=tuple(name for name, _ in solved),
        failed=tuple(failed),
        frame_rms_px=frame_rms,
        frame_stars=tuple(len(f[2]) for f in frames),
        models=models,
        parity=1 if np.linalg.det(attitudes[0]) > 0 else -1,
        attitudes=attitudes,
        mount=mount,
        residuals=np.column_stack([which, xy, res]),
        star_icrs=np.vstack([f[1] for f in frames]),
        circle=circle,
        start_lens=start_lens,
        refused=tuple(refused),
    )


def _candidates(model: str) -> tuple[str, ...]:
    if model == AUTO:
        return (*FIXED_FISHEYES, "kannala-brandt")
    model_class(model)  # a one-line error for an unknown name
    return (model,)


def _starts(model: str, lens: str | None, camera, circle: _Circle | None) -> list:
    """The ways the images are solved, tried in turn on the first image: (what, lens model,
    camera). A given camera alone; else the lens models (``lens``; the fixed fisheyes for
    Kannala-Brandt and auto; ``model``), each first through a camera centred on the image
    circle whose edge is 90° from the axis (a decentred lens), then with its focal scan."""
    if camera is not None:
        return [("camera", None, camera)]
    if lens is not None:
        lenses = (model_class(lens).model,)
    elif model in (AUTO, "kannala-brandt"):
        lenses = FIXED_FISHEYES
    else:
        lenses = (model,)
    starts = []
    if circle is not None:
        for name in lenses:
            cls = model_class(name)
            if cls.kind == "fisheye":
                unit = cls.from_params(1, 1, [1.0, 0.0, 0.0])
                g = kernels().radial_g(cls.model_code, unit.params, 0.5 * math.pi)[0]
                cam = cls.from_params(circle.width, circle.height, [1.0, circle.cx, circle.cy])
                cam = cam.with_focal(circle.radius_px / g)
                starts.append((f"{name} on the image circle", None, cam))
    return starts + [(name, name, None) for name in lenses]


def _solve_each(names, images, progress, starts, **options):
    """Each image solved (the ``starts`` in turn on the first image until one solves, then
    that one): the solved ones of the first solved image's size (name, result), the others
    (name, reason), and what solved."""
    solved: list[tuple[str, ImageSolveResult]] = []
    failed = []
    shape = None
    chosen = None
    for name, image in zip(names, images, strict=True):
        tried = []
        for start in starts if chosen is None else (chosen,):
            res = _solve_one(image, start, options)
            tried.append((start[0], res.reason))
            if res.solution is not None:
                chosen = start
                break
        if progress is not None:
            progress()
        size = (res.detections.width, res.detections.height)
        if res.solution is None:
            failed.append((name, "; ".join(f"{what}: {why}" for what, why in tried)))
        elif shape is not None and size != shape:
            failed.append((name, f"{size[0]} x {size[1]} px, not {shape[0]} x {shape[1]} px"))
        else:
            shape = size  # the first image solved sets the size
            solved.append((name, res))
    if not solved:
        raise StarnavError("no image could be solved: " + "; ".join(f"{n}: {r}" for n, r in failed))
    return solved, failed, chosen[0]


def _solve_one(image, start, options: dict) -> ImageSolveResult:
    _, lens, camera = start
    if camera is not None:
        opts = {k: v for k, v in options.items() if k not in ("fov_deg", "fov_range_deg")}
        return solve_image(image, camera=camera, **opts)
    pinhole = model_class(lens).kind == "pinhole"
    return solve_image(image, lens=lens, fit_distortion=pinhole, **options)


@dataclass(frozen=True)
class _Circle:
    """An image circle (px) with the size of its image."""

    cx: float
    cy: float
    radius_px: float
    width: int
    height: int


def _circle(image) -> _Circle | None:
    """The image circle of an image (None: a full-frame image)."""
    pixels = image if isinstance(image, np.ndarray) else read_image(image)
    found = find_image_circle(pixels)
    if found is None:
        return None
    height, width = pixels.shape
    return _Circle(found.cx, found.cy, found.radius_px, width, height)


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


def _solved_matches(res: ImageSolveResult, cat: Catalog):
    """The attitude, catalog vectors and pixels of the stars an image's solve identified."""
    s = res.solution
    matched = [m for m in s.stars if m.catalog_id is not None]
    known = np.isin([m.catalog_id for m in matched], cat.ids)
    matched = [m for m, k in zip(matched, known, strict=True) if k]
    xy = np.array([(m.x, m.y) for m in matched]).reshape(-1, 2)
    return s.R_cam_from_icrs, cat.vectors[cat.rows([m.catalog_id for m in matched])], xy


def _stars_theta_max(camera: CameraModel, frames) -> float:
    """The largest angle (rad) from the axis of a matched star."""
    top = 0.0
    for _, _, xy in frames:
        if len(xy):
            top = max(
                top, float(np.max(np.arccos(np.clip(camera.pixels_to_bearings(xy)[:, 2], -1, 1))))
            )
    return top


def _converted(source: CameraModel, cls: type, theta_max: float) -> CameraModel:
    """A camera of model ``cls`` whose r(θ) best matches ``source``'s over 0..``theta_max``
    (same principal point): a fixed model's focal length, Kannala-Brandt's k1..k4 too."""
    if isinstance(source, cls):
        return source
    theta = np.linspace(0.0, max(theta_max, 0.1), _R_SAMPLES + 1)[1:]
    r = np.array(
        [
            source.focal_px * kernels().radial_g(source.model_code, source.params, t)[0]
            for t in theta
        ]
    )
    unit = cls.from_params(source.width, source.height, [1.0, source.cx, source.cy])
    if cls.coefficients:  # r = f θ + f k1 θ³ + ... : linear in (f, f k1, ..., f k4)
        n = len(cls.coefficients)
        A = np.column_stack([theta ** (2 * j + 1) for j in range(n + 1)])
        a, *_ = np.linalg.lstsq(A, r, rcond=None)
        return cls.from_params(
            source.width, source.height, [a[0], source.cx, source.cy, *(a[1:] / a[0])]
        )
    g = np.array([kernels().radial_g(cls.model_code, unit.params, t)[0] for t in theta])
    return cls.from_params(
        source.width, source.height, [float(r @ g / (g @ g)), source.cx, source.cy]
    )


def _joint_fit(solved, cat: Catalog, cls: type, circle: _Circle | None, given: bool):
    """One camera of model ``cls`` and an attitude per image, fitted to all their matched
    stars (the solves' own matches first, then matched again after each round); from the
    median of the images' own cameras converted to ``cls``, about the image circle's centre
    when there is one (else the centre the solves had; a ``given`` starting camera's own).
    Returns the camera, scipy's last fit and the frames (R0, catalog vectors, pixels)."""
    width, height = solved[0][1].detections.width, solved[0][1].detections.height
    cams = [r.camera for _, r in solved]
    base = cams[0]
    params = np.median([c.params[: 3 + len(type(base).coefficients)] for c in cams], axis=0)
    source = type(base).from_params(width, height, params)
    frames = [_solved_matches(r, cat) for _, r in solved]
    if isinstance(source, cls) and cls.kind == "pinhole" and not given:
        source = dataclasses.replace(source, cx=width / 2.0, cy=height / 2.0)
    camera = _converted(source, cls, _stars_theta_max(source, frames))
    if circle is not None and not given:
        camera = dataclasses.replace(camera, cx=circle.cx, cy=circle.cy)
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
        fit = _fit(frames, cls, camera, width, height, n, n_intrinsic)
        camera = _camera(cls, width, height, fit.x[3 * n :])
    return camera, fit, frames


def _fit(frames, cls, camera, width, height, n, n_intrinsic):
    n_stars = sum(len(f[2]) for f in frames)
    if n_stars < 3 * n + n_intrinsic + _SPARE_STARS:
        raise StarnavError(
            f"only {n_stars} matched stars: too few to calibrate the {cls.model} model"
        )
    x0 = np.concatenate(
        [np.zeros(3 * n), [math.log(camera.focal_px)], camera.params[1:n_intrinsic]]
    )
    return least_squares(
        _joint_residuals, x0, args=(frames, cls, width, height, n), method="lm", x_scale="jac"
    )


def _model_fit(name: str, fit) -> ModelFit:
    res = fit.fun
    m = len(res)
    rss = float(res @ res)
    k = len(fit.x)
    bic = m * math.log(max(rss, 1e-300) / m) + k * math.log(m)
    return ModelFit(name, float(math.sqrt(2.0 * rss / m)), m // 2, k, bic)


def _compare(fits: dict, solved) -> tuple[ModelFit, ...]:
    """Every candidate refitted on the same stars (those of the candidate that matched the
    most) and scored."""
    name = max(fits, key=lambda k: len(fits[k][1].fun))
    _, _, common = fits[name]
    out = []
    width, height = solved[0][1].detections.width, solved[0][1].detections.height
    n = len(solved)
    for model, (camera, fit, frames) in fits.items():
        start = [
            (rotate_by(fit.x[3 * i : 3 * i + 3], f[0]), c[1], c[2])
            for i, (f, c) in enumerate(zip(frames, common, strict=True))
        ]
        cls = type(camera)
        try:
            again = _fit(start, cls, camera, width, height, n, 3 + len(cls.coefficients))
        except StarnavError:  # too few stars for this model's parameters: not a candidate
            continue
        out.append(_model_fit(model, again))
    return tuple(out)


def _bounded(camera: CameraModel, fit, frames, circle: _Circle | None) -> CameraModel:
    """The fitted camera with the image circle it records: a fisheye's circle where the frames
    show one, cut where its r(θ) stops increasing (beyond every star, else an error); a
    pinhole's r(θ) must increase over the whole image."""
    if camera.kind == "pinhole":
        camera.check_monotonic("the calibrated camera")
        return camera
    stars = _stars_theta_max(camera, frames)
    top = float(camera.model_theta_max_rad)
    for theta in np.linspace(0.0, top, _TURN_SAMPLES, endpoint=False)[1:]:
        if not kernels().radial_g(camera.model_code, camera.params, float(theta))[1] > 0.0:
            top = float(theta)
            break
    if top <= stars:
        raise StarnavError(
            f"the fitted {camera.model} lens's radius r(θ) stops increasing at "
            f"θ = {math.degrees(top):.1f}°, inside the stars (to {math.degrees(stars):.1f}°): "
            "try another --model"
        )
    limit = None
    if circle is not None:
        limit = kernels().radial_theta(
            camera.model_code, camera.params, circle.radius_px / camera.focal_px
        )
        limit = max(limit, stars)
    corner = max(
        math.hypot(x - camera.cx, y - camera.cy)
        for x in (0, camera.width)
        for y in (0, camera.height)
    )
    reaches = (
        camera.focal_px * kernels().radial_g(camera.model_code, camera.params, top)[0] >= corner
    )
    if top < camera.model_theta_max_rad and not reaches:
        limit = top if limit is None else min(limit, top)
    if limit is None:
        return camera
    bounded = camera.with_circle(math.degrees(2.0 * min(limit, 0.999 * top)))
    bounded.check_monotonic("the calibrated camera")
    return bounded


def _mount(attitudes, solved, names, times, site) -> Mount | None:
    """The fixed orientation, from the frames with a UTC, when the site is known."""
    if site is None or times is None:
        return None
    pairs = [
        (R, times[names.index(name)])
        for R, (name, _) in zip(attitudes, solved, strict=True)
        if times[names.index(name)] is not None
    ]
    if not pairs:
        return None
    return fit_mount([p[0] for p in pairs], [p[1] for p in pairs], *site)


def plot_residuals(cal: Calibration, path: str | Path) -> Path:
    """Write a PNG of the fit's residuals: their size against the distance from the principal
    point, and as arrows on the image plane (magnified)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = cal.camera
    _, x, y, dx, dy = cal.residuals.T
    r = np.hypot(x - cam.cx, y - cam.cy)
    size = np.hypot(dx, dy)
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 6))
    a.plot(r, size, ".", ms=3)
    a.set_xlabel("distance from the principal point (px)")
    a.set_ylabel("residual (px)")
    a.set_title(f"{cam.model}: rms {cal.rms_px:.3f} px over {cal.n_stars} stars")
    scale = 0.05 * max(cam.width, cam.height) / max(float(np.max(size)), 1e-9)
    b.quiver(x, y, dx * scale, dy * scale, angles="xy", scale_units="xy", scale=1, width=0.002)
    b.plot([cam.cx], [cam.cy], "r+", ms=12)
    if cal.circle is not None:
        b.add_patch(
            plt.Circle(
                (cal.circle.cx, cal.circle.cy), cal.circle.radius_px, fill=False, color="0.5"
            )
        )
    b.set_xlim(0, cam.width)
    b.set_ylim(cam.height, 0)
    b.set_aspect("equal")
    b.set_title(f"residuals x{scale:.0f} (+: principal point)")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
