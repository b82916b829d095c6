"""A drop-in call against Debian's solve-field, side by side on the same real 1-2 MP images
with the same hints: docs/performance.md, block "dropin-vs-solve-field".

    nice -n 0 python benchmarks/speed/dropin_vs_solve_field.py [--repeats 3] [--quick]
        [--no-cold] [--out docs/performance.md | -] [FILE ...]

Each command runs as its clients run it, as a new process, and is timed end to end (wall time
of the process and of any it starts, from start to exit; peak resident memory of the largest):

* ``solve-field`` (astrometry.net, Debian's package and index files) with INDI's options
  (``indi_astrometry``: ``--no-verify --no-plots --resort --downsample 2 -O``), a CPU limit
  of 30 s (that blind calls end) and an output folder;
* ``starnav-solve-field`` with the same command line;
* ``starnav-astap`` with N.I.N.A.'s (``-f IMG -fov HEIGHT -z 0 -s 500 -r R -ra HOURS
  -spd DEC+90``, docs/dropin.md) and an output base.

Two kinds of call per image: hinted as N.I.N.A. hints (the position 2° off the field centre,
searched within 5°; the scale within ±10 %: solve-field's ``-3 -4 -5 -L -H -u degwidth``,
ASTAP's ``-ra -spd -r -fov``), and blind (no position, no scale: ASTAP's ``-fov 0 -r 180``).
The truth is astrometry.net's own answer on each image (``tests/data/real/reference.json``,
made without hints); every answer's field centre is checked against it, and the table gives
the offset (arcmin) so that a fast wrong answer cannot pass for a result.

Every kind of call runs once before timing (the page cache holds the index files, starnav's
caches hold the machine code and the catalog tables, Python's its bytecode, as on any
installation after its first call); then ``--repeats`` rounds, each running every command
once on every image, in turn: median (and min) seconds. Separately, starnav's first call on a
new installation (``--no-cold`` skips it): the same hinted ``starnav-solve-field`` call with
an empty cache (``STARNAV_CACHE_DIR``), so that the machine code is compiled and the tables
built. And the start-up of the programs alone: ``starnav-solve-field --help``,
``starnav-astap -h``.

Images: ``FILE`` names of reference.json, else one photograph per source repository of the
corpus (``default_images``: the first by name of those of 1-2.2 MP that astrometry.net solved
with its answer passing the catalog check, at least 3° wide: the embedded catalog's reach),
read from ``$STARNAV_REAL_CORPUS``, else ``../shared/data/real``; absent ones are listed as
such. ``--quick``: the first two present, one round, no cold call, the table printed only.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
import time

import numpy as np

from benchmarks.harness import (
    DOCS,
    ROOT,
    SHARED,
    WRONG_DEG,
    machine,
    replace_block,
    table_head,
    table_row,
)
from starnav.geometry import angle_between, radec_to_unit

DOC = DOCS / "performance.md"
BLOCK = "dropin-vs-solve-field"
REFERENCE = ROOT / "tests" / "data" / "real" / "reference.json"
BIN = Path(sys.executable).parent  # the console scripts beside this Python
SOLVE_FIELD = shutil.which("solve-field") or "solve-field"
SOURCES = ROOT / "tests" / "data" / "real" / "sources.json"
MEGAPIXELS = (1.0, 2.2)
MIN_WIDTH_DEG = 3.0  # the embedded catalog's reach
INDI = ["--no-verify", "--no-plots", "--resort", "--downsample", "2", "-O"]
CPU_LIMIT_S = 30  # solve-field's --cpulimit (and starnav's time budget) of every call
HINT_OFFSET_DEG = 2.0  # the hinted position is this far from the field centre (north-east)
HINT_RADIUS_DEG = 5.0
SCALE_TOLERANCE = 0.10
CENTRE = re.compile(r"Field center: \(RA,Dec\) = \(([-\d.]+), ([-\d.]+)\) deg\.")
INI_VALUE = re.compile(r"^(PLTSOLVD|CRVAL1|CRVAL2)=\s*(\S+)", re.M)
SPAWN = """
import os, sys, time
t0 = time.perf_counter()
with open(sys.argv[2], "wb") as out:
    pid = os.posix_spawnp(sys.argv[3], sys.argv[3:], os.environ,
                          file_actions=[(os.POSIX_SPAWN_DUP2, out.fileno(), 1),
                                        (os.POSIX_SPAWN_DUP2, out.fileno(), 2)])
    _, status, usage = os.wait4(pid, 0)
