"""Build the FOV-search tables from scratch and report each band: catalog depth, stars,
bytes held in memory (catalog and KD-tree; pattern table), build time. Writes the
``fov-tables`` block of docs/images.md.

    python benchmarks/fov_tables.py
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from docblock import replace_block
from lost_in_space import machine

DOC = Path(__file__).resolve().parents[1] / "docs" / "images.md"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fov-range", nargs=2, type=float, default=(5.0, 40.0))
    parser.add_argument("--width", type=int, default=1024)
    parser.add_argument("--height", type=int, default=1024)
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    parser.add_argument("--block", default="fov-tables", help="the block of --out to write")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["STARNAV_CACHE_DIR"] = cache  # a cold cache: every table is built
        from starnav.fov import (
            band_grid,
            diagonal_fov_deg,
            horizontal_fov_deg,
            load_band,
            search_catalog,
        )
        from starnav.identify.pattern4 import catalog_nbytes

        w, h = args.width, args.height
        lo, hi = (diagonal_fov_deg(v, w, h) for v in args.fov_range)
        rows, total_s, total_mb = [], 0.0, 0.0
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
            rows.append(
                f"| {a:.2f}-{b:.2f} | {top:.2f} | {band.catalog.mag.max():.2f} | "
                f"{len(band.catalog)} | {catalog_nbytes(band.database) / 1e6:.1f} | "
                f"{len(band.table)} | {band.table.nbytes / 1e6:.1f} | {seconds:.1f} |"
            )
    text = "\n".join(
        [
            f"FOV range {args.fov_range[0]:g}-{args.fov_range[1]:g}° across {w} x {h} px "
            f"(diagonal {lo:.2f}-{hi:.2f}°); {machine()}; "
            f"`python benchmarks/fov_tables.py`.",
            "",
            "| diagonal FOV searched (°) | table built for (°) | faintest Hp | stars | "
            "catalog + KD-tree MB | patterns | pattern table MB | build s |",
            "|---|---|---|---|---|---|---|---|",
            *rows,
            f"| all | | | | | | {total_mb:.0f} MB in all | {total_s:.0f} |",
        ]
    )
    text += "\n\n" + nothing_to_find(args.width, args.height, tuple(args.fov_range))
    print(text)
    if args.out != "-":
        replace_block(args.out, args.block, text)


def nothing_to_find(width: int, height: int, fov_range: tuple[float, float]) -> str:
    """What a field with no catalog pattern costs: random points, searched to the end."""
    import numpy as np

    from starnav.fov import solve_fov

    rng = np.random.default_rng(0)
    # one solve first, not counted: it loads the kernels' machine code (numba, on first use)
    solve_fov(
        rng.uniform([0, 0], [width, height], (10, 2)),
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
            res = solve_fov(xy, width=width, height=height, fov_range_deg=fov_range)
            ms.append(res.time_ms)
            wrong += res.solution is not None
        lines.append(
            f"{n} random points: median {np.median(ms):.0f} ms, max {np.max(ms):.0f} ms, "
            f"{wrong} of 10 answered"
        )
    return "A field with nothing to find (10 trials each): " + "; ".join(lines) + "."


if __name__ == "__main__":
    main()
