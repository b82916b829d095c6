"""Many image files in one ``starnav solve`` process, against one process per file.

Renders a set of PNG files (1024 x 768 px, 8-30° fields, Hipparcos Hp <= 7, sky noise, hot
pixels) and a tracking sequence (a slow pan), then times, from the command line as a user runs
it:

- one process per file (``starnav solve FILE --json``) on the first few files: each pays the
  catalog, table and machine-code load;
- ``starnav solve DIR --jsonl`` with ``--workers 1`` and ``--workers 2``: its summary line's
  per-file cost after the first (read + detect + solve), and the wall time;
- the pan with ``--track`` against without.

Answers are scored against the rendered attitude by ``starnav evaluate``'s rule
(``harness.CORRECT_RULE``): "wrong" counts the answers that are not correct.

    python benchmarks/speed/image_batch.py   # writes the block "image-batch" of docs/performance.md
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, score_answer, table_head, table_row
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate.render import RenderSettings, render_frame, write_image

DOC = DOCS / "performance.md"
STARNAV = [sys.executable, "-m", "starnav.cli", "solve"]


def render_set(folder: Path, n: int, seed: int) -> dict[str, np.ndarray]:
    """``n`` files of random fields and FOVs; their true attitudes by file name."""
    rng = np.random.default_rng(seed)
    sky = load_catalog(None, mag_limit=7.0)
    truth = {}
    for k in range(n):
        cam = Camera.from_fov(float(rng.uniform(8.0, 30.0)), 1024, 768)
        ra, dec = rng.uniform(0.0, 360.0), np.degrees(np.arcsin(rng.uniform(-1.0, 1.0)))
        R = attitude_from_radec_roll(ra, dec, float(rng.uniform(0.0, 360.0)), 1)
        write_image(
            folder / f"img{k:03d}.png", render_frame(sky, cam, R, RenderSettings(seed=k)).image
        )
        truth[f"img{k:03d}.png"] = R
    return truth


def render_pan(folder: Path, n: int) -> dict[str, np.ndarray]:
    """A pan of ``n`` frames, 0.2° apart, 12° field."""
    sky = load_catalog(None, mag_limit=7.0)
    cam = Camera.from_fov(12.0, 1024, 768)
    truth = {}
    for k in range(n):
        R = attitude_from_radec_roll(100.0 + 0.2 * k, 20.0, 10.0 + 0.05 * k, 1)
        write_image(
            folder / f"pan{k:03d}.png", render_frame(sky, cam, R, RenderSettings(seed=k)).image
        )
        truth[f"pan{k:03d}.png"] = R
    return truth


def run(args: list[str]) -> tuple[float, str, str]:
    t0 = time.perf_counter()
    p = subprocess.run([*STARNAV, *args], capture_output=True, text=True, check=False)
    return time.perf_counter() - t0, p.stdout, p.stderr


def check(lines: list[dict], truth: dict[str, np.ndarray]) -> tuple[int, int]:
    """(solved, wrong) of JSON lines against the truth."""
    solved = wrong = 0
    for r in lines:
        if not r["solved"]:
            continue
        solved += 1
        wrong += not score_answer(r, truth[Path(r["file"]).name]).correct
    return solved, wrong


def batch_row(label: str, folder: Path, truth, extra: list[str]) -> str:
    out = folder.parent / f"{folder.name}-{len(extra)}.jsonl"
    wall, _, err = run([str(folder), "--jsonl", str(out), *extra])
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    solved, wrong = check(lines, truth)
    summary = next((line for line in err.splitlines() if " files: " in line), "")
    per = re.search(r"per file after it \(median\): (.*)$", summary)
    return table_row(
        label,
        len(lines),
        solved,
        wrong,
        f"{wall:.1f}",
        f"{wall / len(lines) * 1e3:.0f}",
        per.group(1) if per else "n/a",
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=40)
    ap.add_argument("--single", type=int, default=5, help="files solved one process each")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--no-doc", action="store_true")
    args = ap.parse_args()
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "set").mkdir()
        (root / "pan").mkdir()
        truth = render_set(root / "set", args.files, args.seed)
        pan = render_pan(root / "pan", args.files)
        run([str(root / "set" / "img000.png")])  # machine code and tables on disk, once
        singles = []
        for k in range(args.single):
            wall, out, err = run([str(root / "set" / f"img{k:03d}.png"), "--json"])
            if not out.strip():
                raise SystemExit(f"starnav solve printed nothing: {err}")
            singles.append((wall, json.loads(out)))
        single_wall = float(np.median([w for w, _ in singles]))
        single_solve = float(np.median([r["solve_ms"] for _, r in singles]))
        rows = [
            f"| one process per file ({args.single} files) | {args.single} | "
            f"{sum(r['solved'] for _, r in singles)} | - | {sum(w for w, _ in singles):.1f} | "
            f"{single_wall * 1e3:.0f} | solve {single_solve:.0f} ms of it |",
            batch_row("`starnav solve DIR --workers 1`", root / "set", truth, ["--workers", "1"]),
            batch_row("`starnav solve DIR --workers 2`", root / "set", truth, ["--workers", "2"]),
            batch_row("pan, `--workers 1`", root / "pan", pan, ["--workers", "1"]),
            batch_row(
                "pan, `--workers 1 --track`", root / "pan", pan, ["--workers", "1", "--track"]
            ),
        ]
    text = "\n".join(
        [
            f"{args.files} rendered PNG files (1024 x 768 px, FOV 8-30° at random, Hp <= 7, "
            f"seed {args.seed}) and a pan of {args.files} frames (12°, 0.2° apart); the FOV "
            "unknown; the command line as a user runs it.",
            "",
            *table_head(
                "run",
                "files",
                "solved",
                "wrong",
                "wall s",
                "wall ms per file",
                "per file after the first (median, from the summary)",
            ),
            *rows,
            "",
            f"{machine()}; "
            f"`python benchmarks/speed/image_batch.py --files {args.files}`, "
            f"{time.perf_counter() - t_start:.0f} s.",
        ]
    )
    print(text)
    if not args.no_doc:
        replace_block(DOC, "image-batch", text)


if __name__ == "__main__":
    main()
