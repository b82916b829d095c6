"""Per-frame latency of ``starnav track`` fed at a camera's rate over a pipe.

    python benchmarks/speed/track_stream.py --frames 600

A real ``starnav track`` process (``--camera``: 12° / 512 px with ``--sigma-px 0.1``, or a
6° star tracker, 6.1° / 1392 x 1040 px with ``--sigma-px 0.3``; its default catalog depth and
time budget) is fed frames at ``--rate-hz`` (default 10 Hz: the script sleeps until each
frame is due, as a camera would deliver it) and each answer line is read before the next frame
is due. Latency is from the frame's line written (and flushed) to its answer line read: the
pipe both ways, reading, solving and writing the answer, as flight software sees it. The
frames (Hipparcos stars to Hp 6, or 10.3 for the tracker, made before the process starts, so
their making is not timed) are a slew at ``--step-deg`` per frame with a slow roll drift,
0.1 px noise (0.3 for the tracker) and one false star, from a random start; every
``--outage-every``-th frame comes after a 10 s outage (its ``t`` jumps), so it is solved lost
in space, every ``--random-every``-th holds 30 random points and no star field (the hardest
frame: the whole search runs, nothing is found), and every ``--bad-every``-th line is not
JSON. Answers are scored by ``starnav evaluate``'s rule (``harness.CORRECT_RULE``). Writes
the ``track-latency`` block of docs/track.md (``track-latency-tracker`` for the tracker;
``--out -``: print only).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import (
    DOCS,
    machine,
    replace_block,
    score_answer,
    table_head,
    table_row,
)
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate import simulate_frame

DOC = DOCS / "track.md"
# the cameras: (description, command options, horizontal FOV deg, width, height px, the
# stars' Hp limit, centroid noise px, the docs block)
CAMERAS = {
    "12": ("12° / 512 px, stars to Hp 6, 0.1 px noise",
           ["--fov-deg", "12", "--width", "512", "--sigma-px", "0.1"],
           12.0, 512, 512, 6.0, 0.1, "track-latency"),
    "tracker": ("a 6° star tracker: 6.1° / 1392 x 1040 px, stars to Hp 10.3, 0.3 px noise",
                ["--fov-deg", "6.1", "--width", "1392", "--height", "1040", "--sigma-px", "0.3"],
                6.1, 1392, 1040, 10.3, 0.3, "track-latency-tracker"),
}  # fmt: skip
OUTAGE_S = 10.0  # the time jump before an outage frame (longer than --max-gap-s's default)
RANDOM_POINTS = 30  # the points of a frame that holds no star field


def make_frames(args: argparse.Namespace) -> list[tuple[str, str, np.ndarray | None]]:
    """(kind, JSON line, true attitude or None) per line: kinds "frame", "outage", "random",
    "bad"."""
    rng = np.random.default_rng(args.seed)
    _, _, fov_deg, width, height, mag, noise_px, _ = CAMERAS[args.camera]
    catalog = load_catalog(None, mag_limit=mag)
    camera = Camera.from_fov(fov_deg, width, height)
    R = attitude_from_radec_roll(rng.uniform(0, 360), rng.uniform(-60, 60), rng.uniform(0, 360))
    # a steady turn about a fixed axis in the camera frame: mostly across the sky, a little roll
    step = Rotation.from_rotvec(np.radians(args.step_deg) * np.array([0.96, 0.2, 0.2])).as_matrix()
    t_s, out = 0.0, []
    for k in range(1, args.frames + 1):
        if k % args.bad_every == 0:
            out.append(("bad", '{"x": [1, 2, 3], "y": ', None))
            continue
        if k % args.random_every == 0:  # no star field: the whole search runs, nothing found
            xy = (rng.uniform(0, 1, (RANDOM_POINTS, 2)) * (width, height)).round(3)
            out.append(("random", json.dumps({"xy": xy.tolist(), "id": k}), None))
            continue
        kind = "outage" if k % args.outage_every == 0 else "frame"
        t_s += OUTAGE_S if kind == "outage" else 1.0 / args.rate_hz
        R = step @ R
        f = simulate_frame(catalog, camera, R_cam_from_icrs=R, noise_px=noise_px, false_stars=1,
                           seed=rng)  # fmt: skip
        line = {"x": f.xy[:, 0].round(3).tolist(), "y": f.xy[:, 1].round(3).tolist(),
                "mag": f.mag.round(2).tolist(), "t": round(t_s, 3), "id": k}  # fmt: skip
        out.append((kind, json.dumps(line), R))
    return out


def start(options: list[str]) -> tuple[subprocess.Popen, str]:
    """The ``starnav track`` process, once it says it is ready (its ready line)."""
    command = [sys.executable, "-m", "starnav", "track", *options]
    proc = subprocess.Popen(command, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    line = ""
    for line in proc.stderr:  # the lines before it: a notice when the machine code compiles
        if "ready" in line:
            break
    if "ready" not in line:  # the process ended without getting ready
        proc.kill()
        raise SystemExit(f"starnav track did not get ready: {line or 'no line'}")
    return proc, line.strip()


def feed(proc: subprocess.Popen, frames, rate_hz: float) -> tuple[list, int]:
    """Each line written when due (``rate_hz``), its answer read: (kind, latency ms, answer,
    truth) per line; and how many lines were sent late (the previous answer came after the
    next frame was due)."""
    rows, period, late = [], 1.0 / rate_hz, 0
    t_start = time.perf_counter() + period
    for n, (kind, line, R_true) in enumerate(frames):
        due = t_start + n * period
        wait = due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        else:
            late += 1
        t0 = time.perf_counter()
        proc.stdin.write(line + "\n")
        proc.stdin.flush()
        answer = json.loads(proc.stdout.readline())
        rows.append((kind, (time.perf_counter() - t0) * 1e3, answer, R_true))
    return rows, late


def verdict(answer: dict, R_true) -> str:
    """ "correct" / "wrong" / "none" by ``starnav evaluate``'s rule."""
    score = None if R_true is None else score_answer(answer, R_true)
    if score is None or not answer["solved"]:
        return "none"
    return "correct" if score.correct else "wrong"