wall = time.perf_counter() - t0
with open(sys.argv[1], "w") as fh:
    fh.write(f"{wall} {usage.ru_maxrss} {os.waitstatus_to_exitcode(status)}")
"""


def corpus_dir() -> Path:
    return Path(os.environ.get("STARNAV_REAL_CORPUS") or SHARED / "real")


def default_images(refs: dict) -> list[str]:
    """One image per source repository (the first by name): 1-2.2 MP, solved by
    astrometry.net with its answer passing the catalog check, at least ``MIN_WIDTH_DEG``
    wide."""
    repository = {f["name"]: f["repository"] for f in json.loads(SOURCES.read_text())["files"]}
    first: dict[str, str] = {}
    for name, ref in sorted(refs.items()):
        mp = ref["width"] * ref["height"] / 1e6
        checked = not (ref.get("check_inconclusive") or ref.get("check_overridden"))
        if (ref.get("solved_by_reference") and checked and ref["fov_deg"] >= MIN_WIDTH_DEG
                and MEGAPIXELS[0] <= mp <= MEGAPIXELS[1]):  # fmt: skip
            first.setdefault(repository[name], name)
    return sorted(first.values())


def run(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float, int, str]:
    """Wall seconds, peak resident MB (the largest of the process and those it waited for),
    exit code and output (stdout and stderr) of ``cmd`` in a new process, started by a small
    Python process (``SPAWN``) so that this script's own memory is not counted. Python's
    bytecode cache is on (``PYTHONDONTWRITEBYTECODE`` removed), as in an installed package."""
    env = {k: v for k, v in (os.environ if env is None else env).items()
           if k != "PYTHONDONTWRITEBYTECODE"}  # fmt: skip
    with tempfile.NamedTemporaryFile("r") as result, tempfile.NamedTemporaryFile("r") as out:
        subprocess.run([sys.executable, "-c", SPAWN, result.name, out.name, *cmd], env=env,
                       check=True)  # fmt: skip
        wall, rss_kb, code = result.read().split()
        return float(wall), int(rss_kb) / 1024, int(code), out.read()


def offset_deg(ra1: float, dec1: float, ra2: float, dec2: float) -> float:
    """Great-circle angle between two (RA, Dec) positions, degrees."""
    a, b = (radec_to_unit(math.radians(r), math.radians(d)) for r, d in ((ra1, dec1), (ra2, dec2)))
    return math.degrees(float(angle_between(a, b)))


def hint_position(ref: dict) -> tuple[float, float]:
    """(RA, Dec) degrees ``HINT_OFFSET_DEG`` from the reference centre, towards position
    angle 45° (north-east), as a mount's pointing is off."""
    ra, dec = math.radians(ref["ra_deg"]), math.radians(ref["dec_deg"])
    d, pa = math.radians(HINT_OFFSET_DEG), math.radians(45.0)
    dec2 = math.asin(math.sin(dec) * math.cos(d) + math.cos(dec) * math.sin(d) * math.cos(pa))
    ra2 = ra + math.atan2(
        math.sin(pa) * math.sin(d) * math.cos(dec), math.cos(d) - math.sin(dec) * math.sin(dec2)
    )
    return math.degrees(ra2) % 360.0, math.degrees(dec2)


def height_deg(ref: dict) -> float:
    """The image height (degrees) of a pinhole camera of the reference's width."""
    half = math.radians(ref["fov_deg"]) / 2.0
    return math.degrees(2.0 * math.atan(math.tan(half) * ref["height"] / ref["width"]))


def commands(image: Path, ref: dict, hinted: bool, out: Path) -> dict[str, list[str]]:
    """The three command lines on ``image``, outputs under ``out``."""
    sf = [str(image), *INDI, "--cpulimit", str(CPU_LIMIT_S), "--dir", str(out / "sf")]
    astap = ["-f", str(image), "-o", str(out / "astap" / image.stem), "-z", "0", "-s", "500"]
    if hinted:
        ra, dec = hint_position(ref)
        lo, hi = ref["fov_deg"] * (1 - SCALE_TOLERANCE), ref["fov_deg"] * (1 + SCALE_TOLERANCE)
        sf += ["-3", f"{ra:.4f}", "-4", f"{dec:.4f}", "-5", f"{HINT_RADIUS_DEG:g}"]
        sf += ["-L", f"{lo:.3f}", "-H", f"{hi:.3f}", "-u", "degwidth"]
        astap += ["-fov", f"{height_deg(ref):.3f}", "-r", f"{HINT_RADIUS_DEG:g}"]
        astap += ["-ra", f"{ra / 15.0:.5f}", "-spd", f"{dec + 90.0:.4f}"]
    else:
        astap += ["-fov", "0", "-r", "180"]
    return {
        "solve-field": [SOLVE_FIELD, *sf],
        "starnav-solve-field": [str(BIN / "starnav-solve-field"), *sf],
        "starnav-astap": [str(BIN / "starnav-astap"), *astap],
    }


