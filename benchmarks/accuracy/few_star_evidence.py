"""Where the evidence of frames with few true stars goes: the false-match probability of each
frame's best hypothesis, term by term.

    python benchmarks/accuracy/few_star_evidence.py [--frames 20000] [--seed 11] [--true-stars 4]

The frames of ``starnav evaluate --sampling uniform --frames N --seed S`` at the default options
whose points hold exactly ``--true-stars`` true stars are solved again with the kernels run as
plain Python (``NUMBA_DISABLE_JIT=1``, set here), the verifier's ``field_false_match`` and
``brightness_log_ratio`` wrapped to record what they were given and gave; for the hypothesis with
the smallest probability (the identification's or the fit's) it prints, in natural-log units,
log p = log(K H) - (pair log ratios of the points not used to build it) - (unmatched points'
log ratios) - (triangle sides) - (brightness), and the threshold's log(1e-4) = -9.2 to compare.
Slow (plain Python): about 2 s a frame.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

os.environ["NUMBA_DISABLE_JIT"] = "1"  # before any kernel module is imported

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, table_head
from starnav.evaluate import EvalConfig, uniform_boresights
from starnav.evaluate.runner import config_frame, solve_frame
from starnav.identify.kernels import evidence as ik
from starnav.identify.kernels import hypothesis as hk
from starnav.pipeline import kernels as pk


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--true-stars", type=int, default=4)
    args = parser.parse_args()

    config = EvalConfig(seed=args.seed)
    boresights = uniform_boresights(args.frames, seed=args.seed)
    best: dict = {}
    last_brightness = [0.0]
    field_false_match, brightness_log_ratio = ik.field_false_match, ik.brightness_log_ratio

    def brightness(*a):
        last_brightness[0] = brightness_log_ratio(*a)
        return last_brightness[0]

    def verify(dist, obs, rank, n_cone, field_area, n_used, hypotheses, sigmas, radius, other):
        p = field_false_match(dist, obs, rank, n_cone, field_area, n_used, hypotheses, sigmas,
                              radius, other)  # fmt: skip
        if p < best.get("p", 2.0):
            scored = ik.scored_pairs(dist, obs, rank, n_cone)
            n_points = ik.scored_count(rank, n_cone)
            logs = np.empty(len(scored))
            miss = ik.star_log_ratios(scored, n_cone, field_area, sigmas[0], ik.Q_STAR, radius,
                                      logs)  # fmt: skip
            kept = np.sort(logs)[: max(len(scored) - n_used, 0)]
            best.update(p=p, log_kh=math.log(len(sigmas) * max(hypotheses, 1)),
                        pairs=float(kept.sum()), unmatched=(n_points - len(scored)) * miss,
                        brightness=last_brightness[0], sides=other - last_brightness[0],
                        n_cone=n_cone)  # fmt: skip
        return p

    # the callers' names are rebound: the hypothesis test's and the fit policy's
    hk.brightness_log_ratio = pk.brightness_log_ratio = brightness
    hk.field_false_match = pk.field_false_match = verify

    rows = []
    for index in range(args.frames):
        frame, _ = config_frame(config, boresights, index)
        if int(np.sum(frame.true_id != -1)) != args.true_stars:
            continue
        best.clear()
        r = solve_frame(config, boresights, index)
        if "p" in best:
            rows.append((r.outcome, best.copy()))
        print(f"frame {index}: {r.outcome}", file=sys.stderr)
    terms = ("log_kh", "pairs", "unmatched", "sides", "brightness")
    print(
        f"{len(rows)} frames with {args.true_stars} true stars of {args.frames} (seed "
        f"{args.seed}) verified a hypothesis; {sum(o == 'correct' for o, _ in rows)} solved.\n"
    )
    print("\n".join(table_head("term (natural log)", "median", "10 %", "90 %")))
    for name in (*terms, "log p"):
        v = np.array([math.log(b["p"]) if name == "log p" else b[name] for _, b in rows])
        q10, q50, q90 = np.percentile(v, [10, 50, 90])
        print(f"| {name} | {q50:.1f} | {q10:.1f} | {q90:.1f} |")
    cones = np.array([b["n_cone"] for _, b in rows])
    print(
        f"\nCatalog stars in the field cone: median {np.median(cones):.0f}. log(1e-4) = "
        f"{math.log(1e-4):.1f}. {machine()}; `python benchmarks/accuracy/few_star_evidence.py "
        f"--frames {args.frames} --seed {args.seed} --true-stars {args.true_stars}`."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
