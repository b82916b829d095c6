"""Start-up and footprint: what a process pays around one star-list solve.

Every measurement runs in a fresh process, ``--repeats`` times, the kinds taking turns (median
and min reported):

1. ``python -X importtime -c "import starnav"``: the cumulative time of the top-level
   ``starnav`` line.
2. ``starnav identify STARS.csv --fov-deg 12 --width 512 --json`` (the console script, as a
   user runs it) on a list of 20 stars of a simulated 12° / 512 px frame: wall time and peak
   resident memory; as it chooses (the kernels as plain Python, ``starnav.cli.plain``) and
   with ``STARNAV_KERNELS=numba`` (the machine code loaded).
3. A Python process that imports starnav and solves that list with ``starnav.solve`` and the
   field given: its import and solve times, wall time and peak resident memory; with the
   machine code (the library's default) and with ``STARNAV_KERNELS=python``.
4. For scale, the floors under them: Python alone, ``import numpy``, ``import numba``, and a
   numba process calling one trivial kernel loaded from numba's cache, with and without the
   interpreter's garbage collections at exit (which walk numba's objects; ``starnav`` skips
   them).

Each process is started by a small Python process (``SPAWN``) that times it and reads its peak
resident memory (``ru_maxrss``) when it ends: a process forked from this script would count
this script's own memory in its peak. One run of the command first fills the caches (the
machine code, the pair table, the Hipparcos columns): the numbers are those of every process
after an installation's first.

    python benchmarks/speed/startup.py --repeats 10   # writes docs/performance.md, block "startup"
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from starnav.api import prepare_solver
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.runtime.caching import KERNELS_ENV
from starnav.simulate import simulate_frame

DOC = DOCS / "performance.md"
FOV_DEG, WIDTH, N_STARS = 12.0, 512, 20
TARGET_IMPORT_S, TARGET_IDENTIFY_S, TARGET_RSS_MB = 0.3, 0.6, 120.0
PYTHON = sys.executable
STARNAV = str(Path(sys.executable).parent / "starnav")  # the console script beside this Python

SOLVE = """
import time
t0 = time.perf_counter()
import numpy as np
import starnav
t1 = time.perf_counter()
table = np.loadtxt({path!r}, delimiter=",", skiprows=1)
solution = starnav.solve(table[:, :2], fov_deg={fov}, width={width}, brightness=-table[:, 2])
t2 = time.perf_counter()
assert solution is not None and solution.n_matched == {n}, solution
print(t1 - t0, t2 - t1)
"""
SPAWN = """
import os, sys, time
t0 = time.perf_counter()
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
_, status, usage = os.wait4(pid, 0)
wall = time.perf_counter() - t0
with open(sys.argv[1], "w") as fh:
    fh.write(f"{wall} {usage.ru_maxrss} {os.waitstatus_to_exitcode(status)}")
"""
RUNS = ("import", "identify", "identify, machine code", "solve", "solve, plain")
FROZEN_AT_EXIT = "import atexit, gc; atexit.register(gc.freeze); "
TRIVIAL_KERNEL = """
import numba

@numba.njit(cache=True)
def add_one(x):
    return x + 1