def answer(tool: str, text: str, image: Path, out: Path) -> tuple[float, float] | None:
    """The field centre (RA, Dec) degrees a call printed (solve-field's line) or wrote
    (ASTAP's .ini), None when it did not solve."""
    if tool == "starnav-astap":
        ini = out / "astap" / f"{image.stem}.ini"
        values = dict(INI_VALUE.findall(ini.read_text())) if ini.exists() else {}
        if values.get("PLTSOLVD") != "T":
            return None
        return float(values["CRVAL1"]), float(values["CRVAL2"])
    match = CENTRE.search(text)
    return None if match is None else (float(match.group(1)), float(match.group(2)))


def measure_calls(files: dict[str, Path], refs: dict, repeats: int, folder: Path) -> dict:
    """{(image, kind, tool): [(wall s, rss MB, offset arcmin or None), ...]}, the first
    (warm-up) call of each left out."""
    samples: dict[tuple, list] = {}
    for rnd in range(repeats + 1):
        for name, path in files.items():
            for kind in ("hinted", "blind"):
                out = folder / f"{Path(name).stem}-{kind}"
                for tool, cmd in commands(path, refs[name], kind == "hinted", out).items():
                    (out / "sf").mkdir(parents=True, exist_ok=True)
                    (out / "astap").mkdir(parents=True, exist_ok=True)
                    wall, rss, code, text = run(cmd)
                    if code != 0 and not (tool == "starnav-astap" and code in (1, 2)):
                        raise SystemExit(f"{' '.join(cmd)} failed ({code}):\n{text[-2000:]}")
                    centre = answer(tool, text, path, out)
                    ref = refs[name]
                    off = None if centre is None else 60.0 * offset_deg(*centre, ref["ra_deg"],
                                                                        ref["dec_deg"])  # fmt: skip
                    if rnd > 0:
                        samples.setdefault((name, kind, tool), []).append((wall, rss, off))
            print(f"round {rnd}/{repeats}: {name}", file=sys.stderr, flush=True)
    return samples


def measure_help(repeats: int) -> dict[str, list[float]]:
    """Wall seconds of the drop-ins' help, ``max(repeats, 10)`` times each, in turn."""
    cmds = {
        "starnav-solve-field --help": [str(BIN / "starnav-solve-field"), "--help"],
        "starnav-astap -h": [str(BIN / "starnav-astap"), "-h"],
    }
    out: dict[str, list[float]] = {name: [] for name in cmds}
    for _ in range(max(repeats, 10)):
        for name, cmd in cmds.items():
            out[name].append(run(cmd)[0])
    return out


def measure_cold(name: str, path: Path, ref: dict, folder: Path) -> tuple[float, str]:
    """Seconds of one hinted ``starnav-solve-field`` call with an empty cache (on an image
    the warm calls solved), and the line it printed about the compilation (or "")."""
    cache = folder / "empty-cache"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["STARNAV_CACHE_DIR"] = str(cache)
    out = folder / "cold"
    (out / "sf").mkdir(parents=True, exist_ok=True)
    cmd = commands(path, ref, True, out)["starnav-solve-field"]
    wall, _, code, text = run(cmd, env)
    said = next((ln for ln in text.splitlines() if "compil" in ln.lower()), "")
    if code != 0 or answer("starnav-solve-field", text, path, out) is None:
        said += f" (it did not solve: exit {code})"
    return wall, said


