"""Where an image solve's time goes, frame by frame as ``benchmarks/peers/images.py`` times it.

    taskset -c 1 python benchmarks/speed/image_split.py [--frames 60] [--write]

Frames: ``--frames`` renders of the ``seed-1024`` preset (1024 px, 20°, Hipparcos Hp <= 7)
written as 16-bit PNG files, made as ``benchmarks/peers/images.py`` makes them (its
``render_files``, seed 2026). Each file is read afresh (``read_image``, not timed), then solved
with the FOV given (``solve_image(array, fov_deg=20)``), as that benchmark's worker does; the
stages are timed by wrapping them (a microsecond each): detection (``detect_stars``) and in it
the fast path's kernels (tile statistics, background subtraction, sources), the PSF (half-light
radii), the centroids and photometry of the likely stars, and the rest (numpy and Python
around them); the solve (``solve_stars``). The minor page faults of each solve are counted
(``getrusage``): memory the kernel hands a process afresh is zeroed page by page, which a
frame's 4 MB arrays pay when the heap gives them back between frames. Prints the median per
frame; ``--write`` puts the table in docs/images.md (block ``image-split``). Numba and the
thread pools are held to one thread; pin the process to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os

os.environ.update(
    dict.fromkeys(
        ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"), "1"
    )
)

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from benchmarks.peers.images import FOV_GIVEN_DEG, MAG_LIMIT, render_files
from benchmarks.speed.solve_split import timed
from starnav.catalog import load_catalog
from starnav.detect import kernels, stars, tracker
from starnav.detect.read import read_image
from starnav.pipeline import image

STAGES = (  # (label, module, attribute): wrapped where the callers look them up
    ("detection (`detect_stars`)", image, "detect_stars"),
    ("- tile statistics (kernel)", kernels, "tile_statistics"),
    ("- background subtracted, hot-pixel candidates (kernel)", kernels, "background_subtracted"),
    ("- sources: filter, threshold, deblending (kernel)", kernels, "find_sources"),
    ("- PSF: half-light radii (kernel) and their mode", tracker, "psf_sigma_from"),
    ("- centroids and photometry of the likely stars", stars, "_tracker_detections"),
    ("identification and fit (`solve_stars`)", image, "solve_stars"),
)


def minor_faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--write", action="store_true", help="write the docs/images.md block")
    args = parser.parse_args()
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    with tempfile.TemporaryDirectory(prefix="starnav-split-") as tmp:
        paths = [t.path for t in render_files(catalog, args.frames, args.seed, Path(tmp))]
        starnav.solve_image(read_image(paths[0]), fov_deg=FOV_GIVEN_DEG)  # load; not counted
        times: dict[str, list[float]] = {}
        for label, module, name in STAGES:
            setattr(module, name, timed(times, label, getattr(module, name)))
        total, faults = [], []
        for path in paths:
            pixels = read_image(path)
            f0, t0 = minor_faults(), time.perf_counter()
            starnav.solve_image(pixels, fov_deg=FOV_GIVEN_DEG)
            total.append(time.perf_counter() - t0)
            faults.append(minor_faults() - f0)
    per_frame = {label: np.array(times[label]) * 1e3 for label, _, _ in STAGES}
    detection = per_frame[STAGES[0][0]]
    rest = detection - sum(per_frame[label] for label, _, _ in STAGES[1:6])
    lines = table_head("stage", "median ms a frame")
    lines.append(table_row("array to attitude (`solve_image`)", f"{np.median(total) * 1e3:.2f}"))
    for label, _, _ in STAGES:
        lines.append(table_row(label, f"{np.median(per_frame[label]):.2f}"))
        if label.startswith("- centroids"):
            lines.append(
                table_row("- the rest: numpy and Python around them", f"{np.median(rest):.2f}")
            )
    lines.append(table_row("minor page faults a solve", f"{np.median(faults):.0f}"))
    text = "\n".join(
        [
            *lines,
            "",
            f"{args.frames} files of the `seed-1024` preset (seed {args.seed}), each read afresh "
            f"and solved with the FOV given ({FOV_GIVEN_DEG:g}°), as `benchmarks/peers/images.py`"
            "'s worker does; medians over the frames. One core (`taskset -c 1`), numba and "
            f"thread pools of 1; {machine(load_at_end=True)}; "
            "`python benchmarks/speed/image_split.py`.",
        ]
    )
    print(text)
    if args.write:
        replace_block(DOCS / "images.md", "image-split", text)


if __name__ == "__main__":
    main()
