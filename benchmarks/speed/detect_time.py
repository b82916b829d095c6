"""Detection time on rendered frames, for docs/images.md ("How stars are found in real skies").

    python benchmarks/speed/detect_time.py

12 ``seed-1024`` frames (1024 px, 20°, Hipparcos Hp <= 7) at random attitudes (seed 3),
``starnav.pipeline.image.detect_image`` on each three times; prints the median and the minimum (ms).
Run it pinned to one core (``taskset -c 1``) on each checkout to compare.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine
from starnav.catalog import load_catalog
from starnav.geometry import attitude_from_radec_roll
from starnav.pipeline.image import detect_image
from starnav.simulate.render import PRESETS, render_frame


def main() -> None:
    catalog = load_catalog(None, mag_limit=7.0)
    camera, settings = PRESETS["seed-1024"]
    rng = np.random.default_rng(3)
    frames = []
    for i in range(12):
        dec = np.degrees(np.arcsin(rng.uniform(-1, 1)))
        R = attitude_from_radec_roll(rng.uniform(0, 360), dec, rng.uniform(0, 360))
        frames.append(render_frame(catalog, camera, R, dataclasses.replace(settings, seed=i)).image)
    times = []
    for _ in range(3):
        for image in frames:
            t0 = time.perf_counter()
            detect_image(image)
            times.append((time.perf_counter() - t0) * 1e3)
    print(
        f"detect_image on 1024 px frames: median {np.median(times):.1f} ms, "
        f"min {np.min(times):.1f} ms ({len(times)} runs); {machine()}"
    )


if __name__ == "__main__":
    main()
