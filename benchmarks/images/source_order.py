"""Source lists in any order: the real photographs' detections solved as x, y lists sorted
by brightness, in detection order and shuffled, blind and with a client's hints, for
docs/dropin.md ("Source lists in any order").

    nice python benchmarks/images/source_order.py [--budget 10] [--write]

Every image of ``$STARNAV_REAL_CORPUS`` (else ``../shared/data/real``) that astrometry.net
solved (tests/data/real/reference.json) is read and its stars detected (``detect_stars``,
every detection, as image2xy or SExtractor list them); the list (FITS pixels) is then solved
by ``solve_plate``, ``--budget`` seconds each, four ways: brightest first with its flux
column; in detection order (rows by y) with the flux column (read_xylist's case: sorted by
it); in detection order with no brightness; shuffled (seed 1) with no brightness. Each with
no hint (``HINTS`` "blind"); brightest first and the two without brightness also with the
scale hinted (the width within ±10 % of astrometry.net's, as N.I.N.A. and solve-field's
-L/-H send it: "scale") and with the scale and a position 2° from astrometry.net's centre,
searched within 5° ("scale + position"). A solve is scored by the image centre against
astrometry.net's: correct within 0.1°, wrong 0.5° or more off. Prints the table;
``--write`` puts it in docs/dropin.md.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, SHARED, machine, replace_block, table_head, table_row
from starnav.detect.read import read_image
from starnav.detect.stars import detect_stars
from starnav.pipeline.plate import PlateHints, XYList, solve_plate

REFERENCE = Path(__file__).resolve().parents[2] / "tests" / "data" / "real" / "reference.json"
ORDERS = ("brightest first", "detection order + flux", "detection order", "shuffled")
HINTS = ("blind", "scale", "scale + position")
# (order, hints) solved: every order blind, those of interest with hints
RUNS = [(o, "blind") for o in ORDERS] + [
    (o, h) for h in HINTS[1:] for o in (ORDERS[0], ORDERS[2], ORDERS[3])
]
SCALE_ERROR = 0.10  # the width hinted within ±10 %
POSITION_OFF_DEG, POSITION_RADIUS_DEG = 2.0, 5.0
CORRECT_DEG, WRONG_DEG = 0.1, 0.5


def corpus() -> Path:
    return Path(os.environ.get("STARNAV_REAL_CORPUS") or SHARED / "real")


def lists(x, y, flux, width, height) -> dict[str, XYList]:
    """The four lists of one image's detections (``ORDERS``)."""
    by_y = np.argsort(y, kind="stable")
    shuffled = np.random.default_rng(1).permutation(len(x))
    return {
        ORDERS[0]: XYList.make(x, y, width, height, sort_values=flux, sort_name="FLUX"),
        ORDERS[1]: XYList.make(
            x[by_y], y[by_y], width, height, sort_values=flux[by_y], sort_name="FLUX"
        ),
        ORDERS[2]: XYList.make(x[by_y], y[by_y], width, height),
        ORDERS[3]: XYList.make(x[shuffled], y[shuffled], width, height),
    }


def hints_for(kind: str, ref: dict) -> PlateHints:
    """The client's hints of a run: none, the width within ``SCALE_ERROR``, or that and a
    position ``POSITION_OFF_DEG`` north of astrometry.net's centre (south above Dec 80°)."""
    if kind == "blind":
        return PlateHints()
    fov = (ref["fov_deg"] * (1.0 - SCALE_ERROR), ref["fov_deg"] * (1.0 + SCALE_ERROR))
    if kind == "scale":
        return PlateHints(fov_range_deg=fov)
    step = POSITION_OFF_DEG if ref["dec_deg"] < 80.0 else -POSITION_OFF_DEG
    return PlateHints(fov_range_deg=fov, ra_deg=ref["ra_deg"], dec_deg=ref["dec_deg"] + step,
                      radius_deg=POSITION_RADIUS_DEG)  # fmt: skip


def run_name(order: str, hints: str) -> str:
    return order if hints == "blind" else f"{order}, {hints}"


def offset_deg(ra1, dec1, ra2, dec2) -> float:
    r1, d1, r2, d2 = (math.radians(v) for v in (ra1, dec1, ra2, dec2))
    c = math.sin(d1) * math.sin(d2) + math.cos(d1) * math.cos(d2) * math.cos(r1 - r2)
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def run(budget_s: float) -> tuple[list[dict], str]:
    refs = json.loads(REFERENCE.read_text())["images"]
    load = os.getloadavg()[0]
    rows = []
    for name in sorted(refs):
        path = corpus() / name
        if not path.is_file() or not refs[name].get("solved_by_reference"):
            continue
        pixels = read_image(path)
        found = detect_stars(pixels)
        height, width = pixels.shape
        x, y = found.xy[:, 0] + 0.5, found.xy[:, 1] + 0.5
        row = {"file": name, "n": len(x)}
        sources = lists(x, y, found.flux, width, height)
        for order, kind in RUNS:
            source = sources[order]
            t0 = time.perf_counter()
            res = solve_plate(source, hints_for(kind, refs[name]), time_budget_s=budget_s)
            seconds = time.perf_counter() - t0
            verdict = "none"
            if res.plate is not None:
                off = offset_deg(res.plate.ra_deg, res.plate.dec_deg, refs[name]["ra_deg"],
                                 refs[name]["dec_deg"])  # fmt: skip
                verdict = (
                    "correct" if off < CORRECT_DEG else "wrong" if off >= WRONG_DEG else "inexact"
                )
            row[run_name(order, kind)] = (verdict, seconds)
            print(f"{name} {len(x)} {run_name(order, kind)}: {verdict} {seconds:.2f} s",
                  flush=True)  # fmt: skip
        rows.append(row)
    return rows, machine(load, load_at_end=True)


def table(rows: list[dict], machine_line: str, budget_s: float) -> str:
    out = [f"Machine: {machine_line}. Budget {budget_s:g} s a solve; {len(rows)} "
           f"photographs; scale: the width within ±{100 * SCALE_ERROR:g} %; position: "
           f"{POSITION_OFF_DEG:g}° off, searched within {POSITION_RADIUS_DEG:g}°.", ""]  # fmt: skip
    names = [run_name(o, h) for o, h in RUNS]
    out += table_head("order, hints", "solved (correct)", "wrong", "median time, s",
                      "max time, s")  # fmt: skip
    for order in names:
        cells = [r[order] for r in rows]
        correct = sum(v == "correct" for v, _ in cells)
        solved = sum(v != "none" for v, _ in cells)
        wrong = sum(v == "wrong" for v, _ in cells)
        times = [s for _, s in cells]
        out.append(table_row(order, f"{solved} of {len(cells)} ({correct})", wrong,
                             f"{np.median(times):.2f}", f"{max(times):.2f}"))  # fmt: skip
    out += ["", "Per photograph (detections; the verdicts in the order above):", ""]
    out += table_head("file", "detections", *names)
    for r in rows:
        out.append(table_row(r["file"], r["n"], *(f"{r[o][0]} {r[o][1]:.1f} s" for o in names)))
    return "\n".join(out)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--budget", type=float, default=10.0, help="seconds a solve (default 10)")
    p.add_argument("--write", action="store_true", help="write the table into docs/dropin.md")
    args = p.parse_args()
    rows, machine_line = run(args.budget)
    text = table(rows, machine_line, args.budget)
    print(text)
    if args.write:
        replace_block(DOCS / "dropin.md", "source-order", text)


if __name__ == "__main__":
    main()
