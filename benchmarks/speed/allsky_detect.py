"""All-sky detection before and after the sky mask, on real frames, for docs/allsky.md.

    nice python benchmarks/speed/allsky_detect.py [FILE ...] [--repeats 3] [--out PATH]

Frames: the files given, else the KHO Sony frame of ``../shared/data/allsky`` and every file
in the folder ``$STARNAV_ALLSKY_FRAMES`` names (real all-sky frames that may not be committed:
see docs/allsky.md for where they come from). Each frame is read, binned as
``solve_image`` bins it (``pipeline.image.detection_binning``) and detected as a fisheye with
the default threshold and star count, two ways:

* circle only (the detection before the sky mask, unchanged): the pixels outside the image
  circle (``find_image_circle``, shrunk by 1 % of its radius) masked, then ``detect_stars``;
* sky mask (``pipeline.image.detect_image`` with ``lens="equidistant"``): the sky mask
  (``detect.skymask``: the circle, the horizon's obstacles, glare), then ``detect_stars``, and
  deeper when fewer than 15 stars are found.

Times are each frame's fastest of ``--repeats`` (ms, the binned frame's detection; reading
and binning not counted). The table gives the stars found each way, how many of the circle-only
detections lie where the sky mask masks (the junk it removes, or stars it loses: look at the
frame), the mask's shares and the threshold used. ``--out``: the markdown table and the
machine line written into that file's ``allsky-detect`` block ('-': printed only).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, SHARED, machine, replace_block, table_head, table_row
from starnav.detect.circle import find_image_circle
from starnav.detect.read import read_image
from starnav.detect.skymask import find_sky_mask
from starnav.detect.stars import detect_stars
from starnav.pipeline.image import detect_image, detection_binning
from starnav.pipeline.options import DEFAULT_THRESHOLD_SIGMA, FISHEYE_MAX_STARS

DOC = DOCS / "allsky.md"


def frames(args: list[str]) -> list[Path]:
    """The files to detect: those given, else the shared KHO frame and $STARNAV_ALLSKY_FRAMES's."""
    if args:
        return [Path(a) for a in args]
    out = sorted((SHARED / "allsky").glob("*.jpg"))
    folder = os.environ.get("STARNAV_ALLSKY_FRAMES")
    if folder:
        out += sorted(p for p in Path(folder).iterdir() if p.is_file())
    return out


def binned(pixels: np.ndarray) -> np.ndarray:
    """The frame binned as ``solve_image`` bins it (block means, the partial edge dropped)."""
    k = detection_binning(pixels.shape[1], pixels.shape[0])
    if k == 1:
        return pixels
    h, w = pixels.shape[0] // k, pixels.shape[1] // k
    return pixels[: h * k, : w * k].reshape(h, k, w, k).mean(axis=(1, 3), dtype=np.float32)


def circle_only(pixels: np.ndarray):
    """The detection before the sky mask: outside the image circle masked."""
    circle = find_image_circle(pixels)
    if circle is not None:
        pixels = np.array(pixels, dtype=np.float32)
        h, w = pixels.shape
        pixels[circle.outside(w, h, margin_px=0.01 * circle.radius_px)] = np.nan
    return detect_stars(
        pixels, threshold_sigma=DEFAULT_THRESHOLD_SIGMA, max_stars=FISHEYE_MAX_STARS
    )


def fastest(fn, repeats: int):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, (time.perf_counter() - t0) * 1e3)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    paths = frames(args.files)
    if not paths:
        raise SystemExit("no frames: give files or set STARNAV_ALLSKY_FRAMES")
    t_start = time.perf_counter()
    lines = table_head(
        "frame", "px", "binned", "circle only: stars, ms", "sky mask: stars, ms",
        "circle-only detections in the mask (of the top 100)", "sky %", "masked", "threshold σ",
    )  # fmt: skip
    slower = []
    for path in paths:
        pixels = binned(read_image(path))
        ms_before, before = fastest(lambda p=pixels: circle_only(p), args.repeats)
        ms_after, after = fastest(
            lambda p=pixels: detect_image(p, lens="equidistant"), args.repeats
        )
        mask = find_sky_mask(pixels)
        ij = np.clip(before.xy.astype(int), 0, [pixels.shape[1] - 1, pixels.shape[0] - 1])
        in_mask = int(mask.excluded[ij[:, 1], ij[:, 0]].sum())
        slower.append(ms_after - ms_before)
        full = read_image(path).shape
        row = table_row(
            path.name, f"{full[1]} x {full[0]}", f"{pixels.shape[1]} x {pixels.shape[0]}",
            f"{len(before)}, {ms_before:.0f}", f"{len(after)}, {ms_after:.0f}", in_mask,
            f"{100 * mask.sky:.0f}", mask.words(), f"{after.threshold_sigma:g}",
        )  # fmt: skip
        print(row, flush=True)
        lines.append(row)
    lines += [
        "",
        f"Median change in detection time: {np.median(slower):+.0f} ms per frame "
        f"(max {max(slower):+.0f} ms).",
        "",
        f"{machine(load_at_end=True)}; `python benchmarks/speed/allsky_detect.py`, "
        f"{time.perf_counter() - t_start:.0f} s.",
    ]
    text = "\n".join(lines)
    print(text)
    if args.out != "-":
        replace_block(args.out, "allsky-detect", text, missing="## Detection on real frames")


if __name__ == "__main__":
    main()