"""


def write_star_list(folder: Path) -> Path:
    """The brightest ``N_STARS`` stars of the first simulated 12° / 512 px frame (seeds 0, 1,
    ...) holding that many Hp <= 6 stars, as ``x,y,mag``."""
    catalog = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(FOV_DEG, WIDTH)
    for seed in range(1000):
        frame = simulate_frame(catalog, camera, seed=seed)
        if len(frame.xy) >= N_STARS:
            break
    keep = np.sort(np.argsort(frame.mag, kind="stable")[:N_STARS])
    path = folder / "stars20.csv"
    table = np.column_stack([frame.xy[keep], frame.mag[keep]])
    np.savetxt(path, table, delimiter=",", header="x,y,mag", comments="", fmt="%.4f")
    return path


def run(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float, str]:
    """Wall seconds, peak resident MB and stdout of ``cmd`` (its first item a path) in a new
    process started by ``SPAWN``; stops the script when it fails."""
    with tempfile.NamedTemporaryFile("r") as result:
        done = subprocess.run(
            [PYTHON, "-c", SPAWN, result.name, *cmd], capture_output=True, text=True, env=env
        )
        wall, rss_kb, code = result.read().split()
    if done.returncode != 0 or int(code) != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({code}):\n{done.stderr}")
    return float(wall), int(rss_kb) / 1024, done.stdout


def import_seconds() -> float:
    """The cumulative ``-X importtime`` time of the top-level ``starnav`` import, in a new
    process (s)."""
    err = subprocess.run(
        [PYTHON, "-X", "importtime", "-c", "import starnav"],
        capture_output=True,
        text=True,
        check=True,
    ).stderr
    line = re.search(r"^import time:\s*\d+ \|\s*(\d+) \| starnav$", err, re.M)
    return int(line.group(1)) / 1e6


def measure(args: argparse.Namespace, folder: Path) -> tuple[dict[str, list], float]:
    """Every kind's samples, taking turns; and the seconds of the warm-up run."""
    stars = write_star_list(folder)
    (folder / "trivial_kernel.py").write_text(TRIVIAL_KERNEL)
    env = {**os.environ, "PYTHONPATH": str(folder)}
    identify = [STARNAV, "identify", str(stars), "--fov-deg", f"{FOV_DEG:g}"]
    identify += ["--width", str(WIDTH), "--json"]
    solve = [PYTHON, "-c", SOLVE.format(path=str(stars), fov=FOV_DEG, width=WIDTH, n=N_STARS)]
    floors = {
        "Python alone (`python -c pass`)": ([PYTHON, "-c", "pass"], None),
        "`import numpy`": ([PYTHON, "-c", "import numpy"], None),
        "`import numba`": ([PYTHON, "-c", "import numba"], None),
        "numba, one trivial cached kernel called": (
            [PYTHON, "-c", "import trivial_kernel; trivial_kernel.add_one(1)"],
            env,
        ),
        "the same, the collections at exit skipped (`gc.freeze`, as `starnav` does)": (
            [PYTHON, "-c", FROZEN_AT_EXIT + "import trivial_kernel; trivial_kernel.add_one(1)"],
            env,
        ),
    }
    plain = {k: v for k, v in os.environ.items() if k != KERNELS_ENV}  # identify chooses
    machine_code = {**plain, KERNELS_ENV: "numba"}
    python_kernels = {**plain, KERNELS_ENV: "python"}
    # compiles the machine code if it is not cached yet
    warm_s = run(identify, machine_code)[0]
    run(floors["numba, one trivial cached kernel called"][0], env)
    samples: dict[str, list] = {name: [] for name in (*RUNS, *floors)}
    for _ in range(args.repeats):
        samples["import"].append(import_seconds())
        samples["identify"].append(run(identify, plain)[:2])
        samples["identify, machine code"].append(run(identify, machine_code)[:2])
        for name, kernels in (("solve", machine_code), ("solve, plain", python_kernels)):
            wall, rss, out = run(solve, kernels)
            samples[name].append((wall, rss, *(float(v) for v in out.split())))
        for name, (cmd, cmd_env) in floors.items():
            samples[name].append(run(cmd, cmd_env)[:2])
    return samples, warm_s


def tables() -> str:
    """What the solve holds besides code: its catalog and pair table (the defaults of a
    known field)."""
    database = prepare_solver(fov_deg=FOV_DEG, width=WIDTH).database
    return (
        f"the solve's catalog: {database.catalog.name}, {len(database.catalog)} stars; its pair "
        f"table {len(database.pair_a) / 1e6:.2f} million pairs, {database.nbytes / 1e6:.1f} MB"
    )


