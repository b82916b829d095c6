"""Where a star-list solve's time goes: the numba kernels against the Python around them.

    python benchmarks/speed/solve_split.py [--scenario a|b|c] [--frames 300]

Solves the frames of a peers.py-like scenario ((a) 12° / 512 px, 0.1 px; (b) 0.5 px, 2 false
stars, 10 % missing; (c) 20° / 1024 px, 0.2 px; Hipparcos Hp <= 6) through one prepared
``Solver`` five times over and prints, per stage, the median of each pass's per-frame times
and the fastest pass's: the whole ``Solver.solve``, its identification and fit stages
(``SolveResult.stage_ms``), and inside them the triangle-search kernel, the conclusion kernel
(``pipeline.kernels.conclude``) and the two Python steps after it (``refinement``,
``solution_of``), timed by wrapping them. The wrappers add about a microsecond each.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, table_head, table_row
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.identify.kernels import search
from starnav.pipeline import conclude
from starnav.pipeline.solver import Solver, SolveSettings
from starnav.simulate import simulate_frame
from starnav.starlist import check_star_list

SCENARIOS = {  # FOV deg, width px, noise px, false stars, missing fraction
    "a": (12.0, 512, 0.1, 0, 0.0),
    "b": (12.0, 512, 0.5, 2, 0.1),
    "c": (20.0, 1024, 0.2, 0, 0.0),
}


def timed(times: dict, key: str, fn):
    """``fn`` with each call's seconds appended to ``times[key]``."""

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        times.setdefault(key, []).append(time.perf_counter() - t0)
        return out

    return wrapper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=list(SCENARIOS), default="a")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    fov, width, noise, false_stars, missing = SCENARIOS[args.scenario]
    catalog = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(fov, width)
    solver = Solver(camera, catalog, settings=SolveSettings(sigma_px=noise))
    rng = np.random.default_rng(args.seed)
    lists = []
    while len(lists) < args.frames:
        f = simulate_frame(catalog, camera, noise_px=noise, false_stars=false_stars,
                           missing_frac=missing, seed=rng)  # fmt: skip
        if len(f.xy) >= 4:
            lists.append(check_star_list(f.xy, width=width, height=width))
    times: dict[str, list[float]] = {}
    kernels = conclude.kernels()

    class Kernels:  # the conclusion's kernel module, its ``conclude`` timed
        def __getattr__(self, name):
            value = getattr(kernels, name)
            return timed(times, "conclusion kernel", value) if name == "conclude" else value

    conclude.kernels = Kernels
    search.triangle_search = timed(times, "triangle-search kernel", search.triangle_search)
    conclude.refinement = timed(times, "refinement (Python)", conclude.refinement)
    conclude.solution_of = timed(times, "solution_of (Python)", conclude.solution_of)
    for stars in lists[:20]:  # the machine code loaded, the caches warm
        solver.solve(stars)
    passes: list[dict[str, float]] = []
    for _ in range(5):
        times.clear()
        for stars in lists:
            t0 = time.perf_counter()
            result = solver.solve(stars)
            times.setdefault("Solver.solve", []).append(time.perf_counter() - t0)
            for stage in ("identify", "fit"):
                times.setdefault(f"stage: {stage}", []).append(result.stage_ms[stage] / 1e3)
        passes.append({k: float(np.median(v)) * 1e6 for k, v in times.items()})
    lines = table_head("step", "median µs (median of 5 passes)", "fastest pass")
    for key in passes[0]:
        values = [p[key] for p in passes]
        lines.append(table_row(key, f"{np.median(values):.1f}", f"{min(values):.1f}"))
    print(f"Scenario ({args.scenario}): {fov:g}° / {width} px, {noise:g} px noise, "
          f"{false_stars} false stars, {missing:.0%} missing; {args.frames} frames.\n")  # fmt: skip
    print("\n".join(lines))
    print(f"\n{machine()}; `python benchmarks/speed/solve_split.py --scenario {args.scenario}`.")


if __name__ == "__main__":
    main()
