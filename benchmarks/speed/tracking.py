"""Tracking mode on a slewing sequence of frames, against lost in space on the same frames.

    python benchmarks/speed/tracking.py --frames 2000

Scenario (a) of docs/peers.md: 12° / 512 px, Hipparcos Hp <= 6, 0.1 px noise. The camera slews
along a great circle at ``--step-deg`` per frame (default 0.5°) with a slow roll drift, starting
at random; each frame is solved with the previous frame's solution as the prior (1° sigma), and
again from scratch. Times are ``SolveResult.time_ms`` (identification and fit); answers
scored by ``starnav evaluate``'s rule (``harness.CORRECT_RULE``). Writes the ``tracking`` block
of docs/performance.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import (
    DOCS,
    machine,
    replace_block,
    score_solution,
    table_head,
    table_row,
    warm_up,
)
from starnav.api import solve_stars
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate import simulate_frame

DOC = DOCS / "performance.md"
# mode -> (solve options, whether the prior is given)
MODES = {
    "tracking": ({}, True),
    "lost in space": ({}, False),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--step-deg", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    t0 = time.time()
    rng = np.random.default_rng(args.seed)
    catalog = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(12.0, 512)
    R = attitude_from_radec_roll(rng.uniform(0, 360), rng.uniform(-60, 60), rng.uniform(0, 360))
    # a steady turn about a fixed axis in the camera frame: mostly across the sky, a little roll
    step = Rotation.from_rotvec(np.radians(args.step_deg) * np.array([0.96, 0.2, 0.2])).as_matrix()
    load_s = warm_up(catalog, camera)
    prior = None
    rows = {name: [] for name in MODES}
    outcome = {name: {"correct": 0, "wrong": 0, "none": 0} for name in rows}
    tracked = 0
    for _ in tqdm(range(args.frames), desc="slew", file=sys.stderr):
        R = step @ R
        f = simulate_frame(catalog, camera, R_cam_from_icrs=R, noise_px=0.1, seed=rng)
        if len(f.xy) < 3:
            prior = None
            for name in rows:
                outcome[name]["none"] += 1
            continue
        for name, (options, tracks) in MODES.items():
            kwargs = dict(options, prior=prior, prior_sigma_deg=1.0) if tracks else options
            r = solve_stars(
                f.xy,
                width=512,
                fov_deg=12.0,
                brightness=f.brightness,
                catalog=catalog,
                sigma_px=0.1,
                **kwargs,
            )
            rows[name].append(r.time_ms)
            s = r.solution
            if s is None:
                outcome[name]["none"] += 1
                if name == "tracking":
                    prior = None
                continue
            ok = score_solution(s, f.R_cam_from_icrs).correct
            outcome[name]["correct" if ok else "wrong"] += 1
            if name == "tracking":
                tracked += s.algorithm == "tracking"
                prior = s
    lines = [
        f"{args.frames} frames of a slew at {args.step_deg:g}° per frame, 12° / 512 px, Hp <= 6, "
        f"0.1 px noise; prior = the previous frame's solution, 1° sigma (seed {args.seed}).",
        "",
        *table_head("mode", "correct", "wrong", "none", "median ms", "p95 ms", "max ms"),
    ]
    for name, times in rows.items():
        t = np.array(times)
        o = outcome[name]
        lines.append(
            table_row(
                name,
                o["correct"],
                o["wrong"],
                o["none"],
                f"{np.median(t):.2f}",
                f"{np.percentile(t, 95):.2f}",
                f"{t.max():.1f}",
            )
        )
    lines += [
        "",
        f"{tracked} frames answered by tracking, the rest fell back to lost in space. The "
        f"first two solves of the process (not counted) loaded the machine code: {load_s:.1f} s. "
        f"`python benchmarks/speed/tracking.py --frames {args.frames}`: "
        f"{time.time() - t0:.0f} s on {machine()}, one process.",
    ]
    text = "\n".join(lines)
    if args.out != "-":
        replace_block(args.out, "tracking", text)
    print(text)


if __name__ == "__main__":
    main()
