"""Sensitivity of the celestial fix (domain.md section 3): how a tilt error of the gravity vector
and the error of single star directions move the position and the heading.

Monte Carlo on the real fix path (``fix_from_directions``): the stars a set of cameras sees at a
known site and UTC are simulated once (``simulate_observation``); each trial perturbs them and
the gravity vector and fixes again. The camera set-up is a parameter (``CameraSetup``: mounts
and one lens model, any ``CameraModel``): three 20° cameras by default, or e.g. one camera
looking up (``upward_camera``); other set-ups can be compared at the same star error and tilt.
Identification is not part of it (the stars are known), so the numbers isolate the geometry of
the fix.

- tilt error t: gravity turned by exactly t about a random horizontal axis;
- single-star error e: every star direction moved by an isotropic Gaussian error whose rms
  (total angle) is e.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from starnav.camera import Camera, CameraModel
from starnav.geometry import ARCSEC_PER_RAD
from starnav.navigation.fix import fix_from_directions
from starnav.navigation.frames import radii_of_curvature_m
from starnav.navigation.simulate import simulate_observation

PUBLISHED_TILT = {3: 126.99, 5: 211.65, 10: 423.29, 15: 634.93, 20: 846.57}
PUBLISHED_STAR = {
    1: (9.21, 0.359),
    2: (18.32, 0.744),
    3: (27.08, 1.073),
    4: (38.44, 1.531),
    5: (45.98, 1.805),
}
THREE_CAMERAS = ((0.0, 45.0), (120.0, 45.0), (240.0, 45.0))
UPWARD = ((0.0, 90.0),)
FEW_STARS = 3  # brightest stars per camera of the study's "few stars" columns
COMPARE_CONDITIONS = ((2.0, 0.0), (2.0, 5.0))  # (star error, tilt error) arcsec of set-ups


@dataclass(frozen=True)
class CameraSetup:
    """The star cameras of the platform: a ``label``, the ``mounts`` ((azimuth, elevation) of
    each boresight in the body frame, degrees; elevation 90 looks straight up when level) and
    the lens model ``camera`` they all have (any ``starnav.camera.CameraModel``)."""

    label: str
    mounts: tuple[tuple[float, float], ...]
    camera: CameraModel


def three_cameras(fov_deg: float = 20.0, width: int = 1024) -> CameraSetup:
    """The reference set-up: three pinhole cameras of ``fov_deg`` (horizontal, degrees) and
    ``width`` x ``width`` px, 120° apart in azimuth at 45° elevation."""
    return CameraSetup(
        f"three {fov_deg:g}° cameras", THREE_CAMERAS, Camera.from_fov(fov_deg, width)
    )


def upward_camera(camera: CameraModel, label: str | None = None) -> CameraSetup:
    """One camera with the lens model ``camera`` looking straight up (body -z)."""
    return CameraSetup(label or f"one upward {camera.fov_deg:.0f}° camera", UPWARD, camera)


@dataclass(frozen=True)
class StudyRow:
    """One setting: its label, stars used, mean and rms position error (m), mean absolute and
    rms heading error (arcsec), over ``trials``."""

    setting: str
    stars: int
    mean_position_m: float
    rms_position_m: float
    mean_azimuth_arcsec: float
    rms_azimuth_arcsec: float
    trials: int


def _rotate(v: np.ndarray, axis: np.ndarray, angle_rad: np.ndarray | float) -> np.ndarray:
    """Rodrigues rotation of vectors ``v`` (n, 3) about unit ``axis`` (n, 3) by ``angle``."""
    angle = np.asarray(angle_rad)[..., None]
    return (
        v * np.cos(angle)
        + np.cross(axis, v) * np.sin(angle)
        + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1 - np.cos(angle))
    )


def _perturb_stars(body: np.ndarray, rms_rad: float, rng) -> np.ndarray:
    if rms_rad == 0:
        return body
    # a 2-D Gaussian in the plane normal to each direction, rms total angle = rms_rad
    step = rng.normal(0.0, rms_rad / np.sqrt(2.0), body.shape)
    step -= body * np.sum(step * body, axis=1, keepdims=True)
    moved = body + step
    return moved / np.linalg.norm(moved, axis=1, keepdims=True)


def _tilt(gravity: np.ndarray, angle_rad: float, rng, *, both_axes: bool = False) -> np.ndarray:
    """Gravity turned by ``angle_rad`` about a random horizontal axis; with ``both_axes``, by
    ``angle_rad`` about each of two perpendicular horizontal axes (sqrt 2 times in all)."""
    if angle_rad == 0:
        return gravity
    axis = np.cross(gravity, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    turned = _rotate(gravity[None], axis[None], angle_rad)[0]
    if both_axes:
        other = np.cross(gravity, axis)
        turned = _rotate(turned[None], other[None], angle_rad)[0]
    return turned


@dataclass(frozen=True)
class Setup:
    """Where and when the study's platform stands, the size of its default cameras and the
    faintest stars they see."""

    lat_deg: float = 34.26
    lon_deg: float = 108.94
    utc: str = "2013-10-10T14:00:00Z"  # the reference epoch, 22:00 local time
    heading_deg: float = 30.0
    width: int = 1024
    mag_limit: float = 7.0


def _trials(
    sky,
    setup,
    trials,
    rng,
    *,
    star_rms_arcsec=0.0,
    tilt_arcsec=0.0,
    both_axes=False,
    cameras=None,
    brightest=None,
):
    cameras = range(len(sky.body)) if cameras is None else cameras
    body = np.vstack([sky.body[k][:brightest] for k in cameras])
    rows = np.concatenate([sky.rows[k][:brightest] for k in cameras])
    ra, dec = sky.catalog.ra_deg[rows], sky.catalog.dec_deg[rows]
    g = sky.observation.gravity_body
    m_north, m_east = radii_of_curvature_m(setup.lat_deg)
    position, azimuth = [], []
    for _ in range(trials):
        fix = fix_from_directions(
            _perturb_stars(body, star_rms_arcsec / ARCSEC_PER_RAD, rng),
            ra,
            dec,
            setup.utc,
            _tilt(g, tilt_arcsec / ARCSEC_PER_RAD, rng, both_axes=both_axes),
        )
        north = np.radians(fix.lat_deg - setup.lat_deg) * m_north
        east = np.radians(fix.lon_deg - setup.lon_deg) * m_east * np.cos(np.radians(setup.lat_deg))
        position.append(np.hypot(north, east))
        azimuth.append(((fix.azimuth_deg - setup.heading_deg + 180.0) % 360.0 - 180.0) * 3600.0)
    position, azimuth = np.array(position), np.abs(np.array(azimuth))
    return len(body), position, azimuth


def _row(label, n, position, azimuth) -> StudyRow:
    return StudyRow(
        label,
        n,
        float(position.mean()),
        float(np.sqrt(np.mean(position**2))),
        float(azimuth.mean()),
        float(np.sqrt(np.mean(azimuth**2))),
        len(position),
    )


def run_locate_study(
    *,
    trials: int = 50,
    fov_deg: float = 20.0,
    fovs_deg: tuple[float, ...] = (5.0, 10.0, 20.0, 30.0),
    seed: int = 0,
    setup: Setup | None = None,
    cameras: CameraSetup | None = None,
    compare: tuple[CameraSetup, ...] = (),
    compare_conditions: tuple[tuple[float, float], ...] = COMPARE_CONDITIONS,
    progress: bool = True,
) -> dict[str, list[StudyRow]]:
    """The study's tables for the camera set-up ``cameras`` (default: ``three_cameras(fov_deg,
    setup.width)``): ``tilt`` (tilt error alone, about one axis; ``tilt2``: that much about
    each of two axes), ``star`` (single-star error alone, every star in view; ``star3``: the 3
    brightest per camera), ``cameras`` (its first camera alone against all of them, 2″ star
    error; the whole set-up only when it has one camera), ``fov`` (2″ star error, pinholes of
    each field of view in ``fovs_deg`` on the set-up's mounts) and, when ``compare`` names
    other set-ups, ``setups``: the set-up and each of those at every (star error, tilt error)
    of ``compare_conditions`` (arcsec)."""
    setup = setup or Setup()
    cameras = cameras or three_cameras(fov_deg, setup.width)
    rng = np.random.default_rng(seed)

    def sky_for(lens, mounts=cameras.mounts):
        return simulate_observation(
            lat_deg=setup.lat_deg,
            lon_deg=setup.lon_deg,
            utc=setup.utc,
            heading_deg=setup.heading_deg,
            mounts=mounts,
            camera=lens,
            mag_limit=setup.mag_limit,
        )

    sky = sky_for(cameras.camera)
    az = cameras.mounts[0][0]
    jobs = (
        [("tilt", f"{t}″", {"tilt_arcsec": t}) for t in PUBLISHED_TILT]
        + [("tilt2", f"{t}″", {"tilt_arcsec": t, "both_axes": True}) for t in PUBLISHED_TILT]
        + [("star", f"{e}″", {"star_rms_arcsec": e}) for e in PUBLISHED_STAR]
        + [
            ("star3", f"{e}″", {"star_rms_arcsec": e, "brightest": FEW_STARS})
            for e in PUBLISHED_STAR
        ]
        + (
            [("cameras", f"one camera (az {az:g}°)", {"star_rms_arcsec": 2.0, "cameras": [0]})]
            if len(cameras.mounts) > 1
            else []
        )
        + [("cameras", cameras.label, {"star_rms_arcsec": 2.0})]
    )
    tables: dict[str, list[StudyRow]] = {k: [] for k in ("tilt", "tilt2", "star", "star3")}
    tables.update(cameras=[], fov=[])
    others = [(other, sky_for(other.camera, other.mounts)) for other in compare]
    total = len(jobs) + len(fovs_deg) + (len(others) + 1) * len(compare_conditions) * bool(others)
    bar = tqdm(total=total, desc="locate study", disable=not progress)
    for table, label, options in jobs:
        n, position, azimuth = _trials(sky, setup, trials, rng, **options)
        tables[table].append(_row(label, n, position, azimuth))
        bar.update()
    for fov in fovs_deg:
        lens = Camera.from_fov(fov, setup.width)
        n, position, azimuth = _trials(sky_for(lens), setup, trials, rng, star_rms_arcsec=2.0)
        tables["fov"].append(_row(f"{fov:g}°", n, position, azimuth))
        bar.update()
    if others:
        tables["setups"] = []
        for star, tilt in compare_conditions:
            for which, its_sky in [(cameras, sky), *others]:
                n, position, azimuth = _trials(
                    its_sky, setup, trials, rng, star_rms_arcsec=star, tilt_arcsec=tilt
                )
                label = f"{which.label}, {star:g}″ stars, {tilt:g}″ tilt"
                tables["setups"].append(_row(label, n, position, azimuth))
                bar.update()
    bar.close()
    return tables


def format_tables(tables: dict[str, list[StudyRow]]) -> str:
    """The study as markdown, ours beside the published numbers."""
    lines = [
        "| tilt error | published position error (m) | ours, about one axis (m) | ours, that "
        "much about each of two axes (m) |",
        "|---|---|---|---|",
    ]
    for one, two, published in zip(
        tables["tilt"], tables["tilt2"], PUBLISHED_TILT.values(), strict=True
    ):
        lines.append(
            f"| {one.setting} | {published:.2f} | {one.mean_position_m:.2f} | "
            f"{two.mean_position_m:.2f} |"
        )
    lines += [
        "",
        "| single-star error (rms) | published mean position (m) | ours, all stars (m) | "
        f"ours, {FEW_STARS} brightest per camera (m) | published azimuth (″) | ours, all (″) | "
        f"ours, {FEW_STARS} per camera (″) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row, few, (pos, az) in zip(
        tables["star"], tables["star3"], PUBLISHED_STAR.values(), strict=True
    ):
        lines.append(
            f"| {row.setting} | {pos:.2f} | {row.mean_position_m:.2f} | "
            f"{few.mean_position_m:.2f} | {az:.3f} | {row.mean_azimuth_arcsec:.3f} | "
            f"{few.mean_azimuth_arcsec:.3f} |"
        )
    titles = [("cameras", "cameras (2″ star error)"), ("fov", "field of view (2″)")]
    titles += [("setups", "camera set-up")] if tables.get("setups") else []
    for name, title in titles:
        if not tables[name]:
            continue
        lines += [
            "",
            f"| {title} | stars | mean position (m) | mean abs azimuth (″) |",
            "|---|---|---|---|",
        ]
        for row in tables[name]:
            lines.append(
                f"| {row.setting} | {row.stars} | {row.mean_position_m:.2f} | "
                f"{row.mean_azimuth_arcsec:.3f} |"
            )
    return "\n".join(lines)


def plot_study(tables: dict[str, list[StudyRow]], path) -> None:
    """Position error against tilt error and against single-star error, with the published
    points (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    tilt = list(PUBLISHED_TILT)
    left.plot(tilt, list(PUBLISHED_TILT.values()), "ks", label="published")
    left.plot(tilt, [r.mean_position_m for r in tables["tilt"]], "o-", label="ours, one axis")
    left.plot(tilt, [r.mean_position_m for r in tables["tilt2"]], "o--", label="ours, two axes")
    left.set_xlabel("tilt error (″)")
    left.set_ylabel("position error (m)")
    star = list(PUBLISHED_STAR)
    right.plot(star, [p for p, _ in PUBLISHED_STAR.values()], "ks", label="published")
    right.plot(star, [r.mean_position_m for r in tables["star"]], "o-", label="ours, all stars")
    right.plot(
        star,
        [r.mean_position_m for r in tables["star3"]],
        "o--",
        label=f"ours, {FEW_STARS} brightest per camera",
    )
    right.set_xlabel("single-star error, rms (″)")
    right.set_ylabel("mean position error (m)")
    for ax in (left, right):
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("three cameras 120° apart at 45° elevation, 1024 px, Hp <= 7", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
