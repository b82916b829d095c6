"""Throughput of solve_stars_batch (many frames, all cores) against one process.

    python benchmarks/speed/batch.py --frames 2000

Frames: 12° / 512 px, Hp <= 6, 0.5 px noise, 2 false stars, 10 % missing, uniform on the sky.
Writes the ``batch`` block of docs/performance.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row, warm_up
from starnav.api import solve_stars_batch
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.simulate import simulate_frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    catalog = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(12.0, 512)
    rng = np.random.default_rng(args.seed)
    frames = []
    while len(frames) < args.frames:
        f = simulate_frame(catalog, camera, noise_px=0.5, false_stars=2, missing_frac=0.1, seed=rng)
        if len(f.xy) >= 3:
            frames.append(f)
    load_s = warm_up(catalog, camera)  # what a process's first solve costs, not counted
    rows = []
    for workers in sorted({1, os.cpu_count() or 1}):
        t0 = time.perf_counter()
        results = solve_stars_batch(
            [f.xy for f in frames],
            brightness=[f.brightness for f in frames],
            workers=workers,
            width=512,
            fov_deg=12.0,
            catalog=catalog,
            sigma_px=0.5,
        )
        wall = time.perf_counter() - t0
        solved = sum(r.solution is not None for r in results)
        rows.append(
            table_row(workers, len(frames), solved, f"{wall:.1f}", f"{len(frames) / wall:.0f}")
        )
    text = "\n".join(
        [
            f"{args.frames} frames (12° / 512 px, Hp <= 6, 0.5 px noise, 2 false stars, 10 % "
            f"missing), `starnav.solve_stars_batch`; {machine()}.",
            "",
            *table_head("processes", "frames", "solved", "wall s", "frames / s"),
            *rows,
            "",
            f"The machine code was loaded before timing ({load_s:.1f} s); forked workers "
            f"share it. `python benchmarks/speed/batch.py --frames {args.frames}`",
        ]
    )
    replace_block(DOCS / "performance.md", "batch", text)
    print(text)


if __name__ == "__main__":
    main()
