"""Which three stars give the best three-star pointing? Analytic and Monte Carlo study.

Three-star pointing (``starnav.pointing``) uses only each star's distance a_i from the principal
point, so the boresight error comes from the radial component of the centroid noise. A first
order expansion in the camera frame (star offsets p_i from the principal point, d = z) gives

    p_i . delta_d + f delta_d_z = -f a_i delta_a_i / r_i^2,      r_i^2 = a_i^2 + f^2,

so the boresight error delta_d is the gradient of the plane through the three points p_i with
heights h_i = -f a_i delta_a_i / r_i^2. The gradient of barycentric coordinate i has length
1 / H_i (H_i: the triangle's altitude from vertex i), hence

    sigma_boresight = sigma_px * sqrt(sum_i (f a_i / (r_i^2 H_i))^2)   (radians)
                    ~ (sigma_px / f) * sqrt(sum_i (a_i / H_i)^2)        (small field).

The factor G = sqrt(sum (a_i / H_i)^2) is scale-free: it depends on the triangle's shape and
on where the principal point sits in it, not on the triangle's size. Its minimum is
sqrt(4/3) (equilateral triangle centred on the principal point). ``geometric_factor`` computes
the exact form; the study checks it against ``sigma_boresight_arcsec`` and a Monte Carlo.

``run_study`` evaluates classic arrangements (table), maps the error over the placement and
size of an equilateral triangle, and relates the error to the tetrahedron volume
|det[u1, u2, u3]| / 6 over random triangles. Pixels: origin top-left, y down.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from starnav.camera import Camera
from starnav.geometry import (
    ARCSEC_PER_RAD,
    angle_between,
    attitude_from_radec_roll,
    unit_to_radec,
)
from starnav.pointing import (
    MIN_FLATNESS,
    PointingError,
    flatness,
    sigma_boresight_arcsec,
    three_star,
)

# the attitude the camera looks from; the results do not depend on it (checked in the tests)
ATTITUDE_RADEC_ROLL_DEG = (30.0, 20.0, 10.0)
PLACEMENT_CIRCUMRADIUS = 0.2  # of the image width, for the placement map
SIZE_OFFSETS = (0.0, 0.1, 0.2)  # centroid offsets (of the width, to the right) in the size panel
SIZE_MC_RADII = (0.005, 0.02, 0.08, 0.2, 0.45)  # centred sizes with a Monte Carlo check
_MC_CHUNK = 200_000  # noisy draws solved at once


@dataclass(frozen=True, eq=False)
class ArrangementResult:
    """One triangle: pixel vertices ``xy`` (3, 2), analytic 1-sigma and Monte Carlo RMS
    boresight error (arcsec; None when the API rejects the triple as collinear), the
    tetrahedron volume |det U| / 6 and ``geometric_factor`` = error / (sigma_px / f)."""

    name: str
    xy: np.ndarray = field(repr=False)
    analytic_arcsec: float | None
    mc_rms_arcsec: float | None
    volume: float
    geometric_factor: float | None

    @property
    def rejected(self) -> bool:
        return self.analytic_arcsec is None

    @property
    def mc_over_analytic(self) -> float | None:
        if self.rejected:
            return None
        return self.mc_rms_arcsec / self.analytic_arcsec


@dataclass(frozen=True, eq=False)
class SizeResult:
    """Equilateral triangle of circumradius ``circumradius`` (fraction of the width) whose
    centroid is ``offset`` (fraction of the width) right of the principal point: analytic and
    (where run, else None) Monte Carlo error in arcsec, tetrahedron volume."""

    circumradius: float
    offset: float
    analytic_arcsec: float
    mc_rms_arcsec: float | None
    volume: float


@dataclass(frozen=True, eq=False)
class StudyResult:
    """Everything ``run_study`` measured, and the PNGs it wrote.

    ``volume_slope``: slope of log10(error) against log10(volume) over ``n_random`` random
    triangles (``volume_r2`` its coefficient of determination); ``volume_slope_inside``: the
    same for the triangles that contain the principal point. ``placement_*``: analytic error
    range over the placements of the equilateral triangle in the map (arcsec);
    ``closed_form_max_rel_diff``: largest relative difference, over the random triangles,
    between ``geometric_factor`` * sigma_px / f and ``sigma_boresight_arcsec``."""

    rows: tuple[ArrangementResult, ...]
    figures: tuple[Path, ...]
    fov_deg: float
    width: int
    focal_px: float
    sigma_px: float
    trials: int
    seed: int
    volume_slope: float
    volume_r2: float
    volume_slope_inside: float
    n_random: int
    n_random_inside: int
    placement_min_arcsec: float
    placement_min_offset_px: float
    placement_max_arcsec: float
    sizes: tuple[SizeResult, ...]
    closed_form_max_rel_diff: float

    @property
    def best(self) -> ArrangementResult:
        return min(self._accepted(), key=lambda r: r.analytic_arcsec)

    @property
    def worst(self) -> ArrangementResult:
        return max(self._accepted(), key=lambda r: r.analytic_arcsec)

    def _accepted(self) -> list[ArrangementResult]:
        return [r for r in self.rows if not r.rejected]

    def row(self, name: str) -> ArrangementResult:
        return next(r for r in self.rows if r.name == name)

    def to_dict(self) -> dict:
        """JSON-ready summary: the table rows, best and worst, the volume law, the figures."""
        return {
            "fov_deg": self.fov_deg,
            "width": self.width,
            "focal_px": self.focal_px,
            "sigma_px": self.sigma_px,
            "trials": self.trials,
            "arrangements": [
                {
                    "name": r.name,
                    "xy": r.xy.tolist(),
                    "analytic_arcsec": r.analytic_arcsec,
                    "mc_rms_arcsec": r.mc_rms_arcsec,
                    "volume": r.volume,
                    "geometric_factor": r.geometric_factor,
                    "rejected": r.rejected,
                }
                for r in self.rows
            ],
            "best": self.best.name,
            "worst": self.worst.name,
            "worst_over_best": self.worst.analytic_arcsec / self.best.analytic_arcsec,
            "volume_slope": self.volume_slope,
            "volume_r2": self.volume_r2,
            "volume_slope_inside": self.volume_slope_inside,
            "figures": [str(f) for f in self.figures],
        }


def equilateral(cx: float, cy: float, circumradius: float) -> np.ndarray:
    """Vertices (3, 2) of an equilateral triangle, one vertex straight up (-y)."""
    ang = np.radians([90.0, 210.0, 330.0])
    return np.column_stack([cx + circumradius * np.cos(ang), cy - circumradius * np.sin(ang)])


def classic_arrangements(width: int) -> dict[str, np.ndarray]:
    """Named triangles (pixel vertices) in a ``width`` x ``width`` image, centre W/2.

    Defined for 512 px and scaled with the width (a "3 px" offset is 3/512 of the width)."""
    W = float(width)
    c = W / 2.0
    px = W / 512.0
    pts = {
        "equilateral at the field edge (R 0.45 W, centred)": equilateral(c, c, 0.45 * W),
        "small equilateral at the centre (R 0.08 W)": equilateral(c, c, 0.08 * W),
        "small equilateral off centre (R 0.08 W, 0.3 W away)": equilateral(
            c + 0.24 * W, c - 0.18 * W, 0.08 * W
        ),
        "right triangle, legs 0.8 W, centre inside": [
            [0.15 * W, 0.85 * W],
            [0.15 * W, 0.05 * W],
            [0.95 * W, 0.85 * W],
        ],
        "right triangle in three corners (hypotenuse through centre)": [
            [0.05 * W, 0.05 * W],
            [0.95 * W, 0.05 * W],
            [0.95 * W, 0.95 * W],
        ],
        "one side through the centre (isosceles)": [
            [0.1 * W, c],
            [0.9 * W, c],
            [c, 0.05 * W],
        ],
        "thin isosceles (apex angle ~6°)": [
            [c, 0.05 * W],
            [0.45 * W, 0.95 * W],
            [0.55 * W, 0.95 * W],
        ],
        "clustered (within 30 px, off centre)": [
            [0.75 * W - 13 * px, 0.3 * W - 10 * px],
            [0.75 * W + 15 * px, 0.3 * W - 5 * px],
            [0.75 * W, 0.3 * W + 18 * px],
        ],
        "nearly collinear (3 px off a line)": [
            [0.1 * W, 0.2 * W],
            [0.5 * W, 0.3 * W + 3 * px],
            [0.9 * W, 0.4 * W],
        ],
        "exactly collinear": [
            [0.1 * W, 0.2 * W],
            [0.5 * W, 0.3 * W],
            [0.9 * W, 0.4 * W],
        ],
    }
    return {name: np.asarray(xy, dtype=float) for name, xy in pts.items()}


def star_vectors(xy: np.ndarray, camera: Camera, R_cam_from_icrs: np.ndarray) -> np.ndarray:
    """ICRS unit vectors (n, 3) of the stars imaged at pixels ``xy`` (n, 2)."""
    return camera.pixels_to_bearings(xy) @ R_cam_from_icrs


def radial_px(xy: np.ndarray, camera: Camera) -> np.ndarray:
    """Distances (px) of pixel positions (..., 2) from the principal point."""
    xy = np.asarray(xy, dtype=float)
    return np.hypot(xy[..., 0] - camera.cx, xy[..., 1] - camera.cy)


def tetrahedron_volume(U: np.ndarray) -> float:
    """Volume of the tetrahedron spanned by the sphere's centre and three unit vectors."""
    return float(abs(np.linalg.det(U)) / 6.0)


