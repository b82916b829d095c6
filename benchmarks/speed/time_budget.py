"""Time budgets: do the defaults cost a solve, and does any call overrun its budget?

Two measurements, on the real solve paths (``starnav.runtime.budget``):

1. Solvable frames, each solved twice, with the default budget and with none
   (``time_budget_s=inf``): star lists with the FOV known (pinhole 20°, wide 120° equidistant),
   star lists and rendered images with the FOV searched (5-40°), fisheye 185° star lists with
   the focal length scanned, and the real images of ../shared/data. Reported: frames solved each
   way (they must agree: a default that cut a solve would show here), the identical answers,
   and the slowest solve as a fraction of its default budget.
2. Fields with nothing to find (random points, a frame of noise), solved with budgets from
   0.1 s to the default: the time each call took over its budget (``time_ms``, which counts
   the identification and fit; the searching the budget bounds).

    python benchmarks/speed/time_budget.py   # writes the block "time-budget" of docs/performance.md
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, SHARED, machine, replace_block, table_head
from starnav.api import solve_stars
from starnav.camera import Camera, Equidistant
from starnav.catalog import load_catalog
from starnav.geometry import attitude_from_radec_roll
from starnav.pipeline.image import solve_image
from starnav.runtime.budget import (
    DEFAULTS,
    KNOWN_BUDGET_S,
    SCAN_BUDGET_S,
    SEARCH_BUDGET_S,
    WIDE_BUDGET_S,
)
from starnav.simulate import simulate_frame
from starnav.simulate.render import RenderSettings, render_frame

DOC = DOCS / "performance.md"
NOISY = {"noise_px": 0.5, "false_stars": 3, "missing_frac": 0.1}


def solvable_cases(frames: int, seed: int):
    """(name, default budget s, [thunk(time_budget_s) -> (solution, time_ms)])."""
    rng = np.random.default_rng(seed)
    hip6 = load_catalog(None, mag_limit=6.0)
    hip7 = load_catalog(None, mag_limit=7.0)
    pin = Camera.from_fov(20.0, 1024)
    wide = Equidistant.from_fov(120.0, 1024, 1024)
    fish = Equidistant.from_fov(185.0, 1024, 1024)

    def lists(camera, n, solve):
        out = []
        for _ in range(n):
            f = simulate_frame(hip6, camera, seed=rng, **NOISY)
            out.append(lambda b, f=f: solve(f, b))
        return out

    def known(camera):
        return lambda f, b: _sol(
            solve_stars(f.xy, camera=camera, brightness=f.brightness, time_budget_s=b)
        )

    def searched(f, b):
        return _sol(
            solve_stars(f.xy, fov_exact=False, width=1024, brightness=f.brightness, time_budget_s=b)
        )

    def scanned(f, b):
        return _sol(
            solve_stars(
                f.xy,
                fov_exact=False,
                width=1024,
                brightness=f.brightness,
                lens="equidistant",
                fov_range_deg=(120.0, 200.0),  # as measured in docs/performance.md
                time_budget_s=b,
            )
        )

    images = []
    for k in range(max(1, frames // 4)):
        fov = float(rng.uniform(8.0, 30.0))
        cam = Camera.from_fov(fov, 1024, 768)
        ra, dec, roll = rng.uniform(0, 360), np.degrees(np.arcsin(rng.uniform(-1, 1))), 30.0
        R = attitude_from_radec_roll(ra, dec, roll, 1)
        img = render_frame(hip7, cam, R, RenderSettings(seed=k)).image
        images.append(lambda b, img=img: _img(solve_image(img, time_budget_s=b)))
    real = [
        (lambda b, p=p: _img(solve_image(p, time_budget_s=b)))
        for p in sorted((SHARED / "images").glob("*.*"))
        if p.suffix.lower() in (".jpg", ".png", ".tif", ".tiff", ".fits")
    ]
    real += [
        (lambda b, p=p: _img(solve_image(p, time_budget_s=b)))
        for p in sorted((SHARED / "real").glob("*.*"))
        if p.suffix.lower() in (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".fits", ".fit")
    ]
    return [
        ("star lists, FOV known: pinhole 20°", KNOWN_BUDGET_S, lists(pin, frames, known(pin))),
        (
            "star lists, FOV known: equidistant 120°",
            WIDE_BUDGET_S,
            lists(wide, frames // 2, known(wide)),
        ),
        (
            "star lists, FOV searched 5-40° (pinhole 20°)",
            SEARCH_BUDGET_S,
            lists(pin, frames // 2, searched),
        ),
        ("rendered images 8-30°, FOV searched", SEARCH_BUDGET_S, images),
        ("real images (../shared/data images and real), FOV searched", SEARCH_BUDGET_S, real),
        (
            "star lists, equidistant 185°, focal scanned 120-200°",
            SCAN_BUDGET_S,
            lists(fish, max(2, frames // 25), scanned),
        ),
    ]


def _sol(result):
    return result.solution, result.time_ms


def _img(result):
    return result.solution, result.solve_ms


def refusal_cases(seed: int):
    """(name, default budget s, thunk(time_budget_s) -> (reason, time_ms)): nothing to find."""
    rng = np.random.default_rng(seed)
    pin = Camera.from_fov(20.0, 1024)
    fish = Equidistant.from_fov(185.0, 1024, 1024)
    noise = rng.normal(100.0, 5.0, (768, 1024)).astype(np.float32)
    for x, y in rng.uniform(10.0, 760.0, (60, 2)):
        noise[int(y) : int(y) + 2, int(x) : int(x) + 2] += 400.0
    return [
        (
            "random points, FOV known (pinhole 20°)",
            KNOWN_BUDGET_S,
            lambda b: _why(solve_stars(rng.uniform(0, 1024, (50, 2)), camera=pin, time_budget_s=b)),
        ),
        (
            "random points, fisheye 185° known",
            WIDE_BUDGET_S,
            lambda b: _why(
                solve_stars(rng.uniform(0, 1024, (100, 2)), camera=fish, time_budget_s=b)
            ),
        ),
        (
            "random points, FOV searched 5-40°",
            SEARCH_BUDGET_S,
            lambda b: _why(
                solve_stars(
                    fov_exact=False, xy=rng.uniform(0, 1024, (50, 2)), width=1024, time_budget_s=b
                )
            ),
        ),
        (
            "image of noise, FOV searched",
            SEARCH_BUDGET_S,
            lambda b: _why_image(solve_image(noise, time_budget_s=b)),
        ),
        (
            "random points, fisheye focal scan",
            SCAN_BUDGET_S,
            lambda b: _why(
                solve_stars(
                    fov_exact=False,
                    xy=rng.uniform(0, 1024, (100, 2)),
                    width=1024,
                    lens="equidistant",
                    time_budget_s=b,
                )
            ),
        ),
    ]


def _why(result):
    return result.reason, result.time_ms


def _why_image(result):
    return result.reason, result.solve_ms


def run_solvable(frames: int, seed: int) -> list[str]:
    rows = []
    for name, default_s, thunks in solvable_cases(frames, seed):
        n = len(thunks)
        if n == 0:
            continue
        solved_default = solved_none = same = 0
        slowest = 0.0
        for thunk in tqdm(thunks, desc=name[:30], file=sys.stderr, leave=False):
            a, ms_a = thunk(None)
            b, _ = thunk(math.inf)
            solved_default += a is not None
            solved_none += b is not None
            if a is not None and b is not None:
                same += bool(
                    np.allclose(a.R_cam_from_icrs, b.R_cam_from_icrs, atol=1e-12)
                    and [m.catalog_id for m in a.stars] == [m.catalog_id for m in b.stars]
                )
            if a is not None:
                slowest = max(slowest, ms_a / 1e3)
        rows.append(
            f"| {name} | {n} | {default_s:g} s | {solved_default} | {solved_none} | {same} | "
            f"{slowest:.2f} s ({100 * slowest / default_s:.0f} %) |"
        )
    return rows


def run_refusals(trials: int, seed: int) -> list[str]:
    rows = []
    for name, default_s, thunk in refusal_cases(seed):
        budgets = sorted({b for b in (0.1, 0.3, 1.0, default_s) if b <= default_s})
        for budget in budgets:
            over, spent = [], 0
            for _ in range(trials):
                reason, ms = thunk(budget)
                over.append(ms / 1e3 / budget - 1.0)
                spent += reason.startswith("time budget spent")
            rows.append(
                f"| {name} | {budget:g} s{' (default)' if budget == default_s else ''} | "
                f"{trials} | {spent} | {100 * np.median(over):+.1f} % | {100 * max(over):+.1f} % |"
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100, help="star lists per solvable case")
    ap.add_argument("--trials", type=int, default=5, help="calls per refusal case and budget")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--no-doc", action="store_true", help="print only")
    args = ap.parse_args()
    t0 = time.perf_counter()
    # load the machine code and the tables first: the budgets do not count them either
    solve_stars(
        fov_exact=False,
        xy=np.random.default_rng(0).uniform(0, 1024, (20, 2)),
        width=1024,
        time_budget_s=0.1,
    )
    solvable = run_solvable(args.frames, args.seed)
    refusals = run_refusals(args.trials, args.seed)
    text = "\n".join(
        [
            f"Defaults: {DEFAULTS}. Each "
            "solvable frame solved with the default budget and with none:",
            "",
            *table_head(
                "case",
                "frames",
                "default budget",
                "solved (default)",
                "solved (no budget)",
                "same answer",
                "slowest solve (of the default)",
            ),
            *solvable,
            "",
            "Nothing to find, each call with the budget given: how far past its budget it "
            "stopped (identification and fit, ``time_ms``):",
            "",
            *table_head(
                "case",
                "budget",
                "calls",
                'said "time budget spent"',
                "over the budget, median",
                "over the budget, max",
            ),
            *refusals,
            "",
            f"{machine()}; "
            f"`python benchmarks/speed/time_budget.py --frames {args.frames} --trials "
            f"{args.trials}`, {time.perf_counter() - t0:.0f} s.",
        ]
    )
    print(text)
    if not args.no_doc:
        replace_block(DOC, "time-budget", text)


if __name__ == "__main__":
    main()
