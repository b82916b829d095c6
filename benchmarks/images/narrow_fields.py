"""Narrow fields (3-6°) solved from rendered images with the field of view unknown, into the
``narrow-fields`` block of docs/images.md.

    python benchmarks/images/narrow_fields.py [--frames 40] [--fov 3 4 5 6] [--fov-range 3 40]

Each frame: a boresight uniform on the sky with a random roll, a 1024 x 1024 px pinhole
camera of the given horizontal FOV (and a 1280 x 720 one at 3°: a wide image has the
narrowest diagonal), rendered with ``simulate.render`` (PSF sigma 1 px, 0.5 s exposure: stars
are detected to about Hp 9.5-10, as a small telescope's camera sees them) and solved by
``starnav.solve_image`` searching ``--fov-range``. The ``--probe`` rows, fields narrower
than the search allows (``Camera.fov_limits_deg``), are solved with that limit lifted in
this process, to show where the embedded catalog stops being enough.

The sky rendered is the whole embedded Hipparcos catalog *and* the stars Hipparcos lacks: the
real sky holds about 1.5 times Hipparcos's stars to magnitude 9 and 3 times to 10
(``SKY_LOG_COUNTS``, whole-sky counts from Allen's Astrophysical Quantities), and those stars
are in the image but not in the catalog the solver identifies with. They are drawn per
0.25 mag bin at the density the real sky has there minus the one Hipparcos has there, both
taken around the boresight (within ``LOCAL_RADIUS_DEG``): the real sky's from the Hipparcos
stars to Hp 7 (complete everywhere) scaled by the whole-sky counts. The counts' slope is
steeper in the Milky Way than towards the galactic poles, which this ignores: it overstates
the missing stars towards the poles and understates them in the plane.

Scores: solved = an answer; wrong = boresight or roll 0.5° or more off, or the wrong parity
(``harness.verdict``: unless correct by ``starnav evaluate``'s rule, which also takes an answer
within 5 of its own sigmas); boresight error over the answers that are not wrong; by the
frame's galactic latitude too.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
import starnav.pipeline.fov
from benchmarks.harness import DOCS, machine, replace_block, score_solution, table_head, verdict
from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.simulate.render import RenderSettings, render_frame

DOC = DOCS / "images.md"
# log10 of the stars brighter than V over the whole sky (Allen's Astrophysical Quantities)
SKY_LOG_COUNTS = {6.0: 3.68, 7.0: 4.15, 8.0: 4.61, 9.0: 5.06, 10.0: 5.50, 11.0: 5.92}
COMPLETE_MAG = 7.0  # Hipparcos is complete to here at every galactic latitude
LOCAL_RADIUS_DEG = 8.0
FAINTEST_DRAWN = 11.0
SETTINGS = RenderSettings(exposure_s=0.5, psf_sigma_px=1.0)
SYNTHETIC_ID = 10_000_000  # ids of the drawn non-Hipparcos stars start here
NGP = np.array([-0.8676661, -0.1980764, 0.4559840])  # north galactic pole, ICRS unit vector


def sky_count(mag: float) -> float:
    """Stars brighter than ``mag`` over the whole sky (interpolated in log10)."""
    m = np.array(list(SKY_LOG_COUNTS))
    return float(10.0 ** np.interp(mag, m, np.array(list(SKY_LOG_COUNTS.values()))))


def missing_stars(hip: Catalog, boresight: np.ndarray, radius_deg: float, rng) -> Catalog:
    """Stars of the real sky that Hipparcos lacks, within ``radius_deg`` of ``boresight``."""
    near = hip.vectors @ boresight >= math.cos(math.radians(LOCAL_RADIUS_DEG))
    local_sr = 2.0 * math.pi * (1.0 - math.cos(math.radians(LOCAL_RADIUS_DEG)))
    scale = np.sum(near & (hip.mag <= COMPLETE_MAG)) / local_sr / sky_count(COMPLETE_MAG)
    cap_sr = 2.0 * math.pi * (1.0 - math.cos(math.radians(radius_deg)))
    mags = []
    for lo in np.arange(COMPLETE_MAG, FAINTEST_DRAWN, 0.25):
        real = scale * (sky_count(lo + 0.25) - sky_count(lo))  # per steradian
        have = np.sum(near & (hip.mag > lo) & (hip.mag <= lo + 0.25)) / local_sr
        mags.append(rng.uniform(lo, lo + 0.25, rng.poisson(max(real - have, 0.0) * cap_sr)))
    mag = np.concatenate(mags)
    # uniform on the cap around the boresight
    z = rng.uniform(math.cos(math.radians(radius_deg)), 1.0, len(mag))
    phi = rng.uniform(0.0, 2.0 * math.pi, len(mag))
    local = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    e1 = np.cross(boresight, [0.0, 0.0, 1.0] if abs(boresight[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    v = local @ np.array([e1, np.cross(boresight, e1), boresight])
    ids = SYNTHETIC_ID + np.arange(len(mag))
    ra = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0
    return Catalog(ids, ra, np.degrees(np.arcsin(np.clip(v[:, 2], -1, 1))), mag, "missing")


def joined(a: Catalog, b: Catalog) -> Catalog:
    return Catalog(
        *(np.concatenate([getattr(a, f), getattr(b, f)]) for f in ("ids", "ra_deg", "dec_deg")),
        np.concatenate([a.mag, b.mag]),
        "sky",
    )


@dataclasses.dataclass(frozen=True)
class Outcome:
    fov_deg: float
    solved: bool
    wrong: bool
    boresight_arcsec: float
    galactic_lat_deg: float
    hip_in_frame: int  # Hipparcos stars to Hp 8.5 in the image
    detected: int
    ms: float


def one_frame(hip, camera: Camera, seed: int, fov_range, min_abs_b_deg: float = 0.0) -> Outcome:
    """Render and solve one frame; the boresight uniform on the sky at galactic latitudes of
    at least ``min_abs_b_deg`` (degrees, either side of the plane)."""
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng).as_matrix()
    while abs(R[2] @ NGP) < math.sin(math.radians(min_abs_b_deg)):
        R = Rotation.random(random_state=rng).as_matrix()
    boresight = R[2]
    radius = math.degrees(math.atan(math.hypot(camera.width, camera.height) / 2 / camera.focal_px))
    sky = joined(hip, missing_stars(hip, boresight, radius + 0.2, rng))
    frame = render_frame(sky, camera, R, dataclasses.replace(SETTINGS, seed=seed))
    hip_in = int(np.sum((frame.ids < SYNTHETIC_ID) & (frame.mag <= 8.5)))
    t0 = time.perf_counter()
    res = starnav.solve_image(frame.image, fov_range_deg=fov_range)
    ms = (time.perf_counter() - t0) * 1e3
    lat = math.degrees(math.asin(float(boresight @ NGP)))
    s = res.solution
    if s is None:
        return Outcome(
            camera.fov_deg, False, False, math.nan, lat, hip_in, len(res.detections.xy), ms
        )
    score = score_solution(s, R)
    wrong = verdict(score) == "wrong"
    return Outcome(
        camera.fov_deg, True, wrong, score.boresight_arcsec, lat, hip_in, len(res.detections.xy), ms
    )


def row(label: str, outs: list[Outcome]) -> str:
    n = len(outs)
    solved = [o for o in outs if o.solved]
    good = [o.boresight_arcsec for o in solved if not o.wrong]
    ms = [o.ms for o in outs]
    by_lat = []
    for lo, hi in ((0, 30), (30, 60), (60, 91)):
        band = [o for o in outs if lo <= abs(o.galactic_lat_deg) < hi]
        ok = sum(o.solved and not o.wrong for o in band)
        by_lat.append(f"{ok}/{len(band)}")
    bore = f"{np.median(good):.1f} / {np.max(good):.1f}" if good else "-"
    return (
        f"| {label} | {n} | {100 * len(solved) / n:.0f} | {sum(o.wrong for o in outs)} | "
        f"{bore} | {' · '.join(by_lat)} | "
        f"{np.median([o.hip_in_frame for o in outs]):.0f} "
        f"({min(o.hip_in_frame for o in outs)}) | {np.median(ms):.0f} / {np.max(ms):.0f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--fov", nargs="+", type=float, default=(3.0, 4.0, 5.0, 6.0))
    parser.add_argument("--fov-range", nargs=2, type=float, default=(3.0, 40.0))
    parser.add_argument("--wide-3deg", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument(
        "--probe",
        nargs="*",
        type=float,
        default=(2.5, 2.0),
        help="FOVs below the search's limit, solved with the limit lifted (1024 x 1024)",
    )
    parser.add_argument(
        "--poles",
        nargs="*",
        type=float,
        default=(3.0, 4.0),
        help="FOVs solved again with the boresights at galactic latitudes beyond ±60°",
    )
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    parser.add_argument("--block", default="narrow-fields")
    args = parser.parse_args()
    t_start = time.perf_counter()
    hip = load_catalog(None, mag_limit=FAINTEST_DRAWN)
    cameras = [(f"{f:g}°, 1024 x 1024", Camera.from_fov(f, 1024, 1024)) for f in args.fov]
    if args.wide_3deg:
        cameras.append(("3°, 1280 x 720", Camera.from_fov(3.0, 1280, 720)))
    fov_range = tuple(args.fov_range)
    # the first solve loads the tables and the machine code: not counted
    starnav.solve_image(
        render_frame(hip, cameras[0][1], np.eye(3), SETTINGS).image, fov_range_deg=fov_range
    )
    cameras += [
        (f"{f:g}°, 1024 x 1024, \\|b\\| >= 60°", Camera.from_fov(f, 1024)) for f in args.poles
    ]
    probes = [
        (f"{f:g}°, 1024 x 1024 (below the limit)", Camera.from_fov(f, 1024)) for f in args.probe
    ]
    rows = []
    for k, (label, camera) in enumerate(cameras + probes):
        searched = fov_range if k < len(cameras) else (min(args.probe), fov_range[1])
        if k >= len(cameras):  # lifted for the probes only, after every counted row
            Camera.fov_limits_deg = (min(args.probe), Camera.fov_limits_deg[1])
        pole = 60.0 if "60°" in label else 0.0
        outs = [
            one_frame(hip, camera, args.seed * 1000 + 100 * k + i, searched, pole)
            for i in tqdm(range(args.frames), desc=label, file=sys.stderr, leave=False)
        ]
        rows.append(row(label, outs))
        print(rows[-1], file=sys.stderr)
    lo, hi = fov_range
    text = "\n".join(
        [
            f"{args.frames} frames per row, FOV unknown (searched over {lo:g}-{hi:g}°), "
            f"boresights uniform on the sky; rendered sky: Hipparcos and the stars it lacks "
            f"(to V {FAINTEST_DRAWN:g}), detected to about Hp 9.5-10; seed {args.seed}; "
            f"{machine()}; `python benchmarks/images/narrow_fields.py --frames {args.frames}`, "
            f"{time.perf_counter() - t_start:.0f} s.",
            "",
            *table_head(
                "field",
                "frames",
                "solved %",
                "wrong",
                "boresight ″ median / max",
                "right answers at galactic latitude 0-30° · 30-60° · 60-90°",
                "Hipparcos stars to Hp 8.5 in the image, median (least)",
                "solve ms median / max",
            ),
            *rows,
        ]
    )
    print(text)
    if args.out != "-":
        replace_block(args.out, args.block, text)


if __name__ == "__main__":
    main()