def geometric_factor(xy: np.ndarray, camera: Camera) -> float:
    """Exact first-order boresight error in units of sigma_px / f (see the module docstring):
    sqrt(sum_i (f^2 a_i / (r_i^2 H_i))^2); inf for a degenerate triangle."""
    p = np.asarray(xy, dtype=float) - [camera.cx, camera.cy]
    a = np.hypot(p[:, 0], p[:, 1])
    f = camera.focal_px
    total = 0.0
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        e = p[k] - p[j]
        cross = e[0] * (p[i] - p[j])[1] - e[1] * (p[i] - p[j])[0]
        altitude = abs(cross) / np.hypot(*e)
        if altitude == 0.0:
            return float("inf")
        total += (f * f * a[i] / ((a[i] ** 2 + f * f) * altitude)) ** 2
    return float(np.sqrt(total))


def analytic_sigma_arcsec(
    xy: np.ndarray, camera: Camera, R_cam_from_icrs: np.ndarray, sigma_px: float
) -> float:
    """Analytic 1-sigma boresight error (arcsec) of the stars imaged at ``xy``.

    Raises ``PointingError`` (from ``three_star``) for a triple the API rejects."""
    U = star_vectors(xy, camera, R_cam_from_icrs)
    a = radial_px(xy, camera)
    ra, dec = unit_to_radec(U)
    three_star(
        np.degrees(ra), np.degrees(dec), r_px=a, focal_px=camera.focal_px
    )  # the API's own acceptance checks
    return sigma_boresight_arcsec(U, a, camera.focal_px, sigma_px)


