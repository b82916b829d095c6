"""Faint and double stars of a 6° star tracker: the deep stage (``starnav.pipeline.deep``)
against the bright identification alone, scored with the ESA Kelvins "Star Trackers: First
Contact" metric. The table goes into the ``deep-stars`` block of docs/deep_stars.md (only
with the defaults; ``--no-doc`` prints it only).

    python benchmarks/accuracy/deep_stars.py [--scenes 200] [--seed 1] [--no-doc]

Scenes: a 1024 x 1024 px pinhole camera of 6° horizontal FOV; the stars of the embedded
Hipparcos catalog to Hp 10.3 (``simulate_frame``), 0.5 px centroid noise, 3 false stars,
10 % of the stars missing. The solver identifies on Hipparcos to ``--bright-mag`` (8, the
pair table) and, with the deep stage, matches every point to Hipparcos to ``--deep-mag``
(12: 117 325 stars, whose pair table the solver refuses at 6°). Told centroid sigma 0.5 px.

Doubles: a fifth of the scenes are centred (within 1°) on a pair of catalog stars 1-2 px
apart (both to Hp 10.3: two points, whose ids must not swap), a fifth on a pair under 1 px
apart (Hp 10.3); in every scene two stars closer than ``UNRESOLVED_PX`` are one point at
their flux-weighted photocentre (plus the noise), whose true id is the brighter's.

The points carry their brightness (the simulator's flux, 10**(-0.4 Hp)); the last rows
solve the same scenes without it (positions alone, as the contest maps come).

Score per scene: max((c - 2w) / max(t, 1), -1), c the points given their true id, w the
points given another (``evaluate.runner._wrong_ids``'s rule: a star confused with a catalog
neighbour closer than max(1 px, 3 noise sigma) is not wrong, and counted as neither here;
a false star given an id is wrong), t the true stars among the points. Swapped pairs: two
points each given the other's star (forgiven when the stars are that close; counted apart).
Unresolved doubles: points made of two stars; flagged: points the stage flagged ``double``
(two or more free catalog stars to Hp 12 in the match circle, most with an Hp 10.3-12 star
the scene does not show). Time: the solve's
``time_ms`` (identification, fit and the deep stage), on whatever this machine shares.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, replace_block, table_head
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.evaluate.runner import _wrong_ids
from starnav.geometry import attitude_from_radec_roll
from starnav.pipeline.solver import Solver, SolveSettings
from starnav.simulate import FALSE_STAR_ID, SimulatedFrame, simulate_frame
from starnav.starlist import check_star_list

FOV_DEG, SIZE_PX = 6.0, 1024
SCENE_MAG = 10.3  # the stars the camera sees
NOISE_PX, FALSE_STARS, MISSING = 0.5, 3, 0.1
UNRESOLVED_PX = 1.0  # two stars closer than this are one point


def close_pairs(catalog, camera, lo_px: float, hi_px: float) -> np.ndarray:
    """Rows (k, 2) of catalog stars ``lo_px``-``hi_px`` apart at the camera's scale."""
    from scipy.spatial import cKDTree

    tree = cKDTree(catalog.vectors)
    pairs = tree.query_pairs(hi_px / camera.scale_px_per_rad, output_type="ndarray")
    d = np.linalg.norm(catalog.vectors[pairs[:, 0]] - catalog.vectors[pairs[:, 1]], axis=1)
    return pairs[d * camera.scale_px_per_rad >= lo_px]


