"""Detection time per megapixel on one core, for docs/images.md ("Detection time").

    taskset -c 1 python benchmarks/speed/detect_time.py [--repeats 5] [--write]

Frames: 12 rendered ``seed-1024`` frames (1024 px, 20°, Hipparcos Hp <= 7, random attitudes,
seed 3), 6 rendered at 2048 px (the same 20° field and render settings), and the real
star-tracker frames of ``../shared/data/real`` (tetra3's eight 1024 x 768 TIFFs, the
openstartracker frame). Each frame is detected ``--repeats`` times with
``starnav.detect.detect_stars`` (``max_stars`` 50, as ``solve_image`` asks) as it chooses
("auto": the fast path on a clean frame, ``starnav.detect.tracker``) and with the fast path
declined ("real-sky": the detection before the fast path, unchanged). Prints, per kind of
frame, the path taken, and the median over frames of each frame's fastest time in ms and in
ms per megapixel; ``--write`` puts the table in docs/images.md. Numba and the thread pools
are held to one thread; pin the process to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os

os.environ.update(
    dict.fromkeys(
        ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"), "1"
    )
)

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, SHARED, machine, replace_block, table_head, table_row
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.detect import stars
from starnav.detect.read import read_image
from starnav.detect.stars import detect_stars
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate.render import PRESETS, render_frame

MAX_STARS = 50


def rendered(catalog, size: int, count: int) -> list[np.ndarray]:
    """``count`` frames of the seed-1024 preset's 20° field at ``size`` px a side."""
    camera, settings = PRESETS["seed-1024"]
    if size != camera.width:
        camera = Camera.from_fov(20.0, size, size)
    rng = np.random.default_rng(3)
    frames = []
    for i in range(count):
        dec = np.degrees(np.arcsin(rng.uniform(-1, 1)))
        R = attitude_from_radec_roll(rng.uniform(0, 360), dec, rng.uniform(0, 360))
        frames.append(render_frame(catalog, camera, R, dataclasses.replace(settings, seed=i)).image)
    return frames


def real(pattern: str) -> list[np.ndarray]:
    return [np.asarray(read_image(p)) for p in sorted((SHARED / "real").glob(pattern))]


def fastest_ms(image: np.ndarray, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        detect_stars(image, max_stars=MAX_STARS)
        times.append((time.perf_counter() - t0) * 1e3)
    return min(times)


def takes_fast_path(image: np.ndarray) -> bool:
    taken = []
    original = stars._tracker_detections

    def spy(*args, **kwargs):
        taken.append(True)
        return original(*args, **kwargs)

    stars._tracker_detections = spy
    try:
        detect_stars(image, max_stars=MAX_STARS)
    finally:
        stars._tracker_detections = original
    return bool(taken)


def real_sky_ms(image: np.ndarray, repeats: int) -> float:
    """``fastest_ms`` with the fast path declined."""
    original = stars.tracker_sources
    stars.tracker_sources = lambda *args, **kwargs: None
    try:
        return fastest_ms(image, repeats)
    finally:
        stars.tracker_sources = original


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--write", action="store_true", help="write the docs/images.md block")
    args = parser.parse_args()
    catalog = load_catalog(None, mag_limit=7.0)
    kinds = [
        ("rendered 1024 x 1024 (12)", rendered(catalog, 1024, 12)),
        ("rendered 2048 x 2048 (6)", rendered(catalog, 2048, 6)),
        ("tetra3 real, 1024 x 768 (8)", real("tetra3_*.tiff")),
        ("openstartracker real, 1392 x 1040 (1)", real("openstartracker_*.png")),
    ]
    detect_stars(kinds[0][1][0])  # compile or load the kernels
    lines = table_head(
        "frames", "fast path taken", "real-sky ms", "auto ms", "real-sky ms/MP", "auto ms/MP"
    )
    for name, frames in kinds:
        mp = np.array([f.size / 1e6 for f in frames])
        slow = np.array([real_sky_ms(f, args.repeats) for f in frames])
        auto = np.array([fastest_ms(f, args.repeats) for f in frames])
        fast = sum(takes_fast_path(f) for f in frames)
        lines.append(
            table_row(
                name,
                f"{fast} of {len(frames)}",
                f"{np.median(slow):.1f}",
                f"{np.median(auto):.1f}",
                f"{np.median(slow / mp):.1f}",
                f"{np.median(auto / mp):.1f}",
            )
        )
    text = "\n".join(
        [
            *lines,
            "",
            f"`detect_stars(image, max_stars={MAX_STARS})`, each frame's fastest of "
            f"{args.repeats} runs, the median over the frames; real-sky: the fast path declined. "
            "One core (`taskset -c 1`), numba and thread pools of 1; "
            f"{machine(load_at_end=True)}; `python benchmarks/speed/detect_time.py`.",
        ]
    )
    print(text)
    if args.write:
        replace_block(DOCS / "images.md", "detect-time", text)


if __name__ == "__main__":
    main()