def monte_carlo_rms_arcsec(
    xy: np.ndarray,
    camera: Camera,
    R_cam_from_icrs: np.ndarray,
    sigma_px: float,
    trials: int,
    rng: np.random.Generator,
) -> float:
    """RMS boresight error (arcsec) over ``trials`` noisy draws of the centroids.

    Each draw adds Gaussian noise ``sigma_px`` to x and y, recomputes a_i and solves
    ``linear_boresight`` (vectorised: one solve with a (3, n) right-hand side)."""
    U = star_vectors(xy, camera, R_cam_from_icrs)
    truth = R_cam_from_icrs[2]
    f = camera.focal_px
    squares = 0.0
    done = 0
    while done < trials:
        n = min(_MC_CHUNK, trials - done)
        noisy = xy[None, :, :] + rng.normal(0.0, sigma_px, (n, 3, 2))
        a = radial_px(noisy, camera)
        cos_theta = f / np.sqrt(a * a + f * f)
        d = np.linalg.solve(U, cos_theta.T).T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        squares += float(np.sum(angle_between(d, truth) ** 2))
        done += n
    return float(np.sqrt(squares / trials) * ARCSEC_PER_RAD)


def run_study(
    *,
    fov_deg: float = 12.0,
    width: int = 512,
    sigma_px: float = 0.5,
    trials: int = 20000,
    seed: int = 0,
    out_dir: Path = Path("docs"),
    progress: bool = True,
    n_random: int = 3000,
    placement_grid: int = 81,
) -> StudyResult:
    """Run the study and write ``pointing_arrangements.png``, ``pointing_placement_map.png``
    and ``pointing_volume.png`` into ``out_dir``.

    Camera: pinhole, ``width`` x ``width`` px, horizontal field ``fov_deg``, principal point at
    the centre; ``sigma_px``: centroid noise per axis; ``trials``: Monte Carlo draws per
    triangle; ``n_random``: random triangles for the volume law; ``placement_grid``: grid
    points per axis of the placement map."""
    camera = Camera.from_fov(fov_deg, width)
    R = attitude_from_radec_roll(*ATTITUDE_RADEC_ROLL_DEG)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    rows = arrangement_results(camera, width, R, sigma_px, trials, seed, progress)
    # placement map: equilateral triangle of fixed size, centroid over the image
    r_place = PLACEMENT_CIRCUMRADIUS * width
    centres = np.linspace(0.0, width, placement_grid)
    grid = placement_map(camera, R, sigma_px, centres, r_place)
    iy, ix = np.unravel_index(np.nanargmin(grid), grid.shape)
    placement_min_offset = float(np.hypot(centres[ix] - camera.cx, centres[iy] - camera.cy))
    sizes = size_results(camera, width, R, sigma_px, trials, seed, progress)
    law = volume_law(camera, width, R, sigma_px, seed, n_random)

    return StudyResult(
        rows=tuple(rows),
        figures=write_figures(out_dir, camera, sigma_px, rows, grid, centres, r_place, sizes, law),
        fov_deg=fov_deg,
        width=width,
        focal_px=camera.focal_px,
        sigma_px=sigma_px,
        trials=trials,
        seed=seed,
        volume_slope=float(law.slope),
        volume_r2=float(law.r2),
        volume_slope_inside=float(law.slope_inside),
        n_random=int(n_random),
        n_random_inside=int(law.inside.sum()),
        placement_min_arcsec=float(np.nanmin(grid)),
        placement_min_offset_px=placement_min_offset,
        placement_max_arcsec=float(np.nanmax(grid)),
        sizes=tuple(sizes),
        closed_form_max_rel_diff=law.closed_form_max_rel_diff,
    )


