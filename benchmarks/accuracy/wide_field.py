"""Wide-field and fisheye lost in space on simulated star lists (one core, real solve path).

Frames: boresights uniform on the sphere, random roll, 1024 x 1024 px, Hipparcos Hp <= 6,
0.5 px centroid noise, 5 false stars, 10 % of stars dropped, brightness (magnitudes) given.
Each row is a lens model at a horizontal field of view; fields of 150° and more are circular
fisheyes (the image circle inscribed in the image, its full angle the field). The camera is
known (``solve_stars(camera=...)``); a solution is correct by ``starnav evaluate``'s rule
(``harness.CORRECT_RULE``), wrong otherwise; "ids off" counts the points of correct solutions
given another star's id (close pairs a few pixels apart: at 185° over 1024 px a pixel is 11′
of sky). Time: identification and fit (``SolveResult.time_ms``), catalog, database and machine
code loaded.

    python benchmarks/accuracy/wide_field.py --frames 100 --out docs/wide_field.md
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import CORRECT_RULE, machine, replace_block, score_solution, table_head
from starnav.api import get_database, solve_stars
from starnav.camera import MODELS, CameraModel
from starnav.catalog import load_catalog
from starnav.simulate import simulate_frame

SIZE_PX = 1024
KB_COEFFICIENTS = {"k1": 0.02, "k2": -0.003, "k3": 0.0005, "k4": -0.00005}
ROWS = [
    ("pinhole", 60.0),
    ("pinhole", 90.0),
    ("pinhole", 120.0),
    *[(m, f) for m in ("equidistant",) for f in (60.0, 90.0, 120.0, 150.0, 180.0, 185.0)],
    *[(m, f) for m in ("equisolid", "stereographic") for f in (90.0, 120.0, 150.0, 185.0)],
    *[("orthographic", f) for f in (90.0, 120.0, 150.0, 180.0)],
    *[("kannala-brandt", f) for f in (90.0, 120.0, 150.0, 185.0)],
]
SCENARIO = {"noise_px": 0.5, "false_stars": 5, "missing_frac": 0.1}


def camera_of(model: str, fov_deg: float) -> CameraModel:
    """The row's camera: ``model`` with a horizontal ``fov_deg`` over 1024 px; from 150° on a
    circular fisheye whose image circle is the field."""
    cls = MODELS[model]
    coefficients = KB_COEFFICIENTS if model == "kannala-brandt" else {}
    camera = cls.from_fov(fov_deg, SIZE_PX, SIZE_PX, **coefficients)
    return camera.with_circle(fov_deg) if fov_deg >= 150.0 else camera


def run_row(model: str, fov_deg: float, frames: int, seed: int, catalog) -> dict:
    camera = camera_of(model, fov_deg)
    t0 = time.perf_counter()
    database = get_database(catalog, camera)
    build_s = time.perf_counter() - t0
    rng = np.random.default_rng(seed)
    counts = {"correct": 0, "wrong": 0, "none": 0}
    errors, times, n_stars = [], [], []
    ids_off = ids_total = 0
    label = f"{model} {fov_deg:g}°"
    for _ in tqdm(range(frames), desc=label, file=sys.stderr):
        frame = simulate_frame(catalog, camera, seed=rng, **SCENARIO)
        n_stars.append(len(frame.xy))
        result = solve_stars(
            frame.xy, camera=camera, brightness=frame.brightness, catalog=catalog, sigma_px=0.5
        )
        times.append(result.time_ms)
        diff = frame.compare(result.solution)
        if diff is None:
            counts["none"] += 1
            continue
        errors.append(diff["boresight_error_arcsec"])
        good = score_solution(result.solution, frame.R_cam_from_icrs).correct
        counts["correct" if good else "wrong"] += 1
        if good:
            ids_off += diff["ids_wrong"]
            ids_total += diff["ids_wrong"] + diff["ids_correct"]
    e = np.array(errors) if errors else np.array([np.nan])
    return {
        "model": model,
        "fov_deg": fov_deg,
        "frames": frames,
        **counts,
        "median_err_arcsec": float(np.median(e)),
        "max_err_arcsec": float(np.max(e)),
        "median_ms": float(np.median(times)),
        "p95_ms": float(np.percentile(times, 95)),
        "stars": float(np.median(n_stars)),
        "ids_off": ids_off,
        "ids_total": ids_total,
        "db_mb": database.nbytes / 1e6,
        "pairs": len(database.pair_a),
        "pair_stars": database.pair_stars,
        "build_s": build_s,
    }


def table(rows: list[dict], frames: int, seed: int, wall_s: float) -> str:
    lines = [
        f"{frames} frames per row, uniform on the sky, seed {seed}; {SIZE_PX} x {SIZE_PX} px, "
        f"Hipparcos Hp <= 6, 0.5 px noise, 5 false stars, 10 % dropped. Machine: {machine()}; "
        f"one process. Scores: {CORRECT_RULE}.",
        "",
        *table_head(
            "lens",
            "FOV",
            "stars (median)",
            "correct %",
            "wrong",
            "none",
            "boresight error median / max",
            "ids off",
            "median ms",
            "p95 ms",
            "database (pairs among the brightest)",
            "build",
        ),
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['fov_deg']:g}° | {r['stars']:.0f} | "
            f"{100 * r['correct'] / r['frames']:.1f} | {r['wrong']} | {r['none']} | "
            f"{r['median_err_arcsec']:.1f}″ / {r['max_err_arcsec']:.1f}″ | "
            f"{r['ids_off']} of {r['ids_total']} | {r['median_ms']:.0f} | {r['p95_ms']:.0f} | "
            f"{r['db_mb']:.1f} MB "
            f"({r['pairs']:,} pairs, {r['pair_stars']} stars) | {r['build_s']:.2f} s |"
        )
    lines += [
        "",
        f"Command: `python benchmarks/accuracy/wide_field.py --frames {frames}`, "
        f"{wall_s:.0f} s in all.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--rows", help="only rows whose 'model fov' contains this text")
    parser.add_argument("--out", help="write the table into this markdown file's block")
    args = parser.parse_args()
    catalog = load_catalog(None, mag_limit=6.0)
    run_row("pinhole", 60.0, 1, args.seed + 1, catalog)  # loads the machine code: not timed
    t0 = time.time()
    rows = [
        run_row(model, fov, args.frames, args.seed, catalog)
        for model, fov in ROWS
        if args.rows is None or args.rows in f"{model} {fov:g}"
    ]
    text = table(rows, args.frames, args.seed, time.time() - t0)
    print(text)
    if args.out:
        replace_block(args.out, "wide-field-lists", text)


if __name__ == "__main__":
    main()
