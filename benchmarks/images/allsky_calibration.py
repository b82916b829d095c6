"""Real all-sky cameras calibrated from their own frames (``starnav.calibrate``, model
``auto``, with site and UTC), checked against the calibration each source ships, and a later
frame tracked from the camera file.

Sources, read where they are (nothing of theirs is copied into the repository):

- MAGIC's all-sky camera (La Palma, 28.761870 N, 17.890777 W, 2200 m), from
  tudo-astroparticlephysics/all_sky_cloud_detection @e18e137d (MIT; a git directory, default
  its mirror): the frames tests/resources/magic_images/20180816_2101, 20180817_0055 and
  20180817_0341 .fits (UTC from DATE-OBS + TIME-OBS), and its calibration: the mapping
  function resources/magic_mapping_spline.json (a cubic spline, ``tck``: r in mm against the
  zenith angle in degrees) with the SX Trius SX9 sensor (1392 px over 6.5 mm), and the
  zenith pixel of cameras.py's MAGIC2018 (row 1040/2 + 7, column 1392/2 + 33, 0-based).
  The first two frames are calibrated; the third (2 h 40 min later) is tracked.
- The KHO Sony A7S all-sky camera (Svalbard, 78.148 N, 16.043 E, 520 m; UNISvalbard/
  KHO-starcalibration, MIT; ../shared/data/allsky): its calibration is a procedure, not
  numbers (Matlab/starcalibration.m: an equidistant lens d = k z about a zenith pixel, and a
  rotation), run on 19 stars identified by hand with Stellarium's apparent altitude and
  azimuth (tests/data/allsky/kho_20201211_star_ids.csv): that model is fitted here to those
  stars by least squares, and our calibration predicts the same stars' pixels from their
  altitude and azimuth.

Compared: the zenith's pixel (ours: the fitted mount's zenith through the fitted lens) in px
and in degrees on the sky; r(θ), the radius against the zenith angle, ours measured from the
principal point, theirs from their zenith pixel (for a levelled camera the two coincide to
the tilt), over the angles both cover; the stars the fit matched, their distance from the
source's zenith pixel against the source's r(zenith angle) (MAGIC). Tracking: the predicted
attitude's error, and the time to predict (astropy) and to solve (detection counted apart),
median of 5 in one warm process, and the first call of a fresh process (the CLI's case).

Run: python benchmarks/images/allsky_calibration.py [--magic-git DIR] [--kho-later FILE] [--write]
(--write: the table into docs/allsky.md). MAGIC is tried only with --magic-git: its
frames are not solved yet by any start (each start's scan runs to its budget, ~25 min).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import splev
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, SHARED, machine, replace_block, table_head, table_row
from starnav.calibrate import calibrate
from starnav.camera import save_camera
from starnav.camera.lens import kernels
from starnav.detect.header import image_time
from starnav.detect.read import read_image
from starnav.errors import StarnavError
from starnav.navigation.frames import enu_directions
from starnav.navigation.mount import mount_prior, predict_attitude
from starnav.pipeline.image import solve_image

DOC = DOCS / "allsky.md"
MAGIC_GIT = Path("/work/.mirror/tudo-astroparticlephysics+all_sky_cloud_detection/repo/.git")
MAGIC_COMMIT = "e18e137d"
MAGIC_FRAMES = ("20180816_2101", "20180817_0055", "20180817_0341")
MAGIC_SITE = (28.761870, -17.890777, 2200.0)
MAGIC_PIXEL_MM = 6.5 / 1392
MAGIC_ZENITH_XY = (1392 / 2 + 33 + 0.5, 1040 / 2 + 7 + 0.5)  # our convention: centre +0.5
KHO = SHARED / "allsky" / "kho_sony_a7s_20201211_200933.jpg"
KHO_IDS = ROOT / "tests" / "data" / "allsky" / "kho_20201211_star_ids.csv"
KHO_SITE = (78.148, 16.043, 520.0)
KHO_UTC = "2020-12-11T20:09:33"
# the same camera's Test_images/LYR-Sony-211121_170751.jpg of that repository (@7888512b), whose
# name gives the UTC (its EXIF time is the camera clock's)
KHO_LATER = Path("/work/allsky/files/kho_lyr-sony-211121_170751.jpg")
KHO_LATER_UTC = "2021-11-21T17:07:51"
REPEATS = 5


def _r(camera, theta: np.ndarray) -> np.ndarray:
    g = kernels().radial_g
    return np.array([camera.focal_px * g(camera.model_code, camera.params, t)[0] for t in theta])


def _zenith(cal) -> tuple[np.ndarray, np.ndarray]:
    """Our zenith: its pixel and its camera-frame direction."""
    z = cal.mount.zenith_cam
    return cal.camera.bearings_to_pixels(z[None])[0], z


def _sky_deg(cal, xy) -> float:
    """The angle (degrees) between our zenith and the direction our lens gives pixel ``xy``."""
    _, z = _zenith(cal)
    v = cal.camera.pixels_to_bearings(np.asarray(xy, float)[None])[0]
    return math.degrees(math.acos(min(1.0, float(v @ z))))


def _git_file(git: Path, path: str, out: Path) -> Path:
    data = subprocess.run(
        ["git", "--git-dir", str(git), "show", f"{MAGIC_COMMIT}:{path}"],
        check=True,
        capture_output=True,
    ).stdout
    out.write_bytes(data)
    return out


def _fit_row(name, cal, zenith_theirs, r_theirs, theta_deg, extra) -> list[str]:
    ours_xy, _ = _zenith(cal)
    dz = np.hypot(*(ours_xy - np.asarray(zenith_theirs)))
    dr = _r(cal.camera, np.radians(theta_deg)) - r_theirs(theta_deg)
    return [
        table_row(
            name,
            f"{cal.camera.model}, f {cal.camera.focal_px:.2f} ± {cal.sigma['focal_px']:.2f} px",
            f"{len(cal.frames)} / {cal.n_stars} / {cal.rms_px:.2f} px",
            f"({ours_xy[0]:.1f}, {ours_xy[1]:.1f})",
            f"({zenith_theirs[0]:.1f}, {zenith_theirs[1]:.1f})",
            f"{dz:.1f} px = {_sky_deg(cal, zenith_theirs):.2f}°",
            f"{cal.mount.to_dict()['zenith_from_axis_deg']:.2f}°",
            f"{np.median(np.abs(dr)):.1f} / {np.max(np.abs(dr)):.1f} px (0-{theta_deg[-1]:.0f}°)",
            extra,
        )
    ]


def magic(git: Path, folder: Path) -> tuple[list[str], list[str]]:
    paths = [
        _git_file(git, f"tests/resources/magic_images/{n}.fits", folder / f"magic_{n}.fits")
        for n in MAGIC_FRAMES
    ]
    spline = json.loads(
        _git_file(
            git, "all_sky_cloud_detection/resources/magic_mapping_spline.json", folder / "s.json"
        ).read_text()
    )
    tck = spline["tck"]

    def r_theirs(theta_deg):
        return np.asarray(splev(theta_deg, tck)) / MAGIC_PIXEL_MM

    times = [image_time(p).time for p in paths]
    cal = calibrate(paths[:2], model="auto", times=times[:2], site=MAGIC_SITE)
    # the matched stars: distance from their zenith pixel against their r(zenith angle)
    enu_z = []
    for k in range(len(cal.frames)):
        rows = cal.residuals[:, 0] == k
        v = cal.star_icrs[rows]
        ra = np.degrees(np.arctan2(v[:, 1], v[:, 0]))
        dec = np.degrees(np.arcsin(v[:, 2]))
        enu = enu_directions(
            ra, dec, times[k], lat_deg=MAGIC_SITE[0], lon_deg=MAGIC_SITE[1], height_m=MAGIC_SITE[2]
        )
        enu_z.append(np.degrees(np.arccos(enu[:, 2])))
    z = np.concatenate(enu_z)
    xy = cal.residuals[:, 1:3]  # where the stars were measured
    keep = z <= spline["tck"][0][-1]
    d_theirs = np.hypot(*(xy[keep] - np.asarray(MAGIC_ZENITH_XY)).T) - r_theirs(z[keep])
    theta = np.arange(0.0, min(float(np.max(z)), tck[0][-1]) + 0.1, 1.0)
    extra = (
        f"stars' radius under theirs: median {np.median(np.abs(d_theirs)):.1f}, "
        f"90 % {np.percentile(np.abs(d_theirs), 90):.1f} px ({keep.sum()} stars)"
    )
    rows = _fit_row("MAGIC all-sky (tudo, MIT)", cal, MAGIC_ZENITH_XY, r_theirs, theta, extra)
    return rows, track(cal, paths[2], times[2].isot, folder, "MAGIC 20180817_0341")


def _bennett_arcmin(apparent_alt_deg: np.ndarray) -> np.ndarray:
    """Refraction (arcminutes) at an apparent altitude (degrees), standard atmosphere."""
    h = np.asarray(apparent_alt_deg, float)
    return 1.0 / np.tan(np.radians(h + 7.31 / (h + 4.4)))


def kho(later: Path | None, folder: Path) -> tuple[list[str], list[str]]:
    with KHO_IDS.open() as fh:
        stars = list(csv.DictReader(fh))
    az = np.radians([float(s["az_deg_stellarium"]) for s in stars])
    apparent = np.array([float(s["alt_deg_apparent_stellarium"]) for s in stars])
    # Stellarium's altitudes are refracted; the catalog directions our fit uses are not (the
    # lens model takes up the refraction, radial about the zenith): Bennett's formula undoes it
    alt = np.radians(apparent - _bennett_arcmin(apparent) / 60.0)
    xy = np.array([(float(s["sony_x0"]), float(s["sony_y0"])) for s in stars]) + 0.5
    zen = np.pi / 2 - alt

    def model(p):  # starcalibration.m's: d = k z about the zenith, the azimuth rotated
        x0, y0, k, rot = p
        d = k * np.degrees(zen)
        return np.column_stack([x0 - d * np.sin(az + rot), y0 - d * np.cos(az + rot)])

    fit = least_squares(lambda p: (model(p) - xy).ravel(), [1416.0, 1416.0, 15.0, 0.0])
    x0, y0, k, _ = fit.x
    theirs_rms = float(np.sqrt(np.mean(np.sum((model(fit.x) - xy) ** 2, axis=1))))
    cal = calibrate(
        [KHO], model="auto", times=[KHO_UTC], site=KHO_SITE, fov_deg=180.0, lens="equisolid"
    )
    enu = np.column_stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)])
    ours = cal.camera.bearings_to_pixels(enu @ cal.mount.R_cam_from_enu.T)
    d_ours = np.hypot(*(ours - xy).T)
    theta = np.arange(0.0, 90.1, 1.0)
    extra = (
        f"their hand stars from Stellarium alt/az (refraction undone): ours median "
        f"{np.median(d_ours):.1f} px, "
        f"max {np.max(d_ours):.1f} px; their equidistant fit rms {theirs_rms:.1f} px"
    )
    rows = _fit_row(
        "KHO Sony A7S (UNIS, MIT)", cal, (x0, y0), lambda t: k * np.asarray(t), theta, extra
    )
    tracked = track(cal, KHO, KHO_UTC, folder, "KHO, the calibrated frame itself")
    if later is not None and later.is_file():
        tracked += track(cal, later, KHO_LATER_UTC, folder, f"KHO {later.name} (11 months on)")
    return rows, tracked


def track(cal, path: Path, when: str, folder: Path, name: str) -> list[str]:
    """A later frame (``path``, taken at the UTC ``when``) tracked from the camera file:
    the prediction's error, the times."""
    cam_file = folder / "camera.json"
    save_camera(cam_file, cal.camera, mount=cal.mount.to_dict())
    pixels = read_image(path)
    predict, solve, detect, algorithms, offs = [], [], [], set(), []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        R = predict_attitude(cal.mount, when)
        predict.append((time.perf_counter() - t0) * 1e3)
        res = solve_image(pixels, camera=cal.camera, prior=R)
        if res.solution is None:
            return [table_row(name, "not solved", res.reason, "", "", "", "")]
        solve.append(res.solve_ms)
        detect.append(res.detect_ms)
        algorithms.add(res.solution.algorithm)
        d = res.solution.R_cam_from_icrs @ R.T
        offs.append(math.degrees(math.acos(min(1.0, (np.trace(d) - 1) / 2))))
    prior = mount_prior(cam_file, path, when)
    command = ["solve", str(path), "--camera", str(cam_file), "--utc", when, "--json"]
    cold = subprocess.run(
        [sys.executable, "-m", "starnav", *command],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    out = json.loads(cold.stdout)
    return [
        table_row(
            name,
            ", ".join(sorted(algorithms)),
            f"{res.solution.n_matched} / {res.solution.false_match_probability:.0e}",
            f"{offs[0]:.3f}°",
            f"{statistics.median(predict):.1f} / {statistics.median(solve):.1f} / "
            f"{statistics.median(detect):.0f} ms",
            f"{out['mount_prior']['predict_ms']:.0f} / {out['solve_ms']:.0f} / "
            f"{out['detect_ms']:.0f} ms ({out['algorithm']})",
            f"{prior.utc}",
        )
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--magic-git", type=Path, help=f"MAGIC's frames from this git directory (e.g. {MAGIC_GIT})"
    )
    parser.add_argument("--kho-later", type=Path, default=KHO_LATER, help="the later KHO frame")
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    cal_rows, track_rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        if args.magic_git is not None and args.magic_git.is_dir():
            try:
                rows, tracked = magic(args.magic_git, Path(tmp))
            except StarnavError as exc:
                rows, tracked = (
                    [table_row("MAGIC all-sky (tudo, MIT)", f"not calibrated: {exc}")],
                    [],
                )
            cal_rows += rows
            track_rows += tracked
        else:
            print("skipped MAGIC: no --magic-git directory", file=sys.stderr)
        if KHO.is_file():
            rows, tracked = kho(args.kho_later, Path(tmp))
            cal_rows += rows
            track_rows += tracked
        else:
            print(f"skipped KHO: {KHO} is absent", file=sys.stderr)
    lines = [
        f"Machine: {machine(load_at_end=True)}.",
        "",
        *table_head(
            "camera",
            "fitted lens (model auto)",
            "frames / stars / rms",
            "our zenith (px)",
            "theirs (px)",
            "zenith apart",
            "our tilt",
            "r(θ) ours - theirs: median / max",
            "stars",
        ),
        *cal_rows,
        "",
        *table_head(
            "tracked frame",
            "answered by",
            "stars / false-match prob.",
            "predicted off",
            "warm: predict / solve / detect (median of 5)",
            "fresh process (CLI): predict / solve / detect",
            "UTC",
        ),
        *track_rows,
    ]
    text = "\n".join(lines)
    print(text)
    if args.write:
        replace_block(DOC, "allsky_calibration", text, missing="## Measured")


if __name__ == "__main__":
    main()