def arrangement_results(
    camera: Camera,
    width: int,
    R: np.ndarray,
    sigma_px: float,
    trials: int,
    seed: int,
    progress: bool,
) -> list[ArrangementResult]:
    """The classic arrangements (``classic_arrangements(width)``) with their analytic and
    Monte Carlo errors (``trials`` draws each, seeded by (``seed``, row number))."""
    rows = []
    bar = tqdm(
        classic_arrangements(width).items(),
        desc="arrangements (Monte Carlo)",
        file=sys.stderr,
        disable=not progress,
    )
    for k, (name, xy) in enumerate(bar):
        U = star_vectors(xy, camera, R)
        volume = tetrahedron_volume(U)
        try:
            analytic = analytic_sigma_arcsec(xy, camera, R, sigma_px)
        except PointingError:
            rows.append(ArrangementResult(name, xy, None, None, volume, None))
            continue
        mc = monte_carlo_rms_arcsec(
            xy, camera, R, sigma_px, trials, np.random.default_rng([seed, k])
        )
        rows.append(ArrangementResult(name, xy, analytic, mc, volume, geometric_factor(xy, camera)))
    return rows


def placement_map(
    camera: Camera, R: np.ndarray, sigma_px: float, centres: np.ndarray, circumradius: float
) -> np.ndarray:
    """Analytic error (arcsec) of the equilateral triangle of ``circumradius`` px centred at
    each (``centres[ix]``, ``centres[iy]``), as grid[iy, ix]; NaN where it leaves the image."""
    grid = np.full((len(centres), len(centres)), np.nan)
    for iy, cy in enumerate(centres):
        for ix, cx in enumerate(centres):
            xy = equilateral(cx, cy, circumradius)
            if camera.contains(xy).all():
                grid[iy, ix] = analytic_sigma_arcsec(xy, camera, R, sigma_px)
    return grid


