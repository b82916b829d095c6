"""Where the wall time of one drop-in call goes: docs/performance.md, block "dropin-split".

    nice -n 0 python benchmarks/speed/dropin_split.py [--rounds 5] [--out docs/performance.md | -]
        [FILE]

One hinted ``starnav-solve-field`` call (``dropin_vs_solve_field.py``'s command line: INDI's
options, the position 2° off, the width ±10 %) on ``FILE`` (a name of
tests/data/real/reference.json; default cedar_jan1_g90_e100ms.jpg, a 1.2 MP frame
solve-field solves in ~1 s), each a new process with the machine code cached, run by a small
driver (``DRIVER``) that times each stage with ``perf_counter``: the imports, one package at
a time in the order the call needs them (imported ahead of the call so that each is counted
once, where it belongs); numba readying its CPU target on the first kernel call (the rest
of it once scipy.linalg is in); the kernels' machine code loaded from the cache; reading,
detecting, solving (each without the kernel loads inside it); the WCS fitted to the
matched stars and then to the Gaia stars the detections hold (``output.tweak``: detected again
to 500 stars); the files written and the lines printed. The garbage collector's own time is
taken from ``gc.callbacks``; "Python's start and exit" is the process's wall time less the
driver's. Each round runs the call as shipped (the collector paused,
``starnav.cli.parser.collector_paused``, and the process ended by ``exit_now``) and with the
collector on and the interpreter's own exit, in turn; then solve-field on the
same command line. Medians of ``--rounds`` rounds after one warm-up.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*

import argparse
import json
import os
import subprocess
import tempfile
import time

import numpy as np

from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from benchmarks.speed.dropin_vs_solve_field import REFERENCE, SOLVE_FIELD, commands, corpus_dir

DOC = DOCS / "performance.md"
BLOCK = "dropin-split"
DEFAULT_IMAGE = "cedar_jan1_g90_e100ms.jpg"
DRIVER = r"""
import gc, json, os, sys, time
T0 = time.perf_counter()
collector_on = os.environ["SPLIT_COLLECTOR"] == "on"
if not collector_on:
    gc.disable()  # as main() does from its start: the imports below are inside it there
spent, stack, collections = {}, [], [0, 0.0, 0.0]

def on_gc(phase, info):
    if phase == "start":
        collections[2] = time.perf_counter()
    else:
        collections[0] += 1
        collections[1] += time.perf_counter() - collections[2]

gc.callbacks.append(on_gc)

def timed(key, fn):
    def run(*a, **k):
        stack.append(0.0)
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            dt = time.perf_counter() - t
            inner = stack.pop()
            spent[key] = spent.get(key, 0.0) + dt - inner
            if stack:
                stack[-1] += dt
    return run

def wrap(owner, name, key):
    setattr(owner, name, timed(key, getattr(owner, name)))

def step(key, statement):
    timed(key, lambda: exec(statement, {}))()

step("the drop-in's own module", "import starnav.dropin.solve_field")
step("numpy", "import numpy")
step("astropy (io.fits, wcs, time)", "import astropy.io.fits, astropy.wcs, astropy.time")
step("starnav's solver modules", "import starnav.pipeline.plate, starnav.output.sidefiles")
step("numba", "import numba, starnav.detect.kernels")
step("scipy.linalg (numba's BLAS check)", "import scipy.linalg")
import numba.core.base, numba.core.dispatcher
import starnav.cli.parser, starnav.detect.read, starnav.dropin.solve_field as dropin
import starnav.pipeline.image as image
import starnav.pipeline.plate as plate
wrap(numba.core.base.BaseContext, "refresh", "numba readying its CPU target (the rest)")
wrap(numba.core.dispatcher.Dispatcher, "_compile_for_args", "kernels loaded from the cache")
wrap(starnav.detect.read, "read_image", "reading the image")
wrap(image, "_detect_binned", "detecting")
wrap(image, "_solve_hinted", "solving")
wrap(plate, "_result", "the WCS fitted (matched stars, then Gaia stars)")
wrap(dropin, "print_result", "files written, lines printed")
def report(code):
    inside = time.perf_counter() - T0
    print("SPLIT " + json.dumps({"spent": spent, "inside": inside, "code": code,
                                 "collections": collections[:2]}), file=sys.stderr)

if collector_on:  # the collector on, the process ended by the interpreter
    starnav.cli.parser.freeze_at_exit()
    report(dropin._main(sys.argv[1:]))
else:  # as the console script runs it: main() reads sys.argv and ends the process
    exit_now = starnav.cli.parser.exit_now  # run_console's
    starnav.cli.parser.exit_now = lambda code: (report(code), exit_now(code))
    sys.argv = ["starnav-solve-field", *sys.argv[1:]]
    dropin.main()
