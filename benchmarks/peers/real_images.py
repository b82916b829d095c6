"""starnav, cedar-solve and tetra3rs on the real-image corpus (tests/data/real): docs/images.md.

    python benchmarks/peers/real_images.py [--out docs/images.md | -]

The files are the corpus's (``../shared/data/real``, or ``$STARNAV_REAL_CORPUS``; absent ones
are listed as such), the answers are scored against the astrometry.net references of
``tests/data/real/reference.json`` (``make_reference.py``: starnav's conventions, boresight at
the image centre, roll about the boresight from the attitude matrices).

Solvers, each in a process of its own with thread pools of 1, reading the file names as JSON
lines and timing every step with ``perf_counter`` (the adapters of
``benchmarks/peers/images.py``):

* starnav (``images.py --starnav-worker solve``): ``read_image`` then ``solve_image(array)``
  with the FOV unknown (its default search range), default options;
* cedar-solve 0.5.1 (``peer_cedar_image.py``, its environment as ``benchmarks/peers/peers.py``
  makes it): ``solve_from_image`` with its own centroiding, its shipped database, the FOV
  unknown (``fov_estimate`` None);
* tetra3rs 0.14.0 (``peer_tetra3rs_image.py``): its ``extract_centroids`` (standard
  extractor) and ``solve_from_centroids`` with its stock database; it needs an FOV estimate,
  and gets the reference FOV (``GIVEN_FOV_DEG`` where astrometry.net found none), so its
  FOV column is not a blind one.

Scores per image: solved (an answer), wrong (an answer 0.5° or more off in boresight or in
roll about the boresight, or of the wrong parity, or any answer where astrometry.net found
none: there it is shown as "answer, no reference"), boresight error (″), roll error (°),
FOV error (% of the reference's horizontal FOV) and the time from the decoded array to the
attitude (ms). A peer's answer also counts as right when within ``WRONG_DEG``
(``harness.verdict``: not wrong); the test
(tests/corpus/test_real.py) holds starnav to tighter tolerances.
"""

from __future__ import annotations

import os

os.environ.update(
    dict.fromkeys(
        ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"), "1"
    )
)

import argparse
import dataclasses
import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
from benchmarks.harness import (
    DOCS,
    ROOT,
    WRONG_DEG,
    machine,
    replace_block,
    score_answer,
    table_head,
    verdict,
)
from benchmarks.peers.images import STARNAV, ensure_pillow
from benchmarks.peers.peers import PEERS, peer_database, peer_python, run_adapter
from starnav.geometry import attitude_from_radec_roll
from starnav.identify import cache_dir

DATA = ROOT / "tests" / "data" / "real"
DOC = DOCS / "images.md"
GIVEN_FOV_DEG = 20.0  # tetra3rs's FOV estimate for an image without a reference


