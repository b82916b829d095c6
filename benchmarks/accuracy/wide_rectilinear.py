"""Wide-angle rectilinear lenses with barrel distortion, the field of view unknown, on
simulated star lists (one core, real solve path): what the pinhole FOV search solves, and
what the wide-angle fallback (``Camera.wide_fallback``: a Kannala-Brandt focal scan over
40-100° with what the search left of the time budget) adds.

Frames: boresights uniform on the sphere, random roll, 1500 x 1000 px (3:2), a pinhole with
radial distortion k1 (barrel: negative; in the corners of a 62° field, k1 = -0.2 moves a star
95 px), Hipparcos Hp <= 5.5, 0.5 px centroid noise, the brightest 50 stars with their
brightness (what ``starnav solve IMG`` hands the solver), default options (``SolveOptions()``:
5-40°, then 40-70° and 3-5°, then the fallback; 10 s budget). Scored by ``harness.verdict``
(boresight and roll within 0.5°, the parity); "fallback" counts the answers of the
Kannala-Brandt scan.

    python benchmarks/accuracy/wide_rectilinear.py --frames 20 --out docs/wide_field.md
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, replace_block, score_answer, table_head, table_row, verdict
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.stars import solve_stars
from starnav.simulate import simulate_frame

WIDTH, HEIGHT = 1500, 1000
MAG_LIMIT = 5.5
STARS = 50
ROWS = [(fov, k1) for fov in (50.0, 62.0, 75.0) for k1 in (0.0, -0.1, -0.2)]


def run_row(fov_deg: float, k1: float, frames: int, seed: int, catalog) -> dict:
    """``frames`` frames of a ``fov_deg`` lens of distortion ``k1``, solved blind."""
    focal = Camera.from_fov(fov_deg, WIDTH, HEIGHT).focal_px
    camera = Camera(WIDTH, HEIGHT, focal, k1=k1)
    rng = np.random.default_rng(seed)
    counts = {"right": 0, "wrong": 0, "none": 0, "fallback": 0}
    times = []
    for _ in tqdm(range(frames), desc=f"{fov_deg:g}° k1 {k1:g}", file=sys.stderr):
        frame = simulate_frame(catalog, camera, seed=rng, noise_px=0.5)
        order = np.argsort(frame.mag)[:STARS]
        t0 = time.perf_counter()
        result = solve_stars(
            frame.xy[order],
            SolveOptions(),
            width=WIDTH,
            height=HEIGHT,
            brightness=frame.brightness[order],
        )
        times.append(time.perf_counter() - t0)
        if result.solution is None:
            counts["none"] += 1
            continue
        answer = {"R": result.solution.R_cam_from_icrs.tolist(), "parity": 1}
        right = verdict(score_answer(answer, frame.R_cam_from_icrs)) != "wrong"
        counts["right" if right else "wrong"] += 1
        counts["fallback"] += right and result.solution.camera.model != "pinhole"
    return {"fov_deg": fov_deg, "k1": k1, "frames": frames, **counts, "times": times}


def table(rows: list[dict], frames: int, seed: int, wall_s: float) -> str:
    lines = [
        f"{frames} frames per row, uniform on the sky, seed {seed}; {WIDTH} x {HEIGHT} px, "
        f"Hipparcos Hp <= {MAG_LIMIT:g}, 0.5 px noise, the brightest {STARS} stars, the field "
        f"unknown (default options). Machine: {machine()}; one process.",
        "",
        *table_head(
            "horizontal FOV",
            "k1",
            "corner shift px",
            "right",
            "of which the fallback",
            "wrong",
            "none",
            "median s",
            "max s",
        ),
    ]
    for r in rows:
        focal = Camera.from_fov(r["fov_deg"], WIDTH, HEIGHT).focal_px
        corner = np.hypot(WIDTH, HEIGHT) / 2.0
        shift = abs(r["k1"]) * (corner / focal) ** 2 * corner
        lines.append(
            table_row(
                f"{r['fov_deg']:g}°",
                f"{r['k1']:g}",
                f"{shift:.0f}",
                f"{r['right']} / {r['frames']}",
                r["fallback"],
                r["wrong"],
                r["none"],
                f"{np.median(r['times']):.1f}",
                f"{np.max(r['times']):.1f}",
            )
        )
    lines += [
        "",
        f"Command: `python benchmarks/accuracy/wide_rectilinear.py --frames {frames}`, "
        f"{wall_s:.0f} s in all.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, help="replace block wide-rectilinear of this file")
    args = parser.parse_args()
    t0 = time.time()
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    rows = [run_row(fov, k1, args.frames, args.seed, catalog) for fov, k1 in ROWS]
    text = table(rows, args.frames, args.seed, time.time() - t0)
    print(text)
    if args.out:
        replace_block(args.out, "wide-rectilinear", text)


if __name__ == "__main__":
    main()
