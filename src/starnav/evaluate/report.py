"""What an evaluation prints and draws: a markdown table, one CSV row per frame, a sky map."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import astuple, fields
from pathlib import Path

import numpy as np

from starnav.evaluate.runner import EvalConfig, FrameResult, OutcomeCounts, Summary
from starnav.evaluate.score import CORRECT_BORESIGHT_DEG, CORRECT_ROLL_DEG
from starnav.identify.options import describe_options
from starnav.pipeline import DEFAULT_MAX_FALSE_MATCH_PROBABILITY

TABLE_HEADER = (
    "| algorithm | frames | correct | wrong | none | correct % | correct % (>= 4 stars) "
    f"| of the correct: beyond {CORRECT_BORESIGHT_DEG:g}°/{CORRECT_ROLL_DEG:g}° "
    "| median ms | p95 ms | max ms | database MB |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def table_row(name: str, s: Summary) -> str:
    """One markdown row of ``TABLE_HEADER``."""
    return (
        f"| {name} | {s.frames} | {s.correct} | {s.wrong} | {s.none} | "
        f"{100 * s.correct_rate:.2f} | {100 * s.correct_rate_ge4:.2f} | {s.imprecise} | "
        f"{s.median_ms:.2f} | "
        f"{s.p95_ms:.2f} | {s.max_ms:.1f} | {s.db_bytes / 1e6:.1f} |"
    )


def describe(config: EvalConfig, sampling: str) -> str:
    """One line naming the camera (its lens model), the errors and the solver settings."""
    camera = config.make_camera()
    circle = getattr(camera, "image_circle_deg", None)
    lens = f"{camera.model} {camera.fov_deg:g}° / {camera.width}x{camera.height} px"
    if circle is not None:
        lens += f" (image circle {circle:g}°)"
    algo = config.algorithm
    if config.algorithm_options:
        algo += f" ({describe_options(dict(config.algorithm_options))})"
    return (
        f"{sampling}; {lens}, Hipparcos Hp <= "
        f"{config.mag_limit:g}; noise {config.noise_px:g} px, {config.false_stars} false stars, "
        f"{config.missing_frac:.0%} missing, magnitude noise {config.mag_noise:g}; "
        f"{algo}, sigma_px {config.solver_sigma_px:g}, seed {config.seed}" + _kinds_note(config)
    )


def _kinds_note(config: EvalConfig) -> str:
    note = ""
    if config.max_false_match_probability != DEFAULT_MAX_FALSE_MATCH_PROBABILITY:
        note += f", max false-match probability {config.max_false_match_probability:g}"
    if tuple(config.kinds) != ("true",):
        note += f"; frame kinds {', '.join(config.kinds)} in turn"
    return note


def breakdown_tables(summary: Summary) -> str:
    """Markdown tables of the outcomes by kind, and by true stars among the points."""

    def row(first: str, c: OutcomeCounts) -> str:
        return (
            f"| {first} | {c.frames} | {c.correct} | {c.wrong} | {c.none} | "
            f"{c.median_ms:.2f} | {c.p95_ms:.2f} |"
        )

    rule = "|---|---|---|---|---|---|---|"
    lines = ["| kind | frames | correct | wrong | none | median ms | p95 ms |", rule]
    lines += [row(c.kind, c) for c in summary.by_kind]
    if summary.by_true_stars:
        lines += [
            "",
            "| kind, true stars among the points | frames | correct | wrong | none "
            "| median ms | p95 ms |",
            rule,
        ]
        lines += [row(f"{c.kind}, {c.true_stars}", c) for c in summary.by_true_stars]
    return "\n".join(lines)


def markdown(config: EvalConfig, sampling: str, summary: Summary) -> str:
    """The evaluation as a short markdown report."""
    wrong_note = (
        f"{summary.wrong_ids} wrong star ids in solved frames"
        if summary.wrong_ids
        else "no wrong star ids"
    )
    return "\n".join(
        [
            describe(config, sampling),
            "",
            TABLE_HEADER,
            table_row(config.algorithm, summary),
            "",
            f"{summary.frames_ge4} frames have >= 4 real stars; {wrong_note}; "
            f"wall time {summary.wall_s:.1f} s.",
            "",
            breakdown_tables(summary),
        ]
    )


def write_frames_csv(results: Sequence[FrameResult], path: str | Path) -> None:
    """One row per frame, the fields of ``FrameResult`` (empty for None)."""
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([f.name for f in fields(FrameResult)])
        for r in results:
            writer.writerow(["" if v is None else v for v in astuple(r)])


def _sky_xy(ra_deg: np.ndarray, dec_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mollweide axes coordinates with RA growing to the left, as on the sky."""
    ra = np.radians((np.asarray(ra_deg) + 180.0) % 360.0 - 180.0)
    return -ra, np.radians(dec_deg)


def plot_sky_map(results: Sequence[FrameResult], path: str | Path, *, title: str = "") -> None:
    """Two Mollweide maps (ICRS, RA to the left): each boresight's outcome, and the number of
    catalog stars in view."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ra = np.array([r.ra_deg for r in results])
    dec = np.array([r.dec_deg for r in results])
    x, y = _sky_xy(ra, dec)
    outcome = np.array([r.outcome for r in results])
    n_view = np.array([r.n_in_view for r in results])
    size = max(1.0, min(12.0, 30000.0 / max(len(results), 1)))
    fig = plt.figure(figsize=(14, 4.6))
    ax = fig.add_subplot(1, 2, 1, projection="mollweide")
    m = outcome == "correct"
    ax.scatter(x[m], y[m], s=size, c="#9fd49f", lw=0, label=f"correct ({m.sum()})")
    m = outcome == "none"  # the few that matter are drawn larger, on top
    ax.scatter(x[m], y[m], s=3 * size + 6, c="black", lw=0, label=f"not solved ({m.sum()})")
    m = outcome == "wrong"
    ax.scatter(x[m], y[m], s=4 * size + 8, c="red", marker="x", label=f"wrong ({m.sum()})")
    ax.legend(loc="lower right", fontsize=8, markerscale=2, framealpha=0.9)
    ax.set_title("outcome per boresight")
    ax2 = fig.add_subplot(1, 2, 2, projection="mollweide")
    sc = ax2.scatter(x, y, s=size, c=n_view, cmap="viridis", lw=0)
    fig.colorbar(sc, ax=ax2, shrink=0.7, label="catalog stars in view")
    ax2.set_title("stars in view")
    for a in (ax, ax2):
        a.set_xticks(np.radians(np.arange(-150, 151, 60)))
        a.set_xticklabels([f"{(-d) % 360}°" for d in range(-150, 151, 60)], fontsize=7)
        a.grid(True, lw=0.3)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
