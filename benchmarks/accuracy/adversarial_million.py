"""A million adversarial frames through ``starnav evaluate``'s path: 0 wrong answers?

    python benchmarks/accuracy/adversarial_million.py [--frames 1000000] [--chunk 50000]
        [--workers N | --dask ADDRESS] [--state STATE.json]

The evaluation (``starnav.evaluate``, what ``starnav evaluate --kind ...`` runs) at the default
options (12° / 512 px pinhole, Hp <= 6, 0.5 px noise, 2 false stars, 10 % missing, threshold
1e-4), the frame kinds random, scrambled, mirrored, fov-off, crowded and few in turn
(``starnav.evaluate.kinds``), in chunks of ``--chunk`` frames (chunk c: boresights uniform on
the sky from seed ``--seed`` + c, frames from the same seed), so every frame can be remade
and a run that stops keeps what it has: each finished chunk's counts go to ``--state`` and a
rerun with the same state file goes on from there.

Prints markdown (for docs/verification.md): the outcomes by kind, by number of true stars for
the kinds that have a right answer, the claimed false-match probability of the right answers,
every wrong answer (kind, chunk, index, claim) and the solver's time per kind.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, table_head
from starnav.evaluate import EvalConfig, evaluate, uniform_boresights
from starnav.evaluate.kinds import parse_kinds
from starnav.evaluate.runner import star_count_bin

KINDS = "random,scrambled,mirrored,fov-off,crowded,few"
DECADES = [1e-300, 1e-30, 1e-20, 1e-12, 1e-8, 1e-6, 1e-5, 1e-4]  # claimed-p bins of right answers


def chunk_counts(results) -> dict:
    """What one chunk adds: outcomes per kind and per (kind, true stars), solver times per
    kind (ms, for percentiles), right answers per claimed-p bin, the wrong answers."""
    outcomes, by_stars, claims = Counter(), Counter(), Counter()
    times: dict[str, list[float]] = {}
    wrong = []
    for r in results:
        outcomes[f"{r.kind}|{r.outcome}"] += 1
        by_stars[f"{r.kind}|{star_count_bin(r.n_true)}|{r.outcome}"] += 1
        times.setdefault(r.kind, []).append(round(r.time_ms, 3))
        if r.outcome == "correct":
            k = int(np.searchsorted(DECADES, r.false_match_probability, side="right"))
            claims[str(k)] += 1
        if r.outcome in ("wrong", "imprecise"):  # an answer beyond the tolerance counts
            wrong.append({"kind": r.kind, "index": r.index, "p": r.false_match_probability})
    return {
        "outcomes": outcomes,
        "by_stars": by_stars,
        "claims": claims,
        "times": times,
        "wrong": wrong,
    }


def merge(total: dict, part: dict) -> dict:
    for key in ("outcomes", "by_stars", "claims"):
        total[key] = dict(Counter(total.get(key, {})) + Counter(part[key]))
    times = total.setdefault("times", {})
    for kind, values in part["times"].items():
        times.setdefault(kind, []).extend(values)
    total.setdefault("wrong", []).extend(part["wrong"])
    return total


def report(state: dict, kinds: tuple[str, ...]) -> str:
    out, bs = state["outcomes"], state["by_stars"]
    n = sum(out.values())
    lines = [
        f"{n} frames, {state['chunks']} chunks of {state['chunk']}; "
        f"wrong answers: **{len(state['wrong'])}**.",
        "",
        *table_head("kind", "frames", "right", "wrong", "refused", "median ms", "p95 ms", "max ms"),
    ]
    for kind in kinds:
        c = {o: out.get(f"{kind}|{o}", 0) for o in ("correct", "wrong", "none", "imprecise")}
        t = np.array(state["times"].get(kind, [0.0]))
        lines.append(
            f"| {kind} | {sum(c.values())} | {c['correct']} | {c['wrong'] + c['imprecise']} | "
            f"{c['none']} | {np.median(t):.1f} | {np.percentile(t, 95):.1f} | {t.max():.0f} |"
        )
    lines += ["", "Right answers by true stars among the points (kinds with a right answer):", ""]
    bins = ["0-2", "3", "4", "5", "6", ">=7"]
    lines += table_head("kind", *bins)
    for kind in kinds:
        cells = []
        for b in bins:
            total = sum(bs.get(f"{kind}|{b}|{o}", 0) for o in ("correct", "wrong", "none"))
            right = bs.get(f"{kind}|{b}|correct", 0)
            cells.append(f"{right}/{total}" if total else "")
        if any(cells) and kind != "random":
            lines.append(f"| {kind} | " + " | ".join(cells) + " |")
    lines += ["", "Claimed false-match probability of the right answers:", ""]
    labels = [f"< {DECADES[1]:.0e}"] + [
        f"{lo:.0e} - {hi:.0e}" for lo, hi in itertools.pairwise(DECADES[1:])
    ]
    claims = state["claims"]
    lines += table_head("claimed p", *labels)
    lines.append(
        "| right answers | "
        + " | ".join(str(claims.get(str(k), 0)) for k in range(1, len(DECADES)))
        + " |"
    )
    if state["wrong"]:
        lines += ["", "Wrong answers:", ""]
        lines += [f"- {w}" for w in state["wrong"]]
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--chunk", type=int, default=50_000)
    parser.add_argument("--kinds", default=KINDS)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--dask", metavar="ADDRESS", help="a Dask scheduler, or 'local'")
    parser.add_argument("--state", type=Path, default=Path("adversarial_state.json"))
    args = parser.parse_args()
    kinds = parse_kinds(args.kinds)
    state = json.loads(args.state.read_text()) if args.state.exists() else {}
    if state and (state["chunk"], state["kinds"]) != (args.chunk, list(kinds)):
        print(f"{args.state}: another run's state (chunk, kinds); give another --state")
        return 2
    state.setdefault("chunk", args.chunk)
    state.setdefault("kinds", list(kinds))
    state.setdefault("chunks", 0)
    state.setdefault("wall_s", 0.0)
    load = os.getloadavg()[0]
    n_chunks = -(-args.frames // args.chunk)
    for c in range(state["chunks"], n_chunks):
        seed = args.seed + c
        config = EvalConfig(seed=seed, kinds=kinds)
        boresights = uniform_boresights(args.chunk, seed=seed)
        t0 = time.perf_counter()
        _, results = evaluate(config, boresights, workers=args.workers, dask_address=args.dask)
        part = chunk_counts(results)
        for w in part["wrong"]:
            w["seed"] = seed
        merge(state, part)
        state["chunks"] = c + 1
        state["wall_s"] += time.perf_counter() - t0
        args.state.write_text(json.dumps(state))
        print(f"chunk {c + 1}/{n_chunks}: {len(state['wrong'])} wrong so far", file=sys.stderr)
    print(report(state, kinds))
    print()
    print(
        f"{state['wall_s'] / 60:.0f} min of evaluation in all; {machine(load)}; "
        f"`python benchmarks/accuracy/adversarial_million.py --frames {args.frames} "
        f"--chunk {args.chunk} --seed {args.seed}`."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