def merge_unresolved(frame: SimulatedFrame) -> SimulatedFrame:
    """Points closer than ``UNRESOLVED_PX`` made one, at the flux-weighted photocentre of
    their (noisy) positions, with the brighter's id and the summed flux."""
    xy, mag, ids = frame.xy.copy(), frame.mag.copy(), frame.true_id.copy()
    keep = np.ones(len(xy), dtype=bool)
    for i in range(len(xy)):
        for j in range(i + 1, len(xy)):
            if not (keep[i] and keep[j]) or FALSE_STAR_ID in (ids[i], ids[j]):
                continue
            if np.hypot(*(xy[i] - xy[j])) >= UNRESOLVED_PX:
                continue
            fi, fj = 10 ** (-0.4 * mag[i]), 10 ** (-0.4 * mag[j])
            centre = (fi * xy[i] + fj * xy[j]) / (fi + fj)
            b, f = (i, j) if mag[i] <= mag[j] else (j, i)
            xy[b] = centre  # of the noisy positions: noise 0.35-0.5 px
            mag[b] = -2.5 * math.log10(fi + fj)
            keep[f] = False
    return SimulatedFrame(
        xy[keep], mag[keep], ids[keep], frame.R_cam_from_icrs, frame.camera, frame.n_in_view
    )


def scenes(
    n: int,
    seed: int,
    deep,
    camera,
    *,
    noise_px: float = NOISE_PX,
    false_stars: int = FALSE_STARS,
    missing_frac: float = MISSING,
    mag_noise: float = 0.0,
) -> list[tuple[str, SimulatedFrame, int]]:
    """``n`` scenes (kind, frame, points merged into unresolved doubles): a fifth on
    resolved close pairs, a fifth on unresolved ones, the rest uniform on the sky; the
    stars to ``SCENE_MAG`` with ``noise_px`` centroid noise, ``false_stars``, a
    ``missing_frac`` of the stars dropped and ``mag_noise`` (mag, 1 sigma) on the
    brightness."""
    rng = np.random.default_rng(seed)
    seen = deep.brighter_than(SCENE_MAG)
    resolved = close_pairs(seen, camera, 1.0, 2.0)
    unresolved = close_pairs(seen, camera, 0.0, 1.0)
    out = []
    for k in range(n):
        kind = ("pair 1-2 px", "pair < 1 px", "random", "random", "random")[k % 5]
        if kind == "random":
            v = rng.normal(size=3)
        else:
            pairs = resolved if kind == "pair 1-2 px" else unresolved
            v = seen.vectors[pairs[rng.integers(len(pairs)), 0]] + rng.normal(0, 0.01, 3)
        v /= np.linalg.norm(v)
        ra, dec = math.degrees(math.atan2(v[1], v[0])) % 360.0, math.degrees(math.asin(v[2]))
        R = attitude_from_radec_roll(ra, dec, float(rng.uniform(0, 360)), 1)
        frame = simulate_frame(
            seen,
            camera,
            R_cam_from_icrs=R,
            noise_px=noise_px,
            false_stars=false_stars,
            missing_frac=missing_frac,
            mag_noise=mag_noise,
            seed=rng,
        )
        merged = merge_unresolved(frame)
        out.append((kind, merged, len(frame.xy) - len(merged.xy)))
    return out


def swapped_pairs(ids: np.ndarray, true: np.ndarray) -> int:
    """Pairs of points each given the other's true id."""
    given = {int(i): n for n, i in enumerate(ids) if i != -1}
    return sum(
        1
        for p, i in enumerate(ids)
        if i != -1 and i != true[p] and true[p] != FALSE_STAR_ID
        and given.get(int(true[p]), -1) > p and true[given[int(true[p])]] == i
    )  # fmt: skip