def size_results(
    camera: Camera,
    width: int,
    R: np.ndarray,
    sigma_px: float,
    trials: int,
    seed: int,
    progress: bool,
) -> list[SizeResult]:
    """The size panel: equilateral triangles of 40 circumradii at each of ``SIZE_OFFSETS``
    (analytic only), then the centred ones of ``SIZE_MC_RADII`` with a Monte Carlo check;
    radii and offsets are fractions of ``width``."""
    sizes = []
    radii = np.geomspace(0.005, 0.5, 40)
    for offset in SIZE_OFFSETS:
        for rc in radii:
            xy = equilateral(camera.cx + offset * width, camera.cy, rc * width)
            if camera.contains(xy).all():
                sizes.append(
                    SizeResult(
                        float(rc),
                        offset,
                        analytic_sigma_arcsec(xy, camera, R, sigma_px),
                        None,
                        tetrahedron_volume(star_vectors(xy, camera, R)),
                    )
                )
    for k, rc in enumerate(
        tqdm(SIZE_MC_RADII, desc="sizes (Monte Carlo)", file=sys.stderr, disable=not progress)
    ):
        xy = equilateral(camera.cx, camera.cy, rc * width)
        rng = np.random.default_rng([seed, 1000 + k])
        sizes.append(
            SizeResult(
                rc,
                0.0,
                analytic_sigma_arcsec(xy, camera, R, sigma_px),
                monte_carlo_rms_arcsec(xy, camera, R, sigma_px, trials, rng),
                tetrahedron_volume(star_vectors(xy, camera, R)),
            )
        )
    return sizes


@dataclass(frozen=True, eq=False)
class VolumeLaw:
    """The analytic error (arcsec) of ``n_random`` random triangles against their tetrahedron
    volume: per triangle ``volumes``, ``errors`` and whether it holds the principal point
    (``inside``); the fit log10(error) = ``slope`` log10(volume) + ``intercept`` with its
    coefficient of determination ``r2``, the slope of the triangles inside, and the largest
    relative difference of the closed form (``geometric_factor``) from the errors."""

    volumes: np.ndarray
    errors: np.ndarray
    inside: np.ndarray
    slope: float
    intercept: float
    r2: float
    slope_inside: float
    closed_form_max_rel_diff: float