def table(rows) -> list[str]:
    """One row per kind of line (tracked, lost in space, bad line) and all lines."""
    groups = {
        "tracked": [r for r in rows if r[2]["mode"] == "tracked"],
        "lost in space": [r for r in rows if r[2]["mode"] == "lost_in_space"],
        "not solved: random points": [r for r in rows if r[0] == "random"],
        "not solved: star frames": [
            r for r in rows if r[0] != "random" and not r[2]["solved"] and r[2]["error"] is None
        ],
        "bad line (error)": [r for r in rows if r[2]["error"] is not None],
        "all lines": rows,
    }
    lines = table_head("answered as", "lines", "correct", "wrong", "latency median ms",
                       "p95 ms", "max ms", "in the process: median ms", "max ms")  # fmt: skip
    for name, group in groups.items():
        if not group:
            continue
        latency = np.array([r[1] for r in group])
        inside = np.array([r[2]["time_ms"] for r in group])
        verdicts = [verdict(r[2], r[3]) for r in group]
        lines.append(table_row(
            name, len(group), verdicts.count("correct"), verdicts.count("wrong"),
            f"{np.median(latency):.2f}", f"{np.percentile(latency, 95):.2f}",
            f"{latency.max():.2f}", f"{np.median(inside):.2f}", f"{inside.max():.2f}",
        ))  # fmt: skip
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600, help="lines fed (default 600)")
    parser.add_argument("--rate-hz", type=float, default=10.0, help="frame rate (default 10)")
    parser.add_argument("--step-deg", type=float, default=0.05,
                        help="slew per frame (degrees; default 0.05, 0.5°/s at 10 Hz)")  # fmt: skip
    parser.add_argument("--outage-every", type=int, default=20, help="default 20")
    parser.add_argument("--random-every", type=int, default=50, help="default 50")
    parser.add_argument("--bad-every", type=int, default=100, help="default 100")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--camera", choices=list(CAMERAS), default="12",
                        help="12: 12° / 512 px (default); tracker: a 6° star tracker")  # fmt: skip
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    frames = make_frames(args)
    t0 = time.time()
    described, options, *_, block = CAMERAS[args.camera]
    proc, ready = start(options)
    try:
        rows, late = feed(proc, frames, args.rate_hz)
    finally:
        proc.stdin.close()  # end of input: the process exits 0
        code = proc.wait(timeout=60)
    wall = time.time() - t0
    lines = [
        f"{len(rows)} lines at {args.rate_hz:g} Hz through one `starnav track` process over a "
        f"pipe: a slew at {args.step_deg:g}° per frame, {described}, one false star; "
        f"`starnav track {' '.join(options)}`; every {args.outage_every}th frame after a "
        f"{OUTAGE_S:g} s outage (lost in space), every {args.random_every}th "
        f"{RANDOM_POINTS} random points without brightness (no star field: the whole search "
        f"runs), every {args.bad_every}th line not JSON (seed {args.seed}).",
        "",
        *table(rows),
        "",
        f"Latency: the frame's line written to its answer line read; in the process: the "
        f"answer's `time_ms`. Lines sent late (the previous answer came after the next frame "
        f'was due): {late}. Before the first frame: "{ready}". Exit status at the end of '
        f"input: {code}. `python benchmarks/speed/track_stream.py --frames {args.frames} "
        f"--camera {args.camera}`: "
        f"{wall:.0f} s on {machine(load_at_end=True)}.",
    ]
    text = "\n".join(lines)
    if args.out != "-":
        replace_block(args.out, block, text)
    print(text)


if __name__ == "__main__":
    main()