def load_corpus():
    """``tests/data/real/make_reference.py`` as a module: the corpus table and its folder."""
    spec = importlib.util.spec_from_file_location("make_reference", DATA / "make_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@dataclasses.dataclass(frozen=True)
class Solver:
    """A column group of the table: a solver, its adapter, interpreter and arguments."""

    label: str
    adapter: object
    python: Path
    args: tuple[str, ...]
    fov_given: bool


def solvers(root: Path) -> tuple[list[Solver], dict]:
    """starnav, cedar-solve and tetra3rs as run here, and the peers' install lines."""
    out = [
        Solver(
            f"starnav {starnav.__version__}",
            STARNAV,
            Path(sys.executable),
            ("--starnav-worker", "solve"),
            False,
        )
    ]
    installs = {}
    for peer in PEERS:
        python, installs[peer.name] = peer_python(peer, root)
        db_arg, _ = peer_database(python, peer, root, None, Path("-"), "", tag="stock")
        if peer.name == "cedar-solve":
            adapter = dataclasses.replace(peer, adapter="peer_cedar_image.py")
            args = ("solve", "--db", db_arg)
            out.append(Solver(f"cedar-solve {peer.version}", adapter, python, args, False))
        else:
            installs[peer.name] += f" {ensure_pillow(python)}"
            adapter = dataclasses.replace(peer, adapter="peer_tetra3rs_image.py")
            args = ("solve", "--db", db_arg, "--extractor", "standard")
            out.append(Solver(f"tetra3rs {peer.version}", adapter, python, args, True))
    return out, installs


def reference_attitude(ref: dict) -> np.ndarray:
    return attitude_from_radec_roll(ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"])


def score(ref: dict, out: dict) -> dict:
    """One solver on one image: outcome and errors (see the module docstring)."""
    answered = out.get("error") is None and ("R" in out or out.get("ra_deg") is not None)
    row = {"time_ms": out.get("time_ms"), "answered": answered, "error": out.get("error")}
    if not answered:
        return {**row, "outcome": "unsolved"}
    if not ref["solved_by_reference"]:
        return {**row, "outcome": "answer, no reference"}
    score = score_answer(out, reference_attitude(ref))
    fov = out.get("fov_deg")
    row.update(
        boresight_arcsec=score.boresight_arcsec,
        roll_deg=score.roll_deg,
        fov_percent=None if fov is None else 100 * (fov / ref["fov_deg"] - 1),
    )
    wrong = verdict(score) == "wrong"
    return {**row, "outcome": "WRONG" if wrong else "right"}


def cell(r: dict) -> str:
    if r is None:
        return "absent |  |  |  | "
    t = "-" if r["time_ms"] is None else f"{r['time_ms']:.0f}"
    if r["outcome"] != "right":
        mark = "no" if r["outcome"] == "unsolved" else r["outcome"]
        return f"{mark} |  |  |  | {t}"
    fov = "" if r["fov_percent"] is None else f"{r['fov_percent']:+.2f}"
    return f"yes | {r['boresight_arcsec']:.1f} | {r['roll_deg']:.3f} | {fov} | {t}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DOC, help="markdown file ('-': none)")
    parser.add_argument("only", nargs="*", help="only these files (a trial run)")
    args = parser.parse_args()
    t_start = time.time()
    corpus = load_corpus()
    folder = corpus.corpus_dir()
    references = json.loads((DATA / "reference.json").read_text())["images"]
    names = [e["name"] for e in corpus.sources() if not args.only or e["name"] in args.only]
    present = [n for n in names if folder is not None and (folder / n).exists()]
    runs, installs = solvers(cache_dir())
    results: dict[str, dict[str, dict]] = {s.label: {} for s in runs}
    for s in runs:
        items = []
        for name in present:
            ref = references[name]
            fov = (ref.get("fov_deg") or GIVEN_FOV_DEG) if s.fov_given else None
            items.append({"path": str(folder / name), "fov_deg": fov})
        t0 = time.time()
        outs, _ = run_adapter(s.python, s.adapter, list(s.args), items)
        for name, out in zip(present, outs, strict=True):
            results[s.label][name] = score(references[name], out)
        right = sum(r["outcome"] == "right" for r in results[s.label].values())
        print(
            f"{s.label}: {right}/{len(present)} right ({time.time() - t0:.0f} s)", file=sys.stderr
        )
    write_doc(args, names, references, runs, results, installs, t_start)


def summary_line(label: str, rows: dict, n_reference: int) -> str:
    right = [r for r in rows.values() if r["outcome"] == "right"]
    wrong = sum(r["outcome"] == "WRONG" for r in rows.values())
    unref = sum(r["outcome"] == "answer, no reference" for r in rows.values())
    bore = [r["boresight_arcsec"] for r in right]
    times = [r["time_ms"] for r in right]
    med = f"{np.median(bore):.1f}″" if bore else "-"
    tmed = f"{np.median(times):.0f} ms" if times else "-"
    return (
        f"- {label}: {len(right)} of the {n_reference} images astrometry.net solved right, "
        f"{wrong} wrong, {unref} answers where astrometry.net found none; boresight error "
        f"median {med}, time median {tmed} (right answers)"
    )


def write_doc(args, names, references, runs, results, installs, t_start) -> None:
    n_ref = sum(references[n]["solved_by_reference"] for n in names)
    per_run = ("solved", "″", "roll °", "FOV %", "ms")
    lines = table_head(
        "image",
        "reference FOV°",
        *(f"{s.label}: {c}" if c == "solved" else c for s in runs for c in per_run),
    )
    for name in names:
        ref = references[name]
        fov = f"{ref['fov_deg']:.2f}" if ref["solved_by_reference"] else "not solved"
        cells = "".join(f" {cell(results[s.label].get(name))} |" for s in runs)
        lines.append(f"| `{name}` | {fov} |{cells}")
    text = "\n".join(
        [
            f"{len(names)} real images (tests/data/real; {n_ref} solved by astrometry.net, "
            "whose answers are the reference). Peers: "
            + "; ".join(f"{k}: `pip install {v}`" for k, v in installs.items())
            + ". starnav and cedar-solve with the FOV unknown; tetra3rs with the reference FOV "
            "given (it needs an estimate). Thread pools of 1.",
            "",
            *(summary_line(s.label, results[s.label], n_ref) for s in runs),
            "",
            *lines,
            "",
            f"solved: yes (right: within {WRONG_DEG:g}° in boresight and in roll about the "
            "boresight, the right parity), no, WRONG, or 'answer, no reference' (astrometry.net "
            "found none); ″: boresight error; roll °: rotation about the boresight; FOV %: "
            "relative error of the horizontal FOV; ms: the decoded array to the attitude.",
            "",
            f"{machine()}; `nice python benchmarks/peers/real_images.py`, "
            f"{time.time() - t_start:.0f} s.",
        ]
    )
    print(text)
    if str(args.out) != "-":
        missing = (
            "## Real images\n\nGenerated by `benchmarks/peers/real_images.py` (its docstring"
            " says what is measured and how) on the corpus of `tests/data/real` (its README:"
            " sources, licences, references)."
        )
        replace_block(args.out, "real_images", text, missing=missing)


if __name__ == "__main__":
    main()