def volume_law(
    camera: Camera, width: int, R: np.ndarray, sigma_px: float, seed: int, n_random: int
) -> VolumeLaw:
    """The volume law over ``n_random`` random triangles (vertices uniform in 0..``width``,
    too flat ones skipped), drawn with the seed (``seed``, 2000)."""
    f = camera.focal_px
    per_sigma_f = sigma_px / f * ARCSEC_PER_RAD  # arcsec per unit of geometric factor
    rng = np.random.default_rng([seed, 2000])
    volumes, errors, inside, closed_form = [], [], [], []
    while len(volumes) < n_random:
        xy = rng.uniform(0.0, width, (3, 2))
        U = star_vectors(xy, camera, R)
        if flatness(U) < MIN_FLATNESS:
            continue
        volumes.append(tetrahedron_volume(U))
        errors.append(sigma_boresight_arcsec(U, radial_px(xy, camera), f, sigma_px))
        inside.append(_contains_point(xy, (camera.cx, camera.cy)))
        closed_form.append(geometric_factor(xy, camera) * per_sigma_f)
    volumes, errors, inside = np.array(volumes), np.array(errors), np.array(inside)
    closed_form_rel = float(np.max(np.abs(np.array(closed_form) / errors - 1.0)))
    slope, intercept = np.polyfit(np.log10(volumes), np.log10(errors), 1)
    resid = np.log10(errors) - (slope * np.log10(volumes) + intercept)
    r2 = 1.0 - np.var(resid) / np.var(np.log10(errors))
    slope_inside = np.polyfit(np.log10(volumes[inside]), np.log10(errors[inside]), 1)[0]
    return VolumeLaw(volumes, errors, inside, slope, intercept, r2, slope_inside, closed_form_rel)


def write_figures(
    out_dir: Path,
    camera: Camera,
    sigma_px: float,
    rows: list[ArrangementResult],
    grid: np.ndarray,
    centres: np.ndarray,
    r_place: float,
    sizes: list[SizeResult],
    law: VolumeLaw,
) -> tuple[Path, ...]:
    """Write the study's three PNGs into ``out_dir``; their paths."""
    return (
        _plot_arrangements(rows, camera, sigma_px, out_dir / "pointing_arrangements.png"),
        _plot_placement(
            grid, centres, sizes, camera, r_place, sigma_px, out_dir / "pointing_placement_map.png"
        ),
        _plot_volume(
            law.volumes,
            law.errors,
            law.inside,
            law.slope,
            law.intercept,
            sizes,
            camera,
            out_dir / "pointing_volume.png",
        ),
    )


def _contains_point(xy: np.ndarray, q) -> bool:
    """Whether point q lies inside (or on) the triangle ``xy``."""
    signs = []
    for i in range(3):
        p0, p1 = xy[i], xy[(i + 1) % 3]
        signs.append((p1[0] - p0[0]) * (q[1] - p0[1]) - (p1[1] - p0[1]) * (q[0] - p0[0]))
    return bool(min(signs) >= 0 or max(signs) <= 0)


