"""A blind ``starnav solve IMG`` with the cached tables memory-mapped against read whole:
docs/performance.md, block "table-reads".

    nice -n 0 python benchmarks/speed/table_reads.py [--rounds 5] [--out docs/performance.md | -]
        [FILE ...]

Each call is a new process (the machine code and the tables cached, the page cache warm: one
call of each kind runs before timing), run by a small driver (``DRIVER``) that calls
``starnav.cli.main(["solve", IMG, "--json"])``: no hint, the default FOV range. "mapped" is
the call as shipped (``runtime.caching.load_cached``: each array a copy-on-write view of the
file); "read whole" replaces that reader, where the modules that read tables look it up, by
the one before (``np.load``, every array copied into memory), and changes nothing else. Per
call: the process's wall time, the time in ``pipeline.fov.load_bands`` (the bands' tables
read; with them mapped, a page is read when the search first touches it, inside the search),
and the process's peak resident memory; medians of ``--rounds`` rounds, the two kinds in
turn. The answers (centre and roll) are checked equal. ``FILE``: names of
tests/data/real/reference.json read from ``$STARNAV_REAL_CORPUS`` (else
``../shared/data/real``); default two 1-1.2 MP frames of two cameras.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*

import argparse
import json
import os
import subprocess
import time

import numpy as np

from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from benchmarks.speed.dropin_vs_solve_field import corpus_dir

DOC = DOCS / "performance.md"
BLOCK = "table-reads"
DEFAULT_IMAGES = ("cedar_jan1_g90_e100ms.jpg", "oresat_capture-2022-09-25-09-40-25.png")
DRIVER = r"""
import contextlib, io, json, resource, sys, time
T0 = time.perf_counter()
mode, image = sys.argv[1], sys.argv[2]
import numpy as np
from starnav.catalog import load as catalog_load
from starnav.cli import main
from starnav.identify import database, pattern4
from starnav.pipeline import fov

def read_whole(path):
    # the reader before memory mapping: every array copied into memory
    if not path.exists():
        return None
    try:
        with np.load(path) as data:
            return {name: data[name] for name in data.files}
    except (OSError, KeyError, ValueError):
        return None

if mode == "whole":
    for module in (catalog_load, database, pattern4):
        module.load_cached = read_whole
spent = [0.0]
load_bands = fov.load_bands

def timed(*args, **kwargs):
    t = time.perf_counter()
    try:
        return load_bands(*args, **kwargs)
    finally:
        spent[0] += time.perf_counter() - t

fov.load_bands = timed
out = io.StringIO()
with contextlib.redirect_stdout(out):
    code = main(["solve", image, "--json"])
print(json.dumps({
    "code": code, "answer": out.getvalue(), "load_bands_s": spent[0],
    "driver_s": time.perf_counter() - T0,
    "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}))
"""
MODES = {"mapped": "mapped", "whole": "read whole"}


def run_driver(mode: str, image: Path) -> dict:
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", DRIVER, mode, str(image)], capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"the driver failed on {image.name}:\n{done.stderr[-2000:]}")
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record["wall_s"] = wall
    return record


def answer_key(record: dict) -> tuple:
    """The answer's centre and roll (rounded to 1e-9°), or its reason when not solved."""
    answer = json.loads(record["answer"].strip().splitlines()[-1])
    if not answer.get("solved"):
        return ("not solved", answer.get("reason"))
    return tuple(round(float(answer[k]), 9) for k in ("ra_deg", "dec_deg", "roll_deg"))


def measure(image: Path, rounds: int) -> dict[str, dict[str, list]]:
    for mode in MODES:
        run_driver(mode, image)  # warm: the page cache, the bytecode
    runs: dict[str, dict[str, list]] = {m: {"wall": [], "bands": [], "rss": []} for m in MODES}
    answers = set()
    for k in range(rounds):
        print(f"{image.name}: round {k + 1}/{rounds}", file=sys.stderr)
        for mode in MODES:
            record = run_driver(mode, image)
            runs[mode]["wall"].append(record["wall_s"])
            runs[mode]["bands"].append(record["load_bands_s"])
            runs[mode]["rss"].append(record["maxrss_mb"])
            answers.add(answer_key(record))
    if len(answers) != 1:
        raise SystemExit(f"{image.name}: the answers differ: {sorted(answers)}")
    return runs


def report(results: dict[str, dict], rounds: int, load: float) -> str:
    lines = [
        f"A blind `starnav solve IMG --json` (no hint, the default FOV range), each a new process "
        f"with the machine code and the tables cached and the page cache warm: median of "
        f"{rounds} rounds, the tables memory-mapped (as shipped) and read whole (`np.load`, "
        'the reader before), in turn; the same answers. "bands loaded": the time in '
        "`pipeline.fov.load_bands`.",
        "",
        *table_head("image", "tables", "the process, wall ms", "bands loaded ms", "peak memory MB"),
    ]
    for name, runs in results.items():
        for mode, label in MODES.items():
            r = runs[mode]
            lines.append(
                table_row(
                    name,
                    label,
                    f"{1000 * np.median(r['wall']):.0f}",
                    f"{1000 * np.median(r['bands']):.0f}",
                    f"{np.median(r['rss']):.0f}",
                )
            )
    argv = " ".join(sys.argv[1:])
    lines += [
        "",
        f"{machine(load, load_at_end=True)}; `python benchmarks/speed/table_reads.py"
        f"{' ' + argv if argv else ''}`.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", default=str(DOC), help="docs file to update, or - to print")
    parser.add_argument("files", nargs="*", default=list(DEFAULT_IMAGES))
    args = parser.parse_args()
    load = os.getloadavg()[0]
    folder = corpus_dir()
    results = {}
    for name in args.files:
        image = folder / name
        if not image.exists():
            raise SystemExit(f"{image}: not found (set STARNAV_REAL_CORPUS)")
        results[name] = measure(image, args.rounds)
    text = report(results, args.rounds, load)
    if args.out == "-":
        print(text)
    else:
        replace_block(args.out, BLOCK, text)
        print(f"wrote block {BLOCK!r} of {args.out}")


if __name__ == "__main__":
    main()
