"""Which real photographs take detection's fast path, and whether each solves the same on both
paths, for docs/images.md ("Detection time: the fast path for star-tracker frames").

    STARNAV_REAL_CORPUS=DIR python benchmarks/images/detect_paths.py [--write]

Every image file in ``$STARNAV_REAL_CORPUS`` (else ``../shared/data/real``) is read and
binned as ``solve_image`` bins it (``detection_binning``); ``detect_stars`` is called on it as
``detect_image`` calls it and the path it takes recorded (fast: ``starnav.detect.tracker``
found the frame clean). Each image that takes the fast path is then solved with
``solve_image`` (FOV unknown, 60 s budget) twice: as it is, and with the fast path declined
(the real-sky detection, unchanged). Prints the fast-path images, each with both outcomes and
the attitude difference (boresight, roll about it); ``--write`` puts the table in
docs/images.md.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, SHARED, machine, replace_block, table_head, table_row
from starnav.api import solve_image
from starnav.detect import stars
from starnav.detect.read import read_image
from starnav.geometry import attitude_difference_deg
from starnav.pipeline.image import detection_binning
from starnav.pipeline.options import DEFAULT_MAX_STARS

SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".fit", ".fits")


def takes_fast_path(path: Path) -> bool | None:
    """Whether detection takes the fast path on the image (None: not a 2-D image we read)."""
    try:
        image = np.asarray(read_image(path))
    except Exception:  # any file that is not an image we read
        return None
    if image.ndim != 2:
        return None
    height, width = image.shape
    k = detection_binning(width, height)
    if k > 1:
        h, w = height // k, width // k
        blocks = np.asarray(image[: h * k, : w * k], dtype=np.float32)
        image = blocks.reshape(h, k, w, k).mean(axis=(1, 3))
    taken = []
    original = stars._tracker_detections

    def spy(*args, **kwargs):
        taken.append(True)
        return original(*args, **kwargs)

    stars._tracker_detections = spy
    try:
        stars.detect_stars(image, max_stars=DEFAULT_MAX_STARS)
    finally:
        stars._tracker_detections = original
    return bool(taken)


def solved(path: Path, fast: bool):
    """``solve_image``'s solution (None: not solved), the fast path allowed or declined."""
    original = stars.tracker_sources
    if not fast:
        stars.tracker_sources = lambda *args, **kwargs: None
    try:
        return solve_image(path, time_budget_s=60.0).solution
    finally:
        stars.tracker_sources = original


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="write the docs/images.md block")
    args = parser.parse_args()
    folder = Path(os.environ.get("STARNAV_REAL_CORPUS") or SHARED / "real")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SUFFIXES)
    paths = {p: takes_fast_path(p) for p in files}
    fast = [p for p, taken in paths.items() if taken]
    lines = table_head(
        "image", "fast path", "real-sky path", "apart: boresight, roll ″", "stars fast / real-sky"
    )
    same = 0
    for path in fast:
        a, b = solved(path, True), solved(path, False)
        apart = "-"
        if a is not None and b is not None:
            d = attitude_difference_deg(
                np.asarray(a.R_cam_from_icrs), np.asarray(b.R_cam_from_icrs)
            )
            apart = f"{d[0] * 3600:.2f}, {d[1] * 3600:.2f}"
        same += (a is None) == (b is None)
        n = [sum(m.catalog_id is not None for m in s.stars) if s else 0 for s in (a, b)]
        outcome = ["solved" if s is not None else "not solved" for s in (a, b)]
        lines.append(table_row(path.name, *outcome, apart, f"{n[0]} / {n[1]}"))
    read = sum(taken is not None for taken in paths.values())
    text = "\n".join(
        [
            f"{len(fast)} of {read} images read take the fast path ({folder.name}); "
            f"{same} of {len(fast)} solve (or fail) the same on both paths.",
            "",
            *lines,
            "",
            f"`solve_image(path, time_budget_s=60)`, FOV unknown; stars: identified. "
            f"{machine()}; `python benchmarks/images/detect_paths.py`.",
        ]
    )
    print(text)
    if args.write:
        replace_block(DOCS / "images.md", "detect-paths", text)


if __name__ == "__main__":
    main()
