"""Every identification algorithm on the same simulated frames, and on the 2019 contest maps.

    python benchmarks/accuracy/evaluation.py        # all parts, into docs/evaluation.md
    python benchmarks/accuracy/evaluation.py --parts sweep --frames 300 --algorithms pyramid

Parts (each fills a marked block of docs/evaluation.md, see harness.replace_block):
- ``grid``: the issue's target scenario (12° / 512 px, Hp <= 6, 0.5 px noise, 2 false stars,
  10 % missing) on the published 7200-boresight grid (3° RA/Dec), every algorithm, all cores;
  the wall time is the whole run; also a sky map of the default algorithm.
- ``sweep``: ``--frames`` frames uniform on the sky per scenario, the same frames for every
  algorithm: noise 0 / 0.5 / 1 / 2 px, false stars 0 / 2 / 5, missing 0 / 10 / 30 %, each
  varied alone from the base (0.5 px, 2 false, 10 % missing), magnitude noise 0.75 throughout
  (the published magnitude error: it reorders the brightness list); and a figure of the
  correct rate against noise.
- ``contest``: each algorithm on the 8 contest maps (default solver settings, the contest
  catalog): points identified, points left without a catalog star, median time of 3 runs.

The solver is told sigma_px = the simulated noise (at least 0.1 px). Scoring: ``starnav
evaluate``'s own (``starnav.evaluate.score``): correct with the right parity within 0.05°
boresight and 0.5° roll or within 5 of the solution's own reported 1-sigma errors, wrong
beyond; none when the solver refuses.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, machine, replace_block, table_head
from starnav.api import solve_stars
from starnav.catalog import load_csv
from starnav.evaluate import EvalConfig, grid_boresights, run_evaluation, summarize
from starnav.evaluate.report import TABLE_HEADER, plot_sky_map, table_row
from starnav.evaluate.runner import prepare
from starnav.evaluate.sampling import uniform_boresights
from starnav.identify import ALGORITHMS, DEFAULT_ALGORITHM
from starnav.starlist import read_star_csv

DOC = DOCS / "evaluation.md"
CONTEST = ROOT.parent / "shared" / "data" / "contest2019"
TARGET = EvalConfig(noise_px=0.5, false_stars=2, missing_frac=0.1, mag_noise=0.0, seed=2026)
BASE = replace(TARGET, mag_noise=0.75)
SWEEP = [
    ("noise", "noise_px", [0.0, 0.5, 1.0, 2.0]),
    ("false stars", "false_stars", [0, 2, 5]),
    ("missing", "missing_frac", [0.0, 0.1, 0.3]),
]


def _header(columns: str) -> str:
    """A markdown header line and its rule (``columns`` like "| a | b |")."""
    return "\n".join(table_head(*(c.strip() for c in columns.strip("|").split("|"))))


def _run(config, boresights, workers, desc):
    db_bytes = prepare(config)
    t0 = time.perf_counter()
    with tqdm(total=len(boresights), desc=desc, file=sys.stderr, leave=False) as bar:
        results = run_evaluation(config, boresights, workers=workers, progress=bar.update)
    return summarize(results, db_bytes=db_bytes, wall_s=time.perf_counter() - t0), results


def part_grid(algorithms, workers) -> tuple[str, list[dict]]:
    boresights = grid_boresights(3.0, seed=TARGET.seed)
    rows, out, notes = [], [], []
    for name in algorithms:
        config = replace(TARGET, algorithm=name)
        summary, results = _run(config, boresights, workers, f"grid {name}")
        rows.append(table_row(name, summary) + f" {summary.wall_s:.0f} |")
        wrong = [r.index for r in results if r.outcome == "wrong"]
        few = [r for r in results if r.n_true <= 5]
        few_none = sum(r.outcome == "none" for r in few)
        notes.append(
            f"{name}: {few_none} of its {summary.none} unsolved frames have <= 5 real stars "
            f"(the grid has {len(few)} such frames)"
        )
        out.append({"algorithm": name, **summary.to_dict(), "wrong_frames": wrong})
        if name == DEFAULT_ALGORITHM:
            plot_sky_map(
                results,
                DOCS / "evaluation_skymap.png",
                title=f"{name}: 7200 boresights, 12°/512 px, 0.5 px noise, 2 false stars, "
                "10 % missing",
            )
    header = _header(TABLE_HEADER.split("\n")[0] + " wall s |")
    text = "\n".join(
        [
            f"7200 boresights (3° grid), 12° / 512 px, Hipparcos Hp <= 6, 0.5 px noise, 2 false "
            f"stars, 10 % missing, sigma_px 0.5, seed {TARGET.seed}; {workers} worker processes "
            f"on {machine()}.",
            "",
            header,
            *rows,
            "",
            "Where the unsolved frames are: " + "; ".join(notes) + ".",
        ]
    )
    return text, out


def part_sweep(algorithms, frames, workers) -> tuple[str, list[dict]]:
    boresights = uniform_boresights(frames, seed=BASE.seed)
    out, blocks = [], []
    for label, field, values in SWEEP:
        blocks += [
            f"**{label}** (the others at the base)",
            "",
            _header(f"| {field} " + TABLE_HEADER.split("\n")[0]),
        ]
        for value in values:
            for name in algorithms:
                config = replace(BASE, algorithm=name, **{field: value})
                summary, results = _run(config, boresights, workers, f"{field}={value} {name}")
                wrong = [r.index for r in results if r.outcome == "wrong"]
                out.append(
                    {
                        "vary": field,
                        "value": value,
                        "algorithm": name,
                        **summary.to_dict(),
                        "wrong_frames": wrong,
                    }
                )
                blocks.append(f"| {value:g} " + table_row(name, summary))
        blocks.append("")
    text = "\n".join(
        [
            f"{frames} frames uniform on the sky per row (the same frames for every algorithm), "
            f"12° / 512 px, Hp <= 6; base: 0.5 px noise, 2 false stars, 10 % missing; magnitude "
            f"noise 0.75 in every row; {workers} worker processes on {machine()}.",
            "",
            *blocks,
        ]
    )
    return text, out


def plot_noise(sweep: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for name in dict.fromkeys(r["algorithm"] for r in sweep):
        rows = [r for r in sweep if r["algorithm"] == name and r["vary"] == "noise_px"]
        ax.plot(
            [r["value"] for r in rows],
            [100 * r["correct_rate"] for r in rows],
            marker="o",
            label=name,
        )
    ax.set_xlabel("centroid noise, 1σ (px)")
    ax.set_ylabel("frames solved correctly (%)")
    ax.set_title("12° / 512 px, 2 false stars, 10 % missing, mag noise 0.75", fontsize=9)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def part_contest(algorithms) -> tuple[str, list[dict]]:
    catalog = load_csv(CONTEST / "catalog.csv")
    maps = [read_star_csv(CONTEST / "images" / f"xingtu0{n}.csv") for n in range(1, 9)]
    rows, out = [], []
    for name in algorithms:
        cells, total_id, total_null, times = [], 0, 0, []
        for n, stars in enumerate(maps, start=1):
            width, fov = (512, 12.0) if n <= 6 else (1024, 20.0)
            runs = [
                solve_stars(stars.xy, width=width, fov_deg=fov, catalog=catalog, algorithm=name)
                for _ in range(3)
            ]
            s = runs[-1].solution
            ms = float(np.median([r.time_ms for r in runs]))
            times.append(ms)
            if s is None:
                cells.append(f"refused ({ms:.0f} ms)")
                out.append({"algorithm": name, "map": n, "solved": False, "ms": ms})
                continue
            total_id += s.n_matched
            total_null += len(stars.xy) - s.n_matched
            cells.append(f"{s.n_matched}/{len(stars.xy)} ({ms:.1f} ms)")
            out.append(
                {
                    "algorithm": name,
                    "map": n,
                    "solved": True,
                    "identified": s.n_matched,
                    "points": len(stars.xy),
                    "ra_deg": s.ra_deg,
                    "dec_deg": s.dec_deg,
                    "ms": ms,
                }
            )
        rows.append(
            f"| {name} | " + " | ".join(cells) + f" | {total_id} | {total_null} | "
            f"{np.median(times):.1f} |"
        )
    header = _header(
        "| algorithm | "
        + " | ".join(f"map {n}" for n in range(1, 9))
        + " | points identified | points left null | median ms |"
    )
    text = "\n".join(
        [
            "Cells: points identified / points in the map (median time of 3 runs). Default "
            "settings (sigma_px 1), the contest catalog, maps 1-6 12° / 512 px, 7-8 20° / "
            f"1024 px. {machine()}.",
            "",
            header,
            *rows,
        ]
    )
    return text, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", default=["grid", "sweep", "contest"])
    parser.add_argument("--algorithms", nargs="+", default=list(ALGORITHMS))
    parser.add_argument("--frames", type=int, default=500, help="frames per sweep row")
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args()
    results = {}
    for part in args.parts:
        t0 = time.time()
        if part == "grid":
            text, data = part_grid(args.algorithms, args.workers)
        elif part == "sweep":
            text, data = part_sweep(args.algorithms, args.frames, args.workers)
            if not args.no_write:
                plot_noise(data, DOCS / "evaluation_noise.png")
        elif part == "contest":
            text, data = part_contest(args.algorithms)
        else:
            raise SystemExit(f"unknown part {part!r}")
        text += (
            f"\n\n`python benchmarks/accuracy/evaluation.py --parts {part}`: "
            f"{time.time() - t0:.0f} s."
        )
        print(text + "\n")
        results[part] = data
        if not args.no_write:
            replace_block(DOC, part, text)
            if part == "grid":  # the table also heads docs/accuracy.md
                table = "\n".join(line for line in text.splitlines() if line.startswith("|"))
                replace_block(DOCS / "accuracy.md", "grid-summary", table)
            (DOCS / f"evaluation_{part}.json").write_text(json.dumps(data, indent=1))


if __name__ == "__main__":
    main()
