"""Is the claimed false-match probability calibrated? Adversarial frames, relaxed thresholds.

    python benchmarks/accuracy/false_match_calibration.py [--frames 600] [--workers N]

(``benchmarks/images/calibration.py`` is the camera calibration's; this is the verification
statistic's.) The evaluation (``starnav.evaluate``, the path of ``starnav evaluate``) runs on
``--frames`` boresights uniform on the sky, the frame kinds random, scrambled, mirrored and
fov-off in turn (``starnav.evaluate.kinds``: no right answer exists for the first, hardly any
for the second, the last two have one only under the mirror / with the focal length the
solver is not told), once per ``--thresholds`` value of ``max_false_match_probability``
(relaxed from the default 1e-4 so that the solver answers where it would refuse). The scene
is the issue's: 12° / 512 px pinhole, Hp <= 6, 0.5 px noise, 2 false stars, 10 % missing.

Prints markdown (for docs/verification.md): per run, the outcomes by kind, and a table of
the answers by claimed false-match probability (decades from 1e-8 to 1): how many, how many
wrong. Draws ``--plot`` (default docs/images/calibration.png): for each threshold α, the
fraction of the frames not answered right (wrong or refused: those where any answer given
was wrong) that got a wrong answer claiming p <= α, against α, log-log, with the diagonal: a
calibrated statistic stays on or below it. Zero counts are drawn as 95 % Poisson upper
limits (3 / frames).
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, table_head
from starnav.evaluate import EvalConfig, evaluate, uniform_boresights
from starnav.evaluate.kinds import parse_kinds
from starnav.evaluate.report import breakdown_tables, describe, write_frames_csv

PLOT = DOCS / "images" / "calibration.png"
KINDS = "random,scrambled,mirrored,fov-off"
DECADES = np.logspace(-8, 0, 9)  # bin edges of the claimed probability
POISSON_95 = -np.log(0.05)  # upper limit on the mean of a count of 0 (95 %)


def bins_table(p: np.ndarray, wrong: np.ndarray) -> str:
    """Markdown rows: answers and wrong answers by claimed probability decade."""
    lines = table_head("claimed false-match probability", "answers", "wrong", "wrong fraction")
    edges = [0.0, *DECADES]
    for lo, hi in itertools.pairwise(edges):
        m = (p >= lo) & (p < hi) if hi < 1.0 else (p >= lo)
        label = f"< {hi:.0e}" if lo == 0.0 else f"{lo:.0e} - {hi:.0e}"
        n, w = int(m.sum()), int((m & wrong).sum())
        lines.append(f"| {label} | {n} | {w} | {w / n:.3g} |" if n else f"| {label} | 0 | 0 | |")
    return "\n".join(lines)


def curve(results, alphas: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Wrong answers claiming p <= α, per α, their fraction of the frames not answered right,
    and that number of frames."""
    not_right = [r for r in results if r.outcome != "correct"]
    p = np.array([r.false_match_probability for r in not_right if r.outcome == "wrong"])
    counts = np.array([int(np.sum(p <= a)) for a in alphas])
    n = len(not_right)
    return counts, counts / max(n, 1), n


def plot(runs, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    alphas = np.logspace(-8, 0, 33)
    fig, ax = plt.subplots(figsize=(5.6, 5.0))
    ax.plot([1e-8, 1.0], [1e-8, 1.0], color="0.5", lw=1, ls="--", label="claimed = observed")
    for (threshold, results), colour in zip(runs, ("C0", "C1", "C2", "C3"), strict=False):
        counts, frac, n = curve(results, alphas)
        ok = counts > 0
        ax.plot(alphas[ok], frac[ok], "o-", ms=3, color=colour, label=f"threshold {threshold:g}")
        if (~ok).any():
            upper = np.full((~ok).sum(), POISSON_95 / max(n, 1))
            ax.plot(alphas[~ok], upper, "v", ms=4, mfc="none", color=colour)
        ax.axvline(threshold, color=colour, lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(1e-8, 1.0)
    ax.set_ylim(1e-6, 1.0)
    ax.set_xlabel("claimed false-match probability threshold α")
    ax.set_ylabel("fraction of frames not answered right\nwith a wrong answer claiming p ≤ α")
    ax.set_title("adversarial frames (▽: 95 % upper limit, 0 wrong)", fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, which="major", lw=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600, help="per threshold (default 600)")
    parser.add_argument("--thresholds", type=float, nargs="+", default=[0.5, 1e-2])
    parser.add_argument("--kinds", default=KINDS)
    parser.add_argument("--seed", type=int, default=17)
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--dask", metavar="ADDRESS", help="a Dask scheduler, or 'local'")
    parser.add_argument("--plot", type=Path, default=PLOT)
    parser.add_argument("--frames-csv", type=Path, help="one row per frame (all runs)")
    args = parser.parse_args()
    kinds = parse_kinds(args.kinds)
    boresights = uniform_boresights(args.frames, seed=args.seed)
    sampling = f"{len(boresights)} boresights uniform on the sphere"
    runs, parts, every = [], [], []
    t0 = time.perf_counter()
    for threshold in args.thresholds:
        config = EvalConfig(
            noise_px=0.5,
            false_stars=2,
            missing_frac=0.1,
            seed=args.seed,
            kinds=kinds,
            max_false_match_probability=threshold,
        )
        summary, results = evaluate(
            config, boresights, workers=args.workers, dask_address=args.dask
        )
        runs.append((threshold, results))
        every += results
        answered = [r for r in results if r.outcome != "none"]
        p = np.array([r.false_match_probability for r in answered])
        wrong = np.array([r.outcome == "wrong" for r in answered], dtype=bool)
        parts += [
            f"### max false-match probability {threshold:g}",
            "",
            describe(config, sampling) + f"; wall time {summary.wall_s:.0f} s.",
            "",
            breakdown_tables(summary),
            "",
            bins_table(p, wrong),
            "",
        ]
    plot(runs, args.plot)
    if args.frames_csv:
        write_frames_csv(every, args.frames_csv)
    command = "python benchmarks/accuracy/false_match_calibration.py"
    if args.frames != 600:
        command += f" --frames {args.frames}"
    parts.append(
        f"{time.perf_counter() - t0:.0f} s in all; {machine()}; `{command}`; "
        f"figure {args.plot.name}."
    )
    print("\n".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
