"""A 6° star tracker's frames solved at default options: Kelvins-format scenes (ESA's "Star
Trackers: First Contact": 1392 x 1040 px, stars to magnitude 10.3, false stars, magnitude
noise), scored per scene with the contest's metric. The table goes into the
``tracker-defaults`` block of docs/deep_stars.md (only with the defaults; ``--no-doc``
prints it only).

    python benchmarks/accuracy/tracker_defaults.py [--scenes 300] [--seed 35] [--no-doc]

Scenes (``deep_stars.scenes``): a 1392 x 1040 px pinhole camera of 6.1° horizontal FOV; the
stars of the embedded Hipparcos catalog to Hp 10.3, 0.3 px centroid noise, 0.3 mag
brightness noise, 3 false stars, 10 % of the stars missing; a fifth of the scenes centred
near a catalog pair 1-2 px apart, a fifth near one under 1 px apart; stars closer than 1 px
merged into one point with the brighter's id.

Solved with ``starnav.solve_stars`` given only the field (``fov_deg=6.1`` and the image
size): the catalog depths are the field's defaults (``pipeline.fov.known_field_depth``).
The "before" row tells the solver the defaults it had before they followed the field
(identification on Hipparcos to Hp 6, no deep stage). A second table prices the deeper
catalog: 300 frames of a 10° camera that sees only 4-6 stars of Hp <= 6, at the field's
default depth and told Hp 6.

Score per scene: max((c - 2w) / max(t, 1), -1), c the points given their true id, w the
points given another id (every one: the contest forgives nothing; the "forgiven" column
counts those confused with a catalog neighbour closer than max(1 px, 3 sigma), which
docs/deep_stars.md does not count as wrong), t the true stars among the points. The mean
over the scenes, times 100.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.accuracy.deep_stars import scenes, score, swapped_pairs
from benchmarks.harness import DOCS, machine, replace_block, table_head
from starnav import SolveOptions, solve_stars
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_difference_deg
from starnav.pipeline.fov import known_field_depth
from starnav.simulate import FALSE_STAR_ID, simulate_frame

FOV_DEG, WIDTH, HEIGHT = 6.1, 1392, 1040
NOISE_PX, MAG_NOISE, FALSE_STARS, MISSING = 0.3, 0.3, 3, 0.1
DEFAULTS = {"scenes": 300, "seed": 35}


def run(frames, camera, truth, options: SolveOptions, brightness: bool) -> np.ndarray:
    """Per scene: (strict score, c, w strict, forgiven, t, solved, ms, swaps, P-wrong)."""
    rows = []
    for _kind, frame, _merged in frames:
        t0 = time.perf_counter()
        result = solve_stars(
            frame.xy,
            options,
            width=WIDTH,
            height=HEIGHT,
            brightness=frame.brightness if brightness else None,
        )
        ms = (time.perf_counter() - t0) * 1000.0
        s = result.solution
        ids = np.full(len(frame.xy), -1) if s is None else s.star_table.catalog_id
        c, w, forgiven, t = score(ids, frame, truth, camera, NOISE_PX)
        strict = int(np.sum((ids != -1) & (ids != frame.true_id)))
        false_named = int(np.sum((ids != -1) & (frame.true_id == FALSE_STAR_ID)))
        rows.append(
            (
                max((c - 2 * strict) / max(t, 1), -1.0),
                c,
                strict,
                forgiven,
                t,
                s is not None,
                ms,
                swapped_pairs(ids, frame.true_id),
                false_named,
                w,
            )
        )
    return np.array(rows, dtype=float)


def few_star_table(seed: int, n: int = 300) -> list[str]:
    """The price of the deeper catalog: ``n`` frames of a 10° / 1024 px camera that sees only
    4-6 stars of Hp <= 6 (0.5 px noise, sigma not told), solved at the field's default depth
    and told Hp 6."""
    camera = Camera.from_fov(10.0, 1024, 1024)
    bright = load_catalog(None, mag_limit=6.0)
    rng = np.random.default_rng(seed)
    frames = []
    while len(frames) < n:
        frame = simulate_frame(bright, camera, noise_px=0.5, seed=rng)
        if 4 <= len(frame.xy) <= 6:
            frames.append(frame)
    mag, _ = known_field_depth(camera, SolveOptions(fov_deg=10.0))
    lines = table_head("10° / 1024 px, 4-6 stars of Hp <= 6", "frames", "right", "wrong", "none")
    for name, mag_limit in ((f"default (Hp {mag:g})", None), ("told --mag-limit 6", 6.0)):
        counts = {"right": 0, "wrong": 0, "none": 0}
        for frame in frames:
            s = solve_stars(frame.xy, width=1024, fov_deg=10.0, mag_limit=mag_limit).solution
            if s is None:
                counts["none"] += 1
                continue
            boresight, roll = attitude_difference_deg(s.R_cam_from_icrs, frame.R_cam_from_icrs)
            right = boresight < 0.05 and roll < 0.5 and s.parity == 1
            counts["right" if right else "wrong"] += 1
        lines.append(f"| {name} | {n} | {counts['right']} | {counts['wrong']} | {counts['none']} |")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=DEFAULTS["scenes"])
    ap.add_argument("--seed", type=int, default=DEFAULTS["seed"])
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    camera = Camera.from_fov(FOV_DEG, WIDTH, HEIGHT)
    truth = load_catalog(None, mag_limit=12.0)
    frames = scenes(
        args.scenes,
        args.seed,
        truth,
        camera,
        noise_px=NOISE_PX,
        false_stars=FALSE_STARS,
        missing_frac=MISSING,
        mag_noise=MAG_NOISE,
    )
    defaults = SolveOptions(fov_deg=FOV_DEG)
    mag, deep = known_field_depth(camera, defaults)
    configs = {
        f"defaults (Hp {mag:g} + deep Hp {deep:g})": (defaults, True),
        "defaults, positions only": (defaults, False),
        "before: Hp 6, no deep stage": (SolveOptions(fov_deg=FOV_DEG, deep_mag_limit="off",
                                                     mag_limit=6.0), True),
    }  # fmt: skip
    lines = table_head(
        "solver",
        "scenes",
        "solved",
        "Kelvins score (x100)",
        "worst scene",
        "right ids",
        "wrong ids (forgiven doubles)",
        "false stars named",
        "swapped pairs",
        "ms per scene (median / p95)",
    )
    for name, (options, brightness) in configs.items():
        solve_stars(frames[0][1].xy, options, width=WIDTH, height=HEIGHT)  # loads it all
        t0 = time.perf_counter()
        e = run(frames, camera, truth, options, brightness)
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        strict, c, w, forgiven, t, solved, ms, swaps, false_named, _ = e.T
        lines.append(
            f"| {name} | {len(e)} | {int(solved.sum())} | {100 * strict.mean():.2f} | "
            f"{100 * strict.min():.1f} | {c.sum() / t.sum():.2%} ({int(c.sum())}/{int(t.sum())}) "
            f"| {int(w.sum())} ({int(forgiven.sum())}) | {int(false_named.sum())} | "
            f"{int(swaps.sum())} | {np.median(ms):.1f} / {np.percentile(ms, 95):.1f} |"
        )
    lines += ["", *few_star_table(args.seed)]
    command = "python benchmarks/accuracy/tracker_defaults.py"
    table = "\n".join(lines) + f"\n\n{machine()}; `{command}`."
    print(table)
    if not args.no_doc and (args.scenes, args.seed) == tuple(DEFAULTS.values()):
        replace_block(DOCS / "deep_stars.md", "tracker-defaults", table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