IMPORT_LINE = re.compile(r"^import time:\s+(\d+) \|\s+\d+ \| (\s*)(\S+)$", re.M)
GROUPS = ("numpy", "astropy", "numba", "llvmlite", "scipy", "starnav")
BREAKDOWN = """
import resource, sys, time
t0 = time.perf_counter()
from starnav.dropin.solve_field import main
code = main(sys.argv[1:])
usage = resource.getrusage(resource.RUSAGE_SELF)
print(f"BREAKDOWN {time.perf_counter() - t0} {usage.ru_utime + usage.ru_stime}", file=sys.stderr)
sys.exit(code)
"""


def breakdown(path: Path, ref: dict, folder: Path) -> dict[str, float]:
    """Where one hinted ``starnav-solve-field`` call's time goes, in a process of its own run
    with ``python -X importtime``: the imports' own times (ms) by package (``GROUPS``, the
    rest as "other"), the process's wall and CPU seconds after Python's start."""
    out = folder / "breakdown"
    (out / "sf").mkdir(parents=True, exist_ok=True)
    args = commands(path, ref, True, out)["starnav-solve-field"][1:]
    _, _, code, text = run([sys.executable, "-X", "importtime", "-c", BREAKDOWN, *args])
    if code != 0:
        raise SystemExit(f"breakdown call failed ({code}):\n{text[-2000:]}")
    ms = dict.fromkeys((*GROUPS, "other"), 0.0)
    for self_us, _, name in IMPORT_LINE.findall(text):
        top = name.split(".")[0]
        ms[top if top in ms else "other"] += int(self_us) / 1e3
    wall, cpu = re.search(r"^BREAKDOWN (\S+) (\S+)$", text, re.M).groups()
    return {**ms, "wall_s": float(wall), "cpu_s": float(cpu)}


def spread(values, digits: int = 2) -> str:
    """'median (min)' of ``values``."""
    v = np.asarray(values, dtype=float)
    return f"{np.median(v):.{digits}f} ({v.min():.{digits}f})"


def solved(rows: list) -> bool:
    """Whether every call of a cell answered, within ``WRONG_DEG`` of the reference."""
    return all(r[2] is not None and r[2] < 60.0 * WRONG_DEG for r in rows)


def verdict(rows: list) -> str:
    """The centre offsets (arcmin) of a cell's calls: their largest; "not solved" and "wrong"
    (``WRONG_DEG`` or more off) with their counts."""
    offsets = [r[2] for r in rows]
    missed = sum(o is None for o in offsets)
    wrong = sum(o is not None and o >= 60.0 * WRONG_DEG for o in offsets)
    if missed == len(offsets):
        return "not solved"
    worst = max(o for o in offsets if o is not None)
    return (f"{worst:.1f}′" + (f", {missed} of {len(offsets)} not solved" if missed else "")
            + (f", {wrong} wrong" if wrong else ""))  # fmt: skip