def format_table(result: StudyResult) -> str:
    """Markdown: the arrangement table and the summary numbers of the study."""
    r = result
    per_sigma_f = r.sigma_px / r.focal_px * ARCSEC_PER_RAD
    lines = [
        f"Camera {r.width} x {r.width} px, {r.fov_deg:g}° field (f = {r.focal_px:.1f} px, "
        f"1 px = {ARCSEC_PER_RAD / r.focal_px:.1f}″ at the centre), centroid noise "
        f"{r.sigma_px:g} px per axis, {r.trials} Monte Carlo draws per triangle, seed {r.seed}. "
        f"G = error / (sigma_px / f); its minimum is sqrt(4/3) = {np.sqrt(4 / 3):.3f}.",
        "",
        "| arrangement | analytic 1σ (″) | Monte Carlo RMS (″) | MC / analytic | G "
        "| volume \\|det U\\|/6 | × best |",
        "|---|---|---|---|---|---|---|",
    ]
    best = r.best.analytic_arcsec
    for row in sorted(r.rows, key=lambda x: np.inf if x.rejected else x.analytic_arcsec):
        if row.rejected:
            lines.append(
                f"| {row.name} | rejected (collinear) | — | — | — | {row.volume:.2e} | — |"
            )
            continue
        lines.append(
            f"| {row.name} | {row.analytic_arcsec:.1f} | {row.mc_rms_arcsec:.1f} | "
            f"{row.mc_over_analytic:.3f} | {row.geometric_factor:.3f} | {row.volume:.2e} | "
            f"{row.analytic_arcsec / best:.2f} |"
        )
    centred = sorted(
        (s for s in r.sizes if s.offset == 0.0 and s.mc_rms_arcsec is None),
        key=lambda s: s.circumradius,
    )
    mc_sizes = [s for s in r.sizes if s.mc_rms_arcsec is not None]
    lines += [
        "",
        f"Best: {r.best.name}, {best:.1f}″. Worst accepted: {r.worst.name}, "
        f"{r.worst.analytic_arcsec:.1f}″ ({r.worst.analytic_arcsec / best:.0f} × the best).",
        "",
        f"Placement map (equilateral, circumradius {PLACEMENT_CIRCUMRADIUS:g} W = "
        f"{PLACEMENT_CIRCUMRADIUS * r.width:.0f} px): {r.placement_min_arcsec:.1f}″ at best "
        f"(centroid {r.placement_min_offset_px:.1f} px from the principal point), "
        f"{r.placement_max_arcsec:.1f}″ at worst.",
        "",
        f"Size, centred equilateral (analytic): {centred[0].analytic_arcsec:.2f}″ at "
        f"circumradius {centred[0].circumradius * r.width:.1f} px, "
        f"{centred[-1].analytic_arcsec:.2f}″ at {centred[-1].circumradius * r.width:.1f} px. "
        "Monte Carlo check: "
        + ", ".join(
            f"{s.circumradius * r.width:.1f} px: {s.mc_rms_arcsec:.1f}″ vs {s.analytic_arcsec:.1f}″"
            for s in mc_sizes
        )
        + ".",
        "",
        f"Volume law, {r.n_random} random triangles: log10(error) = "
        f"{r.volume_slope:.3f} log10(volume) + c, R² = {r.volume_r2:.2f}; the "
        f"{r.n_random_inside} that contain the principal point: slope "
        f"{r.volume_slope_inside:.3f}. (1 unit of G = {per_sigma_f:.1f}″.) Closed form G "
        f"against the API's covariance over the same triangles: largest relative difference "
        f"{r.closed_form_max_rel_diff:.1e}.",
    ]
    return "\n".join(lines)


# ---------------------------------------------------------------- figures


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _image_axes(ax, camera: Camera) -> None:
    ax.add_patch(_pyplot().Rectangle((0, 0), camera.width, camera.height, fill=False, color="0.3"))
    ax.plot(camera.cx, camera.cy, "+", color="k", ms=8)
    ax.set_xlim(-0.03 * camera.width, 1.03 * camera.width)
    ax.set_ylim(1.03 * camera.height, -0.03 * camera.height)  # y down, origin top-left
    ax.set_aspect("equal")