def spread(values, digits: int = 2) -> str:
    """'median (min)' of ``values``."""
    v = np.asarray(values, dtype=float)
    return f"{np.median(v):.{digits}f} ({v.min():.{digits}f})"


def report(samples: dict[str, list], warm_s: float, args, load: float, seconds: float) -> str:
    import_s = samples["import"]
    id_wall, id_rss = zip(*samples["identify"], strict=True)
    idm_wall, idm_rss = zip(*samples["identify, machine code"], strict=True)
    py_wall, py_rss, py_import, py_solve = zip(*samples["solve"], strict=True)
    pp_wall, pp_rss, pp_import, pp_solve = zip(*samples["solve, plain"], strict=True)

    def status(value: float, target: float, unit: str) -> str:
        met = "met" if np.median(value) < target else "**not met**"
        return f"{met} (median {np.median(value):.2f} {unit}, target < {target:g})"

    lines = [
        f"A list of {N_STARS} stars of a simulated {FOV_DEG:g}° / {WIDTH} px frame (Hp <= 6), "
        f"the field given; every process new, each kind {args.repeats} times in turn, the "
        "caches filled (machine code, pair table, Hipparcos columns) by one run before "
        f"({warm_s:.1f} s). Median (min).",
        "",
        *table_head("process", "wall s", "peak RSS MB", "of which"),
        table_row(
            "`python -X importtime -c 'import starnav'`",
            spread(import_s, 3),
            "",
            "cumulative time of the `starnav` line",
        ),
        table_row(
            f"`starnav identify STARS.csv --fov-deg {FOV_DEG:g} --width {WIDTH} --json`",
            spread(id_wall),
            spread(id_rss, 0),
            "the kernels as plain Python (the command's choice for one list of a known field)",
        ),
        table_row(
            f"the same with `{KERNELS_ENV}=numba`",
            spread(idm_wall),
            spread(idm_rss, 0),
            "numba and the kernels' machine code loaded",
        ),
        table_row(
            f"Python: `import starnav`, `starnav.solve(xy, fov_deg={FOV_DEG:g}, ...)`",
            spread(py_wall),
            spread(py_rss, 0),
            f"import {spread(py_import)} s, first solve {spread(py_solve)} s (numba and the "
            "machine code loaded in it)",
        ),
        table_row(
            f"the same with `{KERNELS_ENV}=python`",
            spread(pp_wall),
            spread(pp_rss, 0),
            f"import {spread(pp_import)} s, first solve {spread(pp_solve)} s (plain Python)",
        ),
    ]
    for name in samples:
        if name not in RUNS:
            wall, rss = zip(*samples[name], strict=True)
            lines.append(table_row(name, spread(wall), spread(rss, 0), "floor"))
    lines += [
        "",
        f"Targets: `import starnav` {status(import_s, TARGET_IMPORT_S, 's')}; "
        f"`starnav identify` {status(id_wall, TARGET_IDENTIFY_S, 's')}; peak RSS of the "
        f"star-list solve (`starnav identify`) {status(id_rss, TARGET_RSS_MB, 'MB')}; a Python "
        f"process that keeps the machine code loaded (many solves, 0.2-0.5 ms each) holds "
        f"{np.median(py_rss):.0f} MB. In memory besides the code: "
        f"{tables()}.",
        "",
        f"{machine(load, load_at_end=True)}; `python benchmarks/speed/startup.py --repeats "
        f"{args.repeats}`, {seconds:.0f} s.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10, help="runs of each kind (default 10)")
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    load, t0 = os.getloadavg()[0], time.time()
    with tempfile.TemporaryDirectory() as tmp:
        samples, warm_s = measure(args, Path(tmp))
    text = report(samples, warm_s, args, load, time.time() - t0)
    if args.out != "-":
        replace_block(args.out, "startup", text)
    print(text)


if __name__ == "__main__":
    main()
