"""Build the FOV-search tables from scratch and report each band: catalog depth, stars,
pattern stars per lattice field, bytes held in memory (catalog and KD-tree; pattern table)
and on disk (the cached table file), build time, and the process's peak memory. Writes the
``fov-tables`` block of docs/images.md (``--block`` another, e.g. the narrow bands'):

    python benchmarks/images/fov_tables.py
    python benchmarks/images/fov_tables.py --fov-range 3 40 --block fov-tables-3-40
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, table_head

DOC = DOCS / "images.md"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fov-range", nargs=2, type=float, default=(5.0, 40.0))
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=1024)
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    parser.add_argument("--block", default="fov-tables", help="the block of --out to write")
    parser.add_argument(
        "--compare-range",
        nargs=2,
        type=float,
        help="another range (within --fov-range) whose search costs are measured in the same run",
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["STARNAV_CACHE_DIR"] = cache  # a cold cache: every table is built
        from starnav.identify.pattern4 import catalog_nbytes
        from starnav.pipeline.fov import (
            band_grid,
            band_stars_per_field,
            diagonal_fov_deg,
            horizontal_fov_deg,
            load_band,
            search_catalog,
        )

        w, h = args.width, args.height
        lo, hi = (diagonal_fov_deg(v, w, h) for v in args.fov_range)
        rows, total_s, total_mb, disk_mb = [], 0.0, 0.0, 0.0
        for a, b, top in band_grid(lo, hi):
            t0 = time.perf_counter()
            band = load_band(
                top,
                horizontal_fov_deg(a, w, h),
                horizontal_fov_deg(b, w, h),
                search_catalog(None, None),
            )
            seconds = time.perf_counter() - t0
            total_s += seconds
            total_mb += band.nbytes / 1e6
            disk = band.table.path.stat().st_size / 1e6
            disk_mb += disk
            rows.append(
                f"| {a:.2f}-{b:.2f} | {top:.2f} | {band.catalog.mag.max():.2f} | "
                f"{len(band.catalog)} | {band_stars_per_field(top)} | "
                f"{catalog_nbytes(band.database) / 1e6:.1f} | {len(band.table)} | "
                f"{band.table.nbytes / 1e6:.1f} | {disk:.1f} | {seconds:.1f} |"
            )
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3  # KiB on Linux
    text = "\n".join(
        [
            f"FOV range {args.fov_range[0]:g}-{args.fov_range[1]:g}° across {w} x {h} px "
            f"(diagonal {lo:.2f}-{hi:.2f}°); {machine()}; "
            f"`python benchmarks/images/fov_tables.py{cli_args(args)}`.",
            "",
            *table_head(
                "diagonal FOV searched (°)",
                "table built for (°)",
                "faintest Hp",
                "stars",
                "pattern stars per field",
                "catalog + KD-tree MB",
                "patterns",
                "pattern table MB",
                "on disk MB",
                "build s",
            ),
            *rows,
            f"| all | | | | | | | {total_mb:.0f} MB in memory in all | {disk_mb:.0f} | "
            f"{total_s:.0f} |",
            "",
            f"Peak memory of the process that built them all: {peak_mb:.0f} MB.",
        ]
    )
    ranges = [tuple(args.fov_range)] + ([tuple(args.compare_range)] if args.compare_range else [])
    for k, fov_range in enumerate(ranges):
        what = (
            "This range"
            if k == 0
            else f"The same run, the range {fov_range[0]:g}-{fov_range[1]:g}°"
        )
        text += f"\n\n{what}: " + nothing_to_find(args.width, args.height, fov_range)
        text += " " + typical_field(args.width, args.height, fov_range)
    print(text)
    if args.out != "-":
        replace_block(args.out, args.block, text)


def cli_args(args: argparse.Namespace) -> str:
    """The options of this run that differ from the defaults, as typed."""
    out = ""
    if tuple(args.fov_range) != (5.0, 40.0):
        out += f" --fov-range {args.fov_range[0]:g} {args.fov_range[1]:g}"
    if (args.width, args.height) != (1024, 1024):
        out += f" --width {args.width} --height {args.height}"
    if args.compare_range:
        out += f" --compare-range {args.compare_range[0]:g} {args.compare_range[1]:g}"
    return out + (f" --block {args.block}" if args.block != "fov-tables" else "")


def typical_field(width: int, height: int, fov_range: tuple[float, float]) -> str:
    """What an ordinary field costs: 20 simulated 20° frames (Hipparcos to Hp 7, 0.2 px
    noise, 2 false stars) solved with the FOV unknown."""
    import numpy as np

    from starnav.api import solve_stars
    from starnav.camera import Camera
    from starnav.catalog import load_catalog
    from starnav.simulate import simulate_frame

    camera, sky = Camera.from_fov(20.0, width, height), load_catalog(None, mag_limit=7.0)
    ms, solved = [], 0
    for seed in range(20):
        frame = simulate_frame(sky, camera, noise_px=0.2, false_stars=2, seed=seed)
        res = solve_stars(
            frame.xy,
            fov_exact=False,
            width=width,
            height=height,
            brightness=frame.brightness,
            fov_range_deg=fov_range,
        )
        ms.append(res.time_ms)
        solved += res.solution is not None
    return (
        f"A 20° field (20 simulated frames, Hp <= 7): {solved} of 20 solved, median "
        f"{np.median(ms):.0f} ms, max {np.max(ms):.0f} ms."
    )


def nothing_to_find(width: int, height: int, fov_range: tuple[float, float]) -> str:
    """What a field with no catalog pattern costs: random points, searched to the end."""
    import numpy as np

    from starnav.api import solve_stars

    rng = np.random.default_rng(0)
    # one solve first, not counted: it loads the kernels' machine code (numba, on first use)
    solve_stars(
        fov_exact=False,
        xy=rng.uniform([0, 0], [width, height], (10, 2)),
        width=width,
        height=height,
        fov_range_deg=fov_range,
    )
    rng = np.random.default_rng(0)
    lines = []
    for n in (10, 30, 50):
        ms, wrong = [], 0
        for _ in range(10):
            xy = rng.uniform([0, 0], [width, height], (n, 2))
            res = solve_stars(
                xy, fov_exact=False, width=width, height=height, fov_range_deg=fov_range
            )
            ms.append(res.time_ms)
            wrong += res.solution is not None
        lines.append(
            f"{n} random points: median {np.median(ms):.0f} ms, max {np.max(ms):.0f} ms, "
            f"{wrong} of 10 answered"
        )
    return "a field with nothing to find (10 trials each): " + "; ".join(lines) + "."


if __name__ == "__main__":
    main()