def _plot_arrangements(rows, camera: Camera, sigma_px: float, path: Path) -> Path:
    plt = _pyplot()
    n = len(rows)
    ncol = 5
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 3.9 * nrow))
    best = min(r.analytic_arcsec for r in rows if not r.rejected)
    for ax, row in zip(axes.flat, rows, strict=False):
        _image_axes(ax, camera)
        tri = np.vstack([row.xy, row.xy[:1]])
        color = "tab:red" if row.rejected else "tab:blue"
        ax.fill(*row.xy.T, color=color, alpha=0.15)
        ax.plot(*tri.T, "-o", color=color, ms=4)
        if row.rejected:
            text = "rejected (collinear)"
        else:
            text = (
                f"analytic {row.analytic_arcsec:.1f}″\nMC {row.mc_rms_arcsec:.1f}″  "
                f"(× {row.analytic_arcsec / best:.2f})"
            )
        ax.text(
            0.03 * camera.width,
            0.97 * camera.height,
            text,
            fontsize=8,
            va="bottom",
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"},
        )
        ax.set_title(_wrap(row.name, 30), fontsize=8)
        ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(
        f"Three-star pointing: 1σ boresight error, {camera.width} px / {camera.fov_deg:.0f}° "
        f"camera, centroid noise {sigma_px:g} px (+: principal point)",
        fontsize=10,
    )
    fig.tight_layout(h_pad=2.0)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _plot_placement(grid, centres, sizes, camera, r_place, sigma_px, path: Path) -> Path:
    plt = _pyplot()
    from matplotlib.colors import LogNorm

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5.6))
    step = centres[1] - centres[0]
    extent = (
        centres[0] - step / 2,
        centres[-1] + step / 2,
        centres[-1] + step / 2,
        centres[0] - step / 2,
    )
    im = ax0.imshow(grid, extent=extent, origin="upper", norm=LogNorm(), cmap="viridis")
    fig.colorbar(im, ax=ax0, label="analytic 1σ boresight error (″)")
    levels = np.nanmin(grid) * np.array([1.05, 1.25, 1.5, 2.0, 3.0])
    cs = ax0.contour(centres, centres, grid, levels=levels, colors="w", linewidths=0.7)
    ax0.clabel(cs, fmt="%.0f″", fontsize=7)
    for cx, cy in ((camera.cx, camera.cy), (0.3 * camera.width, 0.7 * camera.height)):
        xy = equilateral(cx, cy, r_place)
        ax0.plot(*np.vstack([xy, xy[:1]]).T, "-", color="w", lw=0.8, alpha=0.8)
    _image_axes(ax0, camera)
    ax0.set_title(
        f"centroid of an equilateral triangle (circumradius {r_place:.0f} px, vertex up);\n"
        "blank: a vertex leaves the image",
        fontsize=9,
    )
    ax0.set_xlabel("x (px)")
    ax0.set_ylabel("y (px)")

    for offset in SIZE_OFFSETS:
        pts = sorted(
            (s for s in sizes if s.offset == offset and s.mc_rms_arcsec is None),
            key=lambda s: s.circumradius,
        )
        ax1.plot(
            [s.circumradius * camera.width for s in pts],
            [s.analytic_arcsec for s in pts],
            "-",
            label=f"analytic, centroid {offset * camera.width:.0f} px right of centre",
        )
    mc = [s for s in sizes if s.mc_rms_arcsec is not None]
    ax1.plot(
        [s.circumradius * camera.width for s in mc],
        [s.mc_rms_arcsec for s in mc],
        "ko",
        mfc="none",
        label="Monte Carlo RMS, centred",
    )
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("circumradius (px)")
    ax1.set_ylabel("1σ boresight error (″)")
    ax1.set_title(f"size of an equilateral triangle (noise {sigma_px:g} px)", fontsize=9)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _plot_volume(volumes, errors, inside, slope, intercept, sizes, camera, path) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 5.8))
    ax.loglog(
        volumes[~inside],
        errors[~inside],
        ".",
        ms=3,
        alpha=0.5,
        color="tab:orange",
        label="principal point outside the triangle",
    )
    ax.loglog(
        volumes[inside],
        errors[inside],
        ".",
        ms=3,
        alpha=0.5,
        color="tab:blue",
        label="principal point inside",
    )
    v = np.geomspace(volumes.min(), volumes.max(), 50)
    ax.loglog(
        v,
        10 ** (slope * np.log10(v) + intercept),
        "k-",
        label=f"least-squares fit, slope {slope:.2f}",
    )
    centred = sorted(
        (z for z in sizes if z.offset == 0.0 and z.mc_rms_arcsec is None),
        key=lambda z: z.circumradius,
    )
    r0, r1 = (z.circumradius * camera.width for z in (centred[0], centred[-1]))
    ax.loglog(
        [z.volume for z in centred],
        [z.analytic_arcsec for z in centred],
        "k--",
        lw=2,
        label=f"equilateral centred on the principal point, circumradius {r0:.1f}-{r1:.0f} px",
    )
    ax.set_xlabel("tetrahedron volume |det[u1, u2, u3]| / 6")
    ax.set_ylabel("analytic 1σ boresight error (″)")
    ax.set_title(
        f"{len(volumes)} random triangles, vertices uniform in the {camera.width} px image",
        fontsize=9,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _wrap(text: str, width: int) -> str:
    words, lines, line = text.split(), [], ""
    for w in words:
        if line and len(line) + 1 + len(w) > width:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}".strip()
    return "\n".join([*lines, line])
