"""The published whole-sky study of the triangle method (domain.md, section 2), reproduced.

Camera: f = 40 mm with 16 µm pixels = 2500 px, 512 x 512 px (so the field is 11.69°, not the
12° quoted with it). Catalog: Hipparcos Hp <= 6. Boresights: the 7200 of a 3° RA/Dec grid
(``grid_boresights(3.0)``, roll at random from its seed). Stars: ``simulate_frame`` with 1′
(0.727 px) Gaussian centroid noise and Gaussian magnitude noise of 0.75 mag for the brightness
order ("noisy"), and without either ("noiseless").

Per field: the geometry of the triangles of the brightest stars (bad = shortest side below
d_min = 10 px, or smallest height, over the longest side, below delta = 4 px) and the real
solve path, ``solve_stars(..., algorithm="triangle", algorithm_options={...})``, limited to
the first one or two measured triangles (``Triangle(max_triangles=...)``) or not limited.

    python benchmarks/accuracy/triangle_study.py --out docs/triangle_study.md
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav.api as api
from benchmarks.harness import (
    CORRECT_RULE,
    DOCS,
    machine,
    replace_block,
    score_solution,
    table_head,
    table_row,
)
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.evaluate.sampling import frame_rng, grid_boresights
from starnav.identify.triangle import (
    MIN_HEIGHT_PX,
    MIN_SIDE_PX,
    brightness_triangles,
    select_triangles,
)
from starnav.simulate import project_catalog, simulate_frame

EVALUATION_DOC = DOCS / "evaluation.md"
FOCAL_PX = 40e-3 / 16e-6  # 2500 px
SIZE_PX = 512
MAG_LIMIT = 6.0
NOISE_PX = np.radians(1.0 / 60.0) * FOCAL_PX  # 1′ = 0.727 px
MAG_NOISE = 0.75
SCENARIOS = {
    "noisy": {"noise_px": NOISE_PX, "mag_noise": MAG_NOISE},
    "noiseless": {"noise_px": 0.0, "mag_noise": 0.0},
}
# the noisy scenario's two errors one at a time, for the geometry only (which one makes the
# bad triangles of the noisy fields differ from the noiseless ones)
GEOMETRY_ONLY = {
    "magnitude noise only": {"mag_noise": MAG_NOISE},
    "centroid noise only": {"noise_px": NOISE_PX},
}
# fields with <= 5 stars for other fields of view and catalog cuts: (label, fov_deg, mag)
THIN_VARIANTS = (
    ("12° field, Hp <= 6", 12.0, 6.0),
    ("11.69° field, Hp <= 6.1", None, 6.1),
    ("11.69° field, Hp <= 6.2", None, 6.2),
    ("12° field, Hp <= 6.2", 12.0, 6.2),
)
# (selection, max_triangles): the published first and second try, the optimized first try,
# and both selections without a limit (the hypothesis budget bounds them)
RUNS = (
    ("brightest", 1),
    ("brightest", 2),
    ("optimized", 1),
    ("brightest", None),
    ("optimized", None),
)
NB = 6  # the published "brightest NB stars"
PUBLISHED = {
    "bad_of_20": 7.74,
    "usable_first": 61.3,
    "few_fields": 6,
    "bad_123": 2729,
    "bad_124_after": 1343,
    "bad_125_after": 671,
    "brightest_first": 62.1,
    "brightest_two": 81.34,
    "optimized_first": 100.0,
}

_STATE: dict = {}


def _init(seed: int) -> None:
    camera = Camera(SIZE_PX, SIZE_PX, FOCAL_PX)
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    api.get_database(catalog, api.make_camera(width=SIZE_PX, height=None, fov_deg=camera.fov_deg))
    _STATE.update(
        camera=camera,
        catalog=catalog,
        boresights=grid_boresights(3.0, seed=seed),
        seed=seed,
        thin=[
            (
                camera if fov is None else Camera.from_fov(fov, SIZE_PX),
                load_catalog(None, mag_limit=m),
            )
            for _, fov, m in THIN_VARIANTS
        ],
    )


def _shapes(points_px: np.ndarray) -> np.ndarray:
    """Sorted sides s1 <= s2 <= s3 and twice the area (px, px²) of the 20 triangles of the 6
    brightest points, shape (20, 4); NaN where a star is missing."""
    out = np.full((20, 4), np.nan)
    n = min(len(points_px), NB)
    if n < 3:
        return out
    t = brightness_triangles(NB)
    have = t.max(axis=1) < n
    p = points_px[t[have]]
    u, v, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 2] - p[:, 1]
    sides = np.sort(np.stack([np.hypot(*u.T), np.hypot(*v.T), np.hypot(*w.T)], axis=1), axis=1)
    out[have, :3] = sides
    out[have, 3] = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    return out


def _frame(index: int) -> dict:
    s = _STATE
    b, camera, catalog = s["boresights"], s["camera"], s["catalog"]
    record: dict = {"index": index}
    for name, errors in GEOMETRY_ONLY.items():
        f = simulate_frame(
            catalog,
            camera,
            ra_deg=b.ra_deg[index],
            dec_deg=b.dec_deg[index],
            roll_deg=b.roll_deg[index],
            seed=frame_rng(s["seed"], index),
            **errors,
        )
        record[name] = _shapes(f.xy - [camera.cx, camera.cy])
    record["thin_variants"] = [
        len(project_catalog(cat, f.R_cam_from_icrs, cam)[0]) for cam, cat in s["thin"]
    ]
    for scenario, errors in SCENARIOS.items():
        f = simulate_frame(
            catalog,
            camera,
            ra_deg=b.ra_deg[index],
            dec_deg=b.dec_deg[index],
            roll_deg=b.roll_deg[index],
            seed=frame_rng(s["seed"], index),
            **errors,
        )
        points = f.xy - [camera.cx, camera.cy]  # rows brightest (measured) first
        _, n_good = select_triangles(points[:25], "optimized")
        outcomes: list[tuple[str, float, str]] = []
        for selection, limit in RUNS:
            # the identifier is deterministic and tries triangles in the same order whatever
            # the limit: once a shorter run of this selection answered, a longer one answers
            # the same from the same triangle, so it is not run again
            shorter = [k for k, (sel, lim) in enumerate(RUNS[: len(outcomes)]) if sel == selection]
            if shorter and outcomes[shorter[-1]][0] != "none":
                outcomes.append(outcomes[shorter[-1]])
                continue
            if len(f.xy) < 3:
                outcomes.append(("none", np.nan, "fewer than 3 stars"))
                continue
            r = api.solve_stars(
                f.xy,
                width=SIZE_PX,
                fov_deg=camera.fov_deg,
                brightness=f.brightness,
                catalog=catalog,
                sigma_px=NOISE_PX,
                algorithm="triangle",
                algorithm_options={"selection": selection, "max_triangles": limit},
            )
            if r.solution is None:
                kind = "none"
            else:
                correct = score_solution(r.solution, f.R_cam_from_icrs).correct
                kind = "correct" if correct else "wrong"
            outcomes.append((kind, r.time_ms, r.reason))
        record[scenario] = {
            "n_stars": len(f.xy),
            "shapes": _shapes(points),
            "n_good_optimized": n_good,
            "outcomes": outcomes,
        }
    return record


def _chunk(indices: list[int]) -> tuple[list[dict], float]:
    """The records of frames ``indices`` and the CPU seconds they took."""
    t0 = time.process_time()
    records = [_frame(i) for i in indices]
    return records, time.process_time() - t0


def _bad(
    shapes: np.ndarray,
    min_side_px: float,
    min_height_px: float,
    base: str = "longest",
    min_angle_deg: float = 0.0,
) -> np.ndarray:
    """Bad flags from ``_shapes`` rows (a missing triangle is bad). ``base``: the side the
    height is measured over: "longest" (the smallest height, our definition) or "middle"
    (height = longest side * sin(theta_min)); ``min_angle_deg``: also bad when the smallest
    interior angle is below this."""
    s1, s2, s3, area2 = np.moveaxis(shapes, -1, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        height = area2 / (s3 if base == "longest" else s2)
        bad = (s1 < min_side_px) | (height < min_height_px)
        if min_angle_deg > 0:
            # the smallest angle is opposite the shortest side
            cos_min = np.clip((s2**2 + s3**2 - s1**2) / (2.0 * s2 * s3), -1.0, 1.0)
            bad |= np.degrees(np.arccos(cos_min)) < min_angle_deg
    return bad | np.isnan(s1)


def summarise(records: list[dict], scenario: str) -> dict:
    rec = [r[scenario] for r in records]
    n_frames = len(rec)
    n_stars = np.array([r["n_stars"] for r in rec])
    shapes = np.stack([r["shapes"] for r in rec])  # (frames, 20, 4)
    bad = _bad(shapes, MIN_SIDE_PX, MIN_HEIGHT_PX, "longest")
    full = n_stars >= NB
    b123, b124, b125 = bad[:, 0], bad[:, 1], bad[:, 2]
    kinds = np.array([[o[0] for o in r["outcomes"]] for r in rec])  # (frames, runs)
    times = np.array([[o[1] for o in r["outcomes"]] for r in rec], dtype=float)
    solver = {}
    for j, run in enumerate(RUNS):
        t = times[:, j][np.isfinite(times[:, j])]
        solver[run] = {
            "correct": int(np.sum(kinds[:, j] == "correct")),
            "wrong": int(np.sum(kinds[:, j] == "wrong")),
            "none": int(np.sum(kinds[:, j] == "none")),
            "median_ms": float(np.median(t)),
            "p95_ms": float(np.percentile(t, 95)),
            "max_ms": float(np.max(t)),
        }
    first_ok = kinds[:, RUNS.index(("brightest", 1))] == "correct"
    optimized_first = RUNS.index(("optimized", 1))
    missed = kinds[:, optimized_first] != "correct"
    reasons: dict[str, int] = {}
    for r in np.array(rec)[missed]:
        # the reason without its numbers, so that equal reasons are counted together
        why = r["outcomes"][optimized_first][2].split("(")[0].strip()
        reasons[why] = reasons.get(why, 0) + 1
    return {
        "frames": n_frames,
        "n_stars": n_stars,
        "shapes": shapes,
        "few_fields": int(np.sum(n_stars <= 5)),
        "bad_of_20": float(bad[full].sum(axis=1).mean()),
        "bad_123": int(b123.sum()),
        "bad_124": int(b124.sum()),
        "bad_125": int(b125.sum()),
        "bad_124_after": int(np.sum(b123 & b124)),
        "bad_125_after": int(np.sum(b123 & b124 & b125)),
        "geo_optimized_first": int(np.sum([r["n_good_optimized"] > 0 for r in rec])),
        "solver": solver,
        "solved_when_123_bad": int(np.sum(first_ok & b123)),
        "solved_when_123_good": int(np.sum(first_ok & ~b123)),
        "optimized_missed_reasons": reasons,
        "optimized_missed_stars": n_stars[missed],
        "unsolved_stars": n_stars[kinds[:, RUNS.index(("optimized", None))] != "correct"],
    }


def _pct(count: float, total: int) -> str:
    return f"{100.0 * count / total:.2f} %"


def report(summaries: dict, context: dict, args, elapsed_s: float) -> str:
    """The markdown of docs/triangle_study.md. ``context``: catalog sizes by magnitude limit
    (``n_catalog``), the field of view (``fov_deg``) and the geometry-only counts."""
    n_catalog, fov_deg = context["n_catalog"][MAG_LIMIT], context["fov_deg"]
    noisy, clean = summaries["noisy"], summaries["noiseless"]
    n = noisy["frames"]

    def row(label: str, published: str, key, fmt) -> str:
        return table_row(label, published, fmt(noisy, key), fmt(clean, key))

    def count(s, key):
        return f"{s[key]} ({_pct(s[key], s['frames'])})"

    def solver_pct(s, run):
        return _pct(s["solver"][run]["correct"], s["frames"])

    lines = [
        "# The triangle method's whole-sky study, reproduced",
        "",
        "Reproduction of the published evaluation of the triangle method with brightest-star "
        'triangles and with the "secondary optimisation" (domain.md, section 2). Generated '
        "by `benchmarks/accuracy/triangle_study.py`; every number below comes from that run.",
        "",
        "## Set-up",
        "",
        f"- Camera: f = 40 mm / 16 µm = {FOCAL_PX:.0f} px, {SIZE_PX} x {SIZE_PX} px, so the "
        f"field is **{fov_deg:.2f}° x {fov_deg:.2f}°** (the publication calls it 12° x 12°; "
        "its own focal length and pixel count give 11.69°). Pinhole, no distortion.",
        f"- Catalog: Hipparcos new reduction (I/311), Hp <= {MAG_LIMIT:g}, propagated to the "
        f"current epoch: **{n_catalog} stars**.",
        f"- Boresights: {n} on the 3° RA/Dec grid (`grid_boresights(3.0, seed={args.seed})`: "
        "RA 0, 3, ..., 357°, Dec -88.5 ... 88.5°), roll uniform at random from the seed.",
        f"- Stars: `simulate_frame`; *noisy*: Gaussian centroid noise of 1′ = {NOISE_PX:.3f} px "
        f"per axis and Gaussian magnitude noise of σ = {MAG_NOISE} mag, which sets the "
        "brightness order; *noiseless*: neither. No false or missing stars.",
        f'- Solver: `solve_stars(..., algorithm="triangle", sigma_px={NOISE_PX:.3f})`: '
        f"inter-star angles match within 3·√2·σ = {3 * np.sqrt(2) * NOISE_PX:.2f} px "
        f"= {3 * np.sqrt(2) * NOISE_PX / FOCAL_PX * 180 / np.pi * 60:.2f}′ (published: 3′); "
        "every candidate is verified by reprojecting the catalog and bounding the "
        f"false-match probability (<= 1e-4). Scores: {CORRECT_RULE}.",
        "",
        "## Definitions",
        "",
        "- **Bad triangle**: its shortest side is below d_min = 10 px, or its smallest height "
        "is below δ = 4 px. The smallest height is the one over the **longest side (the "
        "base)**: h = 2·area / s3 = s2·sin θ_min for sides s1 <= s2 <= s3, i.e. the "
        "publication's a·sin θ_min with a = the middle side. Distances are measured on the "
        "focal plane in pixels (noisy centroids in the noisy scenario). A triangle one of "
        "whose stars is missing (a field with fewer stars) counts as bad.",
        "- **Bad of 20**: bad triangles among the 20 of the 6 brightest stars (by measured "
        "magnitude), averaged over the fields with >= 6 stars.",
        "- **1-2-4 / 1-2-5 after**: fields where 1-2-3 *and* 1-2-4 (and 1-2-5) are all bad: "
        "the published 1343 = 18.66 % and its 81.34 % two-try success are complements, so "
        "the publication counts them this way. The unconditional counts are given as well.",
        "- **Success, geometric**: the first (first or second) triangle of the brightest "
        "order is good; for the optimized selection: a good triangle exists among the 25 "
        "brightest stars (the selection then takes it first).",
        "- **Success, solver**: `solve_stars` with the identifier limited to the first "
        "(first two) measured triangles returns the correct attitude. For the optimized "
        'selection, "first" is the first triangle that meets both constraints.',
        "",
        "## Ours against the published numbers",
        "",
        *table_head("quantity", "published", "ours, noisy", "ours, noiseless"),
        row(
            "bad triangles of the 20 of the 6 brightest (mean)",
            "7.74",
            "bad_of_20",
            lambda s, k: f"{s[k]:.2f}",
        ),
        row(
            "a first triangle drawn from those 20 is usable",
            "61.3 %",
            "bad_of_20",
            lambda s, k: f"{100 * (1 - s[k] / 20):.1f} %",
        ),
        row("fields with <= 5 stars", "6", "few_fields", lambda s, k: f"{s[k]}"),
        row("triangle 1-2-3 bad", "2729 (37.9 %)", "bad_123", count),
        row("1-2-3 and 1-2-4 bad", "1343 (18.66 %)", "bad_124_after", count),
        row("1-2-3, 1-2-4 and 1-2-5 bad", "671 (9.32 %)", "bad_125_after", count),
        row("triangle 1-2-4 bad (unconditional)", "—", "bad_124", count),
        row("triangle 1-2-5 bad (unconditional)", "—", "bad_125", count),
        row(
            "brightest, first try, geometric (1-2-3 good)",
            "62.1 %",
            "bad_123",
            lambda s, k: _pct(s["frames"] - s[k], s["frames"]),
        ),
        row(
            "brightest, two tries, geometric (1-2-3 or 1-2-4 good)",
            "81.34 %",
            "bad_124_after",
            lambda s, k: _pct(s["frames"] - s[k], s["frames"]),
        ),
        row(
            "optimized, first try, geometric (a good triangle exists)",
            "~100 %",
            "geo_optimized_first",
            lambda s, k: _pct(s[k], s["frames"]),
        ),
        row(
            "brightest, first try, solver",
            "62.1 %",
            ("brightest", 1),
            solver_pct,
        ),
        row(
            "brightest, two tries, solver",
            "81.34 %",
            ("brightest", 2),
            solver_pct,
        ),
        row(
            "optimized, first try, solver",
            "~100 %",
            ("optimized", 1),
            solver_pct,
        ),
        row(
            "brightest, first try solved although 1-2-3 is bad",
            "—",
            "solved_when_123_bad",
            lambda s, k: f"{s[k]} of {s['bad_123']}",
        ),
        "",
        "## The real solver, every run",
        "",
        "A run limited to more triangles is not repeated where a shorter run of the same "
        "selection already solved the field: the identifier tries the same triangles in the "
        "same order, so it would return the same answer (its time is then the shorter "
        "run's). Times are of `solve_stars` (identification and least-squares fit); the "
        "noiseless fields take longer in the fit, not in the identification.",
        "",
        *table_head(
            "scenario",
            "selection",
            "triangles tried",
            "correct",
            "wrong",
            "none",
            "correct %",
            "median ms",
            "p95 ms",
            "max ms",
        ),
    ]
    for scenario, s in summaries.items():
        for run in RUNS:
            r = s["solver"][run]
            lines.append(
                table_row(
                    scenario,
                    run[0],
                    run[1] if run[1] else "all (budget)",
                    r["correct"],
                    r["wrong"],
                    r["none"],
                    f"{100 * r['correct'] / s['frames']:.2f}",
                    f"{r['median_ms']:.2f}",
                    f"{r['p95_ms']:.2f}",
                    f"{r['max_ms']:.1f}",
                )
            )
    table, fit = sensitivity(noisy)
    lines += ["", *table, "", *differences(summaries, context, fit), ""]
    lines += [
        "## Run",
        "",
        f"Machine: {machine()}; {args.processes} worker processes; {elapsed_s:.0f} s in all, "
        f"{context['cpu_s']:.0f} CPU seconds in the workers (when that is well below "
        f"{args.processes} x the wall time, the machine was shared with other jobs and the "
        "times above are inflated accordingly).",
        "",
        f"Command: `python benchmarks/accuracy/triangle_study.py --seed {args.seed} --processes "
        f"{args.processes} --out {args.out}`",
    ]
    return "\n".join(lines) + "\n"


def _counts(shapes: np.ndarray, full: np.ndarray, **definition) -> tuple[float, ...]:
    """(bad of 20, 1-2-3 bad %, 1-2-3 and 1-2-4 bad %, and 1-2-5 too %) for a definition."""
    bad = _bad(shapes, **definition)
    b0, b1, b2 = bad[:, 0], bad[:, 1], bad[:, 2]
    return (
        float(bad[full].sum(axis=1).mean()),
        100.0 * b0.mean(),
        100.0 * (b0 & b1).mean(),
        100.0 * (b0 & b1 & b2).mean(),
    )


def _threshold_for(shapes: np.ndarray, full: np.ndarray, name: str, grid: np.ndarray) -> float:
    """The threshold ``name`` (with d_min = 10 px) whose mean bad of 20 is the published 7.74."""
    means = [
        _counts(shapes, full, **{"min_side_px": MIN_SIDE_PX, "min_height_px": 0.0, name: t})[0]
        for t in grid
    ]
    return float(np.interp(PUBLISHED["bad_of_20"], means, grid))


def sensitivity(s: dict) -> tuple[list[str], dict]:
    """How the bad counts move with the thresholds and the choice of base (noisy fields);
    also the height and angle thresholds that give the published 7.74 bad of 20."""
    shapes, full = s["shapes"], s["n_stars"] >= NB
    cases = [
        ("d_min 10 px, δ 4 px, height over the longest side (ours)", {}),
        ("d_min 10 px, δ 4 px, height over the middle side", {"base": "middle"}),
        ("d_min 10 px only", {"min_height_px": 0.0}),
        ("δ 4 px only", {"min_side_px": 0.0}),
    ]
    cases += [(f"d_min 10 px, δ {d:g} px", {"min_height_px": float(d)}) for d in (10, 20, 40, 80)]
    cases += [
        (f"d_min 10 px, smallest angle {a:g}°", {"min_height_px": 0.0, "min_angle_deg": a})
        for a in (5, 10, 20)
    ]
    delta_eq = _threshold_for(shapes, full, "min_height_px", np.arange(1.0, 300.0, 0.5))
    angle_eq = _threshold_for(shapes, full, "min_angle_deg", np.arange(0.5, 60.0, 0.1))
    cases += [
        (f"d_min 10 px, δ {delta_eq:.0f} px (fitted to 7.74)", {"min_height_px": delta_eq}),
        (
            f"d_min 10 px, smallest angle {angle_eq:.1f}° (fitted to 7.74)",
            {"min_height_px": 0.0, "min_angle_deg": angle_eq},
        ),
    ]
    lines = [
        "## Sensitivity to the definition of a bad triangle (noisy fields)",
        "",
        *table_head(
            "bad when below",
            "bad of 20",
            "1-2-3 bad",
            "1-2-3 and 1-2-4 bad",
            "1-2-3, 1-2-4, 1-2-5 bad",
        ),
        "| published | 7.74 | 37.90 % | 18.66 % | 9.32 % |",
    ]
    for label, definition in cases:
        options = {"min_side_px": MIN_SIDE_PX, "min_height_px": MIN_HEIGHT_PX, **definition}
        c = _counts(shapes, full, **options)
        lines.append(f"| {label} | {c[0]:.2f} | {c[1]:.2f} % | {c[2]:.2f} % | {c[3]:.2f} % |")
    # share of the 20 triangles breaking each constraint alone
    side_only = _counts(shapes, full, min_side_px=MIN_SIDE_PX, min_height_px=0.0)[0] / 20
    flat_only = _counts(shapes, full, min_side_px=0.0, min_height_px=MIN_HEIGHT_PX)[0] / 20
    return lines, {
        "delta_counts": _counts(shapes, full, min_side_px=MIN_SIDE_PX, min_height_px=delta_eq),
        "angle_counts": _counts(
            shapes, full, min_side_px=MIN_SIDE_PX, min_height_px=0.0, min_angle_deg=angle_eq
        ),
        "delta_eq": delta_eq,
        "angle_eq": angle_eq,
        "side_only_pct": 100.0 * side_only,
        "flat_only_pct": 100.0 * flat_only,
        "middle": _counts(
            shapes, full, min_side_px=MIN_SIDE_PX, min_height_px=MIN_HEIGHT_PX, base="middle"
        ),
    }


def differences(summaries: dict, context: dict, fit: dict) -> list[str]:
    """One paragraph per reason our numbers differ from the published ones."""
    noisy, clean = summaries["noisy"], summaries["noiseless"]
    n = noisy["frames"]
    sol = noisy["solver"]
    n_catalog = context["n_catalog"]
    missed = noisy["optimized_missed_stars"]
    reasons = ", ".join(
        f'{count} × "{why}"'
        for why, count in sorted(noisy["optimized_missed_reasons"].items(), key=lambda x: -x[1])
    )
    b1, o1 = sol[("brightest", 1)]["correct"], sol[("optimized", 1)]["correct"]
    b1_clean = clean["solver"][("brightest", 1)]["correct"]
    o1_clean = clean["solver"][("optimized", 1)]["correct"]
    all_optimized = sol[("optimized", None)]["correct"]
    all_brightest = sol[("brightest", None)]["correct"]
    unsolved = noisy["unsolved_stars"]
    wrong = sum(r["wrong"] for s in summaries.values() for r in s["solver"].values())
    lo, hi = MAG_LIMIT - 0.25, MAG_LIMIT + 0.25
    angle, height = fit["angle_counts"], fit["delta_counts"]
    thin = "; ".join(f"{label}: {count}" for label, count in context["thin"].items())
    noise_cases = [
        ("neither noise", clean["bad_of_20"], 100.0 * clean["bad_123"] / n),
        *((name, c[0], c[1]) for name, c in context["geometry"].items()),
        ("both", noisy["bad_of_20"], 100.0 * noisy["bad_123"] / n),
    ]
    return [
        "## Why the numbers differ",
        "",
        f"**Catalog and field.** Hipparcos Hp <= {MAG_LIMIT:g} holds {n_catalog[MAG_LIMIT]} "
        f"stars: {np.mean(noisy['n_stars']):.1f} per {fov_text()} field on average (median "
        f"{np.median(noisy['n_stars']):.0f}, fewest {noisy['n_stars'].min()}), and "
        f"{noisy['few_fields']} of the {n} fields have <= 5 stars, against 6 published. The "
        "publication cut its catalog at V = 6 and domain.md does not give its size. Hp is a "
        "broader band than Johnson V, so the two magnitudes of a star differ by up to a few "
        "tenths depending on its colour and the two cuts keep somewhat different stars near "
        f"the limit, where the count changes fast (Hp <= {lo:g}: {n_catalog[lo]} stars, "
        f"<= {hi:g}: {n_catalog[hi]}). Fields with <= 5 stars for a wider field or a fainter "
        f"cut: {thin}. So the published 6 thin fields point to a catalog of more stars "
        "than ours (or a wider field), not to a different sky. Thin fields are where "
        "identification fails (see below), while the shapes of bright-star triangles "
        f"hardly depend on the cut. The field is also {context['fov_deg']:.2f}° "
        f"rather than 12° wide: {100 * (1 - (context['fov_deg'] / 12) ** 2):.0f} % less sky "
        "per frame.",
        "",
        "**Definition of a bad triangle.** With the constraints as stated (no side below "
        "10 px, no height below 4 px) bad triangles are rare in our fields: "
        f"{noisy['bad_of_20']:.2f} of 20 on average and 1-2-3 bad in "
        f"{_pct(noisy['bad_123'], n)} of the fields, against 7.74 and 37.9 % published. Of "
        f"the 20 triangles, {fit['side_only_pct']:.1f} % have a side below 10 px (a close "
        f"pair of catalog stars, within {MIN_SIDE_PX / FOCAL_PX * 180 / np.pi * 60:.1f}′) and "
        f"{fit['flat_only_pct']:.1f} % a height below 4 px. Measuring the height over the "
        "middle side (a = the longest side in a·sin θ_min) instead of the longest gives "
        f"{fit['middle'][0]:.2f} of 20, no closer. The published counts need a much stronger "
        f"flatness test: a smallest interior angle of {fit['angle_eq']:.1f}° (with d_min = "
        f"10 px) gives 7.74 bad of 20 and then 1-2-3 bad in {angle[1]:.1f} %, 1-2-3 and "
        f"1-2-4 in {angle[2]:.1f} %, all three of 1-2-3, 1-2-4, 1-2-5 in {angle[3]:.1f} % "
        "of the fields (published 37.9, 18.66, 9.32 %); a height of "
        f"{fit['delta_eq']:.0f} px also gives 7.74 and then {height[1]:.1f}, {height[2]:.1f} "
        f"and {height[3]:.1f} %. The published bad triangles behave like triangles with an "
        f"angle below about {fit['angle_eq']:.0f}° (or a height of tens of pixels), not like "
        "triangles lower than 4 px: the constraint the publication applied, or its unit, "
        "must differ from its text.",
        "",
        "**Thresholds and verification.** The publication matched angles within 3′; ours "
        f"derives {3 * np.sqrt(2) * NOISE_PX / FOCAL_PX * 180 / np.pi * 60:.2f}′ from the "
        "1′ centroid noise (3 σ of a difference of two centroids) and verifies every "
        "candidate against the whole field. That verification does not need a well-shaped "
        "triangle: two stars fix an attitude and the rest of the field confirms it, so a bad "
        f"1-2-3 still identified {noisy['solved_when_123_bad']} of the {noisy['bad_123']} "
        "fields where it is bad. The first try of the brightest selection therefore "
        f"succeeds in {_pct(b1, n)} of the fields ({_pct(b1_clean, n)} noiseless), far above "
        "the published 62.1 %, and the optimized selection's first try in "
        f"{_pct(o1, n)} ({_pct(o1_clean, n)} noiseless), close to the published ~100 %. The "
        f"{len(missed)} noisy fields its first try misses have {np.median(missed):.0f} stars "
        f"(median; {np.sum(missed <= 8)} have <= 8); the solver's reasons: {reasons}. In "
        "the thin fields too few other stars can confirm a hypothesis at p <= 1e-4; in the "
        "others we saw a side pushed beyond the tolerance by the noise, or a small triangle "
        "whose attitude misplaces the far stars by more than the match radius (the "
        "verification reprojects with the triangle's attitude, before any fit). Without a "
        f"limit on the number of triangles the optimized selection identifies "
        f"{_pct(all_optimized, n)} and the brightest {_pct(all_brightest, n)} of the noisy "
        f"fields; the {len(unsolved)} fields the optimized one leaves have at most "
        f"{unsolved.max() if len(unsolved) else 0} stars. {wrong} wrong attitudes in all runs.",
        "",
        f"**Noise.** The magnitude noise (σ = {MAG_NOISE} mag, Gaussian; the publication "
        "does not give its form) changes which stars are the brightest six, the centroid "
        "noise moves the triangles near a threshold; neither changes the counts much. Bad "
        "of 20 and 1-2-3 bad: "
        + "; ".join(f"{name}: {bad:.2f}, {pct:.2f} %" for name, bad, pct in noise_cases)
        + ".",
    ]


def fov_text() -> str:
    fov = Camera(SIZE_PX, SIZE_PX, FOCAL_PX).fov_deg
    return f"{fov:.2f}° x {fov:.2f}°"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="grid roll and frame noise seed")
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--frames", type=int, default=None, help="only the first N boresights")
    parser.add_argument("--out", default="docs/triangle_study.md")
    args = parser.parse_args()
    t0 = time.time()
    n_total = len(grid_boresights(3.0, seed=args.seed))
    indices = list(range(n_total if args.frames is None else min(args.frames, n_total)))
    chunks = [indices[k : k + 40] for k in range(0, len(indices), 40)]
    records: list[dict] = []
    with (
        multiprocessing.Pool(args.processes, initializer=_init, initargs=(args.seed,)) as pool,
        tqdm(total=len(indices), desc="triangle study", file=sys.stderr) as bar,
    ):
        cpu_s = 0.0
        for part, seconds in pool.imap_unordered(_chunk, chunks):
            records.extend(part)
            cpu_s += seconds
            bar.update(len(part))
    records.sort(key=lambda r: r["index"])
    summaries = {name: summarise(records, name) for name in SCENARIOS}
    full = summaries["noisy"]["n_stars"] >= NB  # the errors drop no star: the same fields
    definition = {"min_side_px": MIN_SIDE_PX, "min_height_px": MIN_HEIGHT_PX}
    context = {
        "n_catalog": {
            m: len(load_catalog(None, mag_limit=m))
            for m in (MAG_LIMIT - 0.25, MAG_LIMIT, MAG_LIMIT + 0.25)
        },
        "fov_deg": Camera(SIZE_PX, SIZE_PX, FOCAL_PX).fov_deg,
        "cpu_s": cpu_s,
        "thin": {
            label: int(np.sum(np.array([r["thin_variants"][k] for r in records]) <= 5))
            for k, (label, _, _) in enumerate(THIN_VARIANTS)
        },
        "geometry": {
            name: _counts(np.stack([r[name] for r in records]), full, **definition)
            for name in GEOMETRY_ONLY
        },
    }
    text = report(summaries, context, args, time.time() - t0)
    Path(args.out).write_text(text)
    print(text)
    # the side-by-side table also goes into docs/evaluation.md
    table = text.split("## Ours against the published numbers\n", 1)[1].split("\n## ", 1)[0]
    replace_block(
        EVALUATION_DOC,
        "triangle",
        f"f = 2500 px (40 mm / 16 µm) on 512 x 512 px, so an {context['fov_deg']:.2f}° field; "
        f"Hipparcos Hp <= {MAG_LIMIT:g} ({context['n_catalog'][MAG_LIMIT]} stars); the 7200 "
        "boresights of the 3° grid; noisy: 1′ (0.727 px) centroid noise and 0.75 mag "
        "magnitude noise. Definitions, every solver run, the sensitivity to the definition "
        "of a bad triangle and the reasons for each difference: "
        "[triangle_study.md](triangle_study.md) (`python benchmarks/accuracy/triangle_study.py`).\n"
        + table,
    )


if __name__ == "__main__":
    main()