def score(
    ids: np.ndarray, frame: SimulatedFrame, deep, camera, noise_px: float = NOISE_PX
) -> tuple[int, int, int, int]:
    """(correct, wrong, forgiven, true stars) of one scene's ids."""
    true = frame.true_id
    t = int(np.sum(true != FALSE_STAR_ID))
    c = int(np.sum((ids != -1) & (ids == true)))
    w = _wrong_ids(ids, true, deep, camera, noise_px)
    forgiven = int(np.sum((ids != -1) & (ids != true))) - w
    return c, w, forgiven, t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bright-mag", type=float, default=8.0)
    ap.add_argument("--deep-mag", type=float, default=12.0)
    ap.add_argument("--no-doc", action="store_true", help="print the table only")
    args = ap.parse_args()
    camera = Camera.from_fov(FOV_DEG, SIZE_PX, SIZE_PX)
    deep = load_catalog(None, mag_limit=args.deep_mag)
    bright = load_catalog(None, mag_limit=args.bright_mag)
    frames = scenes(args.scenes, args.seed, deep, camera)
    with_deep = SolveSettings(sigma_px=NOISE_PX, deep_catalog=deep)
    configs = {
        f"bright Hp {args.bright_mag:g} only": (SolveSettings(sigma_px=NOISE_PX), True),
        f"bright Hp {args.bright_mag:g} + deep Hp {args.deep_mag:g}": (with_deep, True),
        f"bright Hp {args.bright_mag:g} + deep Hp {args.deep_mag:g}, no brightness": (
            with_deep,
            False,
        ),
    }
    rows, notes = [], []
    for name, (settings, brightness) in configs.items():
        solver = Solver(camera, bright, settings=settings)
        first = frames[0][1]  # loads the machine code: no scene's time
        solver.solve(check_star_list(first.xy, width=SIZE_PX, height=SIZE_PX))
        per_kind: dict[str, list] = {}
        probability, right = [], []  # of every matched point, for the calibration line
        t0 = time.perf_counter()
        for kind, frame, merged in frames:
            stars = check_star_list(
                frame.xy,
                width=SIZE_PX,
                height=SIZE_PX,
                brightness=frame.brightness if brightness else None,
            )
            result = solver.solve(stars)
            s = result.solution
            ids = np.full(len(frame.xy), -1) if s is None else s.star_table.catalog_id
            c, w, f, t = score(ids, frame, deep, camera)
            table = None if s is None else s.star_table
            if table is not None and table.deep:
                matched = ids != -1
                probability.extend(table.match_probability[matched])
                right.extend(ids[matched] == frame.true_id[matched])
            flagged = 0 if table is None or table.double is None else int(table.double.sum())
            entry = (
                max((c - 2 * w) / max(t, 1), -1.0),
                c,
                w,
                f,
                t,
                result.time_ms,
                s is not None,
                merged,
                flagged,
                swapped_pairs(ids, frame.true_id),
            )
            per_kind.setdefault(kind, []).append(entry)
            per_kind.setdefault("all", []).append(entry)
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        if probability:
            pr, ok = np.array(probability), np.array(right)
            notes.append(
                f"- {name}: {len(pr)} ids, {int((~ok).sum())} not the true one; "
                f"sum of (1 - match_probability) {np.sum(1 - pr):.1f}; "
                f"{int(np.sum(pr < 0.9))} ids with P < 0.9, {int((~ok[pr < 0.9]).sum())} of "
                f"them not the true one; smallest P {pr.min():.3f}"
            )
        for kind in ("all", "random", "pair 1-2 px", "pair < 1 px"):
            e = np.array(per_kind.get(kind, []), dtype=float)
            if len(e):
                rows.append((name, kind, e))
    lines = table_head(
        "solver",
        "scenes",
        "n",
        "solved",
        "mean score",
        "right ids",
        "wrong ids",
        "forgiven doubles",
        "swapped pairs",
        "unresolved doubles (flagged)",
        "ms per scene (median / p95)",
    )
    for name, kind, e in rows:
        score_, c, w, f, t, ms, solved, merged, flagged, swaps = e.T
        lines.append(
            f"| {name} | {kind} | {len(e)} | {int(solved.sum())} | {score_.mean():.4f} | "
            f"{c.sum() / t.sum():.2%} ({int(c.sum())}/{int(t.sum())}) | {int(w.sum())} | "
            f"{int(f.sum())} | {int(swaps.sum())} | {int(merged.sum())} ({int(flagged.sum())}) | "
            f"{np.median(ms):.1f} / {np.percentile(ms, 95):.1f} |"
        )
    table = "\n".join(lines) + "\n\nmatch_probability against the truth:\n\n" + "\n".join(notes)
    print(table)
    defaults = (args.scenes, args.seed, args.bright_mag, args.deep_mag) == (200, 1, 8.0, 12.0)
    if defaults and not args.no_doc:
        replace_block(DOCS / "deep_stars.md", "deep-stars", table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