"""
# the driver's keys, in the order of the table
STAGES = (
    "the drop-in's own module",
    "numpy",
    "astropy (io.fits, wcs, time)",
    "starnav's solver modules",
    "numba",
    "scipy.linalg (numba's BLAS check)",
    "numba readying its CPU target (the rest)",
    "kernels loaded from the cache",
    "reading the image",
    "detecting",
    "solving",
    "the WCS fitted (matched stars, then Gaia stars)",
    "files written, lines printed",
)


def run_driver(args: list[str], collector: str) -> dict:
    """One call through ``DRIVER`` in a new process: its stages (s), the garbage collector's
    collections and time (s), the driver's time and the process's wall time (s)."""
    env = dict(os.environ, SPLIT_COLLECTOR=collector)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", DRIVER, *args], env=env, capture_output=True,
                          text=True)  # fmt: skip
    wall = time.perf_counter() - t
    line = next((ln for ln in done.stderr.splitlines() if ln.startswith("SPLIT ")), None)
    if done.returncode != 0 or line is None:
        raise SystemExit(f"the driver failed ({done.returncode}):\n{done.stderr[-2000:]}")
    if "Field center" not in done.stdout:
        raise SystemExit(f"the call did not solve:\n{done.stdout[-1000:]}")
    out = json.loads(line[len("SPLIT ") :])
    return {**out, "wall": wall}


def measure(image: Path, ref: dict, rounds: int, folder: Path) -> tuple[dict, list[float]]:
    """{collector: [driver results]} and solve-field's wall times (s), ``rounds`` each after
    one warm-up."""
    cmd = commands(image, ref, True, folder)
    (folder / "sf").mkdir(parents=True, exist_ok=True)
    args = cmd["starnav-solve-field"][1:]
    results: dict[str, list[dict]] = {"paused": [], "on": []}
    solve_field: list[float] = []
    for rnd in range(rounds + 1):
        for collector in results:
            out = run_driver(args, collector)
            if rnd:
                results[collector].append(out)
        t = time.perf_counter()
        subprocess.run(cmd["solve-field"], capture_output=True, check=True)
        if rnd:
            solve_field.append(time.perf_counter() - t)
        print(f"round {rnd}/{rounds}", file=sys.stderr, flush=True)
    return results, solve_field


def report(name: str, results: dict, solve_field: list[float], rounds: int, load: float) -> str:
    def median_ms(rows: list[dict], get) -> float:
        return 1e3 * float(np.median([get(r) for r in rows]))

    lines = [
        f"One hinted `starnav-solve-field` call on {name} (the command line of "
        "dropin_vs_solve_field.py), each a new process with the machine code cached: ms, "
        f"median of {rounds} rounds; as shipped (the garbage collector paused during the call, "
        "the process ended by `os._exit` once its output is flushed) and with the collector "
        "on and the interpreter's own exit (as before those two cuts). Each import is of "
        "what the call needs, in its order; a stage's time leaves out the stages inside it "
        "(the kernels loaded while detecting are counted once, as kernels).",
        "",
        *table_head("stage", "as shipped ms", "collector on, usual exit ms"),
    ]
    for stage in STAGES:
        cells = [median_ms(results[c], lambda r, s=stage: r["spent"].get(s, 0.0)) for c in results]
        lines.append(table_row(stage, *(f"{v:.0f}" for v in cells)))
    rows = {
        "garbage collections (count / ms)": [
            f"{np.median([r['collections'][0] for r in results[c]]):.0f} / "
            f"{median_ms(results[c], lambda r: r['collections'][1]):.0f}"
            for c in results
        ],
        "Python's start and exit": [
            f"{median_ms(results[c], lambda r: r['wall'] - r['inside']):.0f}" for c in results
        ],
        "**the process, wall**": [
            f"**{median_ms(results[c], lambda r: r['wall']):.0f}**" for c in results
        ],
    }
    lines += [table_row(k, *v) for k, v in rows.items()]
    lines += [
        "",
        f"solve-field on the same command line: {1e3 * float(np.median(solve_field)):.0f} ms "
        "(median). The stages do not add up to the wall time exactly: each median is taken "
        "on its own, and the collections run inside the stages.",
        "",
        f"{machine(load, load_at_end=True)}; `python benchmarks/speed/dropin_split.py "
        f"--rounds {rounds}`.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", nargs="?", default=DEFAULT_IMAGE, help="a reference.json name")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (default 5)")
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    refs = json.loads(REFERENCE.read_text())["images"]
    if args.file not in refs:
        raise SystemExit(f"{args.file} is not in {REFERENCE}")
    image = corpus_dir() / args.file
    if not image.is_file():
        raise SystemExit(f"{image} is absent (set STARNAV_REAL_CORPUS)")
    if not Path(SOLVE_FIELD).exists() and SOLVE_FIELD == "solve-field":
        raise SystemExit("solve-field is not installed (Debian: apt-get install astrometry.net)")
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        results, solve_field = measure(image, refs[args.file], args.rounds, Path(tmp))
    text = report(args.file, results, solve_field, args.rounds, load)
    if args.out != "-":
        replace_block(args.out, BLOCK, text, missing="## Where a drop-in call's time goes")
    print(text)


if __name__ == "__main__":
    main()