def report(samples, helps, cold, split, files, refs, absent, args, load, seconds) -> str:
    tools = ("solve-field", "starnav-solve-field", "starnav-astap")
    lines = [
        f"Each command a new process, timed end to end; {args.repeats} round(s) after one "
        "warm-up call of each (machine code and tables cached, index files in the page "
        "cache). Seconds median (min); in brackets the largest offset of the answer's field "
        "centre from astrometry.net's reference (arcmin). Hinted: the position 2° off, "
        "searched within 5°, the width ±10 %.",
        "",
        *table_head("image", "MP", "width °", "call", *[f"{t} s" for t in tools], "faster"),
    ]
    faster = {(kind, tool): 0 for kind in ("hinted", "blind") for tool in tools[1:]}
    for name in files:
        ref = refs[name]
        mp = ref["width"] * ref["height"] / 1e6
        for kind in ("hinted", "blind"):
            cells, medians = [], {}
            for tool in tools:
                rows = samples[(name, kind, tool)]
                medians[tool] = float(np.median([r[0] for r in rows]))
                cells.append(f"{spread([r[0] for r in rows])} [{verdict(rows)}]")
            ok = {tool: solved(samples[(name, kind, tool)]) for tool in tools}
            for tool in tools[1:]:
                faster[(kind, tool)] += ok[tool] and medians[tool] < medians["solve-field"]
            ours = [medians[t] for t in tools[1:] if ok[t]]
            ratio = f"x{medians['solve-field'] / min(ours):.2f}" if ok[tools[0]] and ours else "—"
            lines.append(table_row(name, f"{mp:.2f}", f"{ref['fov_deg']:.1f}", kind, *cells,
                                   ratio))  # fmt: skip
    rss = {t: [r[1] for k, rows in samples.items() if k[2] == t for r in rows] for t in tools}
    lines += [
        "",
        "faster: solve-field's median over the faster drop-in's, where both solved (every "
        f"call within {WRONG_DEG:g}° of the reference). Solved and faster than `solve-field` "
        f"(medians) on the {len(files)} images: "
        + "; ".join(f"`{tool}` {n} {kind}" for (kind, tool), n in faster.items())
        + ". Peak resident memory, median over all calls: "
        + ", ".join(f"{t} {np.median(rss[t]):.0f} MB" for t in tools)
        + ".",
        "",
        *table_head("start-up", "wall s, median (min)"),
        *[table_row(f"`{name}`", spread(v, 3)) for name, v in helps.items()],
        "",
        f"Where one hinted `starnav-solve-field` call on {split[0]} spends its time (a process "
        f"run with `python -X importtime`, which slows imports): {split[1]['wall_s']:.2f} s "
        f"wall, {split[1]['cpu_s']:.2f} s CPU; of which imports, by package (ms, each "
        "module's own time): "
        + ", ".join(f"{k} {split[1][k]:.0f}" for k in (*GROUPS, "other"))
        + f" (together {sum(split[1][k] for k in (*GROUPS, 'other')) / 1e3:.2f} s; numba's "
        "CPU target, readied on the first kernel call, imports most of its own and "
        "scipy.linalg's).",
    ]
    if cold is not None:
        lines += [
            "",
            f"A new installation's first call (`starnav-solve-field`, hinted, on {cold[2]}, "
            f"the cache empty: machine code compiled, tables built): {cold[0]:.0f} s"
            + (f' (it says: "{cold[1].strip()}")' if cold[1] else "")
            + ".",
        ]
    if absent:
        lines += ["", f"Absent from {corpus_dir()}: {', '.join(absent)}."]
    version = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "astrometry.net"],
                             capture_output=True, text=True).stdout.strip() or "?"  # fmt: skip
    lines += [
        "",
        f"solve-field: Debian astrometry.net {version}, index files tycho2 07-19 in "
        f"/usr/share/astrometry. {machine(load, load_at_end=True)}; "
        f"`python benchmarks/speed/dropin_vs_solve_field.py --repeats {args.repeats}"
        f"{' --quick' if args.quick else ''}`, {seconds:.0f} s.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", metavar="FILE", help="reference.json image names")
    parser.add_argument("--repeats", type=int, default=3, help="timed rounds (default 3)")
    parser.add_argument(
        "--quick", action="store_true", help="two images, one round, no cold call; print only"
    )
    parser.add_argument("--no-cold", action="store_true", help="skip the empty-cache call")
    parser.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = parser.parse_args()
    if args.quick:
        args.repeats, args.no_cold, args.out = 1, True, "-"
    if shutil.which(SOLVE_FIELD) is None:
        raise SystemExit("solve-field is not installed (Debian: apt-get install astrometry.net "
                         "astrometry-data-tycho2-07 ... -10-19)")  # fmt: skip
    refs = json.loads(REFERENCE.read_text())["images"]
    names = args.files or default_images(refs)
    unknown = [n for n in names if n not in refs or not refs[n].get("solved_by_reference")]
    if unknown:
        raise SystemExit(f"not solved by astrometry.net in reference.json: {', '.join(unknown)}")
    files = {n: corpus_dir() / n for n in names if (corpus_dir() / n).is_file()}
    absent = [n for n in names if n not in files]
    if args.quick:
        files, absent = dict(list(files.items())[:2]), []
    if not files:
        raise SystemExit(f"none of the images is in {corpus_dir()}")
    load, t0 = os.getloadavg()[0], time.time()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        helps = measure_help(args.repeats)
        samples = measure_calls(files, refs, args.repeats, folder)
        # the first image every hinted starnav-solve-field call solved (else the first)
        first = next((n for n in files if solved(samples[(n, "hinted", "starnav-solve-field")])),
                     next(iter(files)))  # fmt: skip
        split = (first, breakdown(files[first], refs[first], folder))
        cold = None
        if not args.no_cold:
            cold = (*measure_cold(first, files[first], refs[first], folder), first)
    text = report(samples, helps, cold, split, files, refs, absent, args, load, time.time() - t0)
    if args.out != "-":
        replace_block(args.out, BLOCK, text, missing="## Drop-in calls against solve-field")
    print(text)


if __name__ == "__main__":
    main()
