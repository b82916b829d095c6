"""starnav, cedar-solve, tetra3rs and astrometry.net on the real-image corpus, by field width:
docs/corpus.md.

    python benchmarks/peers/real_images.py [--set development|held_back|held_back_2|held_back_3|all]
        [--solvers starnav,cedar-solve,tetra3rs] [--rows rows.jsonl] [--before rows.jsonl]
        [--out docs/corpus.md | -] [FILE ...]

The corpus is ``tests/data/real`` (its README: 250 photographs from 62 public repositories,
each with its repository, commit, path, SHA-256 and licence in sources.json; the files
themselves in ``$STARNAV_REAL_CORPUS``, else ``../shared/data/real``, absent ones listed as
such). Its sources are split in four sets (``set`` in sources.json): ``development``, the
photos starnav was measured and changed on; ``held_back``, 12 sources drawn at random (by
source) before any of their photos was solved, run once at the end to measure whether the
changes generalize (it has since been looked at); ``held_back_2``, a fresh set from sources
named nowhere else in tests/data/real (run once since, so looked at too); and
``held_back_3``, another such set drawn after that run, that starnav has not run on before its
one run at the end.

The reference is astrometry.net's answer (``reference.json``, made offline by
``tests/data/real/make_reference.py`` with the Tycho-2 index files 4107-4119, no hint beyond a
0.3-100° width), converted to starnav's conventions; its ``seconds`` are solve-field's wall
time on that image (FITS to .wcs, run at ``nice`` beside other work: an upper bound). A band is
the reference's horizontal field of view, or "not solved by astrometry.net" when it found none.

Solvers, each in a process of its own with thread pools of 1, reading the file names as JSON
lines and timing each step with ``perf_counter`` (the adapters of ``benchmarks/peers/images.py``):

* starnav (``images.py --starnav-worker solve``): ``read_image`` and a FITS file's header
  hints (``fits_hints``: position, scale, pixel sizes, date) then ``solve_image(array,
  hints=...)`` with default options, as ``starnav solve IMG`` runs it (the rows name the
  hints; astrometry.net's references were made without them);
* cedar-solve 0.5.1 (``peer_cedar_image.py``): ``solve_from_image``, its own centroiding and
  shipped database, the FOV unknown;
* tetra3rs 0.14.0 (``peer_tetra3rs_image.py``): its ``extract_centroids`` and
  ``solve_from_centroids`` with its stock database and the reference FOV given (it needs an
  estimate; ``GIVEN_FOV_DEG`` where astrometry.net found none), so its column is not a blind
  one.

Scores per image (``harness.verdict``): right (within ``WRONG_DEG`` in boresight and in roll
about the boresight, the reference's parity), wrong, or no answer. An answer on an image
astrometry.net did not solve blind is given back to astrometry.net as a hint (within 5° and
10 % of the answer, ``verify_unreferenced``): confirmed, unconfirmed (it still finds
nothing) or wrong (it solves elsewhere). A wrong answer against an astrometry.net answer
that fails the catalog check (a reference kept for its log-odds, ``check_overridden`` in
reference.json, or a hinted solve) is "right, reference off" (or "answer, confirmed") when
the same check passes for it and puts more catalog stars on detections
(``dispute_failed_references``; listed under the tables). starnav's unsolved images are
grouped by the
``failure`` class its result names (``starnav.pipeline.diagnose``). ``--rows`` writes each
solver's raw answer per image, ``--from-rows`` writes the tables from such files without
running the solvers, ``--before`` adds the starnav counts of an earlier run.
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
from collections import Counter
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import (
    DOCS,
    ROOT,
    WRONG_DEG,
    answer_attitude,
    machine,
    score_answer,
    table_head,
    table_row,
    verdict,
)
from benchmarks.peers.images import STARNAV, ensure_pillow
from benchmarks.peers.peers import PEERS, peer_database, peer_python, run_adapter
from starnav.geometry import attitude_from_radec_roll, radec_roll_from_attitude
from starnav.identify import cache_dir

DATA = ROOT / "tests" / "data" / "real"
DOC = DOCS / "corpus.md"
GIVEN_FOV_DEG = 20.0  # tetra3rs's FOV estimate for an image without a reference
SETS = ("development", "held_back", "held_back_2", "held_back_3")
BANDS = ((0.0, 3.0), (3.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 60.0), (60.0, 400.0))
NO_REFERENCE = "not solved by astrometry.net"
STARNAV_LABEL = "starnav"


def load_corpus():
    """``tests/data/real/make_reference.py`` as a module: the corpus table and its folder."""
    spec = importlib.util.spec_from_file_location("make_reference", DATA / "make_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@dataclasses.dataclass(frozen=True)
class Solver:
    """A column group of the tables: a solver, its adapter, interpreter and arguments."""

    label: str
    adapter: object
    python: Path
    args: tuple[str, ...]
    fov_given: bool


def solvers(root: Path, wanted: list[str]) -> tuple[list[Solver], dict]:
    """starnav, cedar-solve and tetra3rs as run here (those ``wanted``), and the peers'
    install lines."""
    out, installs = [], {}
    if STARNAV_LABEL in wanted:
        worker = ("--starnav-worker", "solve")
        out.append(Solver(STARNAV_LABEL, STARNAV, Path(sys.executable), worker, False))
    for peer in PEERS:
        if peer.name not in wanted:
            continue
        python, installs[peer.name] = peer_python(peer, root)
        db_arg, _ = peer_database(python, peer, root, None, Path("-"), "", tag="stock")
        if peer.name == "cedar-solve":
            adapter = dataclasses.replace(peer, adapter="peer_cedar_image.py")
            out.append(Solver(peer.name, adapter, python, ("solve", "--db", db_arg), False))
        else:
            installs[peer.name] += f" {ensure_pillow(python)}"
            adapter = dataclasses.replace(peer, adapter="peer_tetra3rs_image.py")
            args = ("solve", "--db", db_arg, "--extractor", "standard")
            out.append(Solver(peer.name, adapter, python, args, True))
    return out, installs


def band_of(ref: dict) -> str:
    """The field-width band of an image: its reference's horizontal FOV, or none."""
    if not ref["solved_by_reference"]:
        return NO_REFERENCE
    fov = ref["fov_deg"]
    for lo, hi in BANDS:
        if lo <= fov < hi:
            return band_name(lo, hi)
    return band_name(*BANDS[-1])


def band_name(lo: float, hi: float) -> str:
    if lo == 0.0:
        return f"< {hi:g}°"
    return f"{lo:g}-{hi:g}°" if hi < 400 else f"> {lo:g}°"


def score(ref: dict, out: dict) -> dict:
    """One solver on one image: outcome and errors (see the module docstring)."""
    answered = out.get("error") is None and ("R" in out or out.get("ra_deg") is not None)
    row = {
        "time_ms": out.get("time_ms"),
        "error": out.get("error"),
        "failure": out.get("failure"),
    }
    if not answered:
        return {**row, "outcome": "unsolved"}
    if not ref["solved_by_reference"]:
        return {**row, "outcome": "answer, no reference"}
    result = score_answer(out, attitude_from_radec_roll(
        ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"]))  # fmt: skip
    row.update(boresight_arcsec=result.boresight_arcsec, roll_error_deg=result.roll_deg)
    return {**row, "outcome": "WRONG" if verdict(result) == "wrong" else "right"}


def run(folder: Path, entries: list[dict], runs: list[Solver], references) -> list[dict]:
    """Every solver on every file present: one row per (image, solver), its answer as the
    adapter printed it (scored against the references when the tables are written)."""
    present = [e for e in entries if (folder / e["name"]).is_file()]
    rows = []
    for s in runs:
        items = []
        for e in present:
            ref = references[e["name"]]
            fov = (ref.get("fov_deg") or GIVEN_FOV_DEG) if s.fov_given else None
            items.append({"path": str(folder / e["name"]), "fov_deg": fov})
        t0 = time.time()
        outs = []
        # in chunks, for the progress bar (one worker process per chunk)
        chunk = 20
        for start in tqdm(range(0, len(items), chunk), desc=s.label, unit="x20 images"):
            part, _ = run_adapter(s.python, s.adapter, list(s.args), items[start : start + chunk])
            outs.extend(part)
        for e, out in zip(present, outs, strict=True):
            rows.append({"name": e["name"], "solver": s.label, **out})
        right = sum(
            score(references[r["name"]], r)["outcome"] == "right"
            for r in rows
            if r["solver"] == s.label
        )
        print(
            f"{s.label}: {right}/{len(present)} right ({time.time() - t0:.0f} s)", file=sys.stderr
        )
    return rows


def verify_unreferenced(corpus, folder: Path, rows: list[dict]) -> None:
    """Each answer on an image astrometry.net did not solve blind, given back to it as a hint
    (``make_reference.solve_one`` with ``near``: within 5° of the answer's boresight, its
    width within 10 %, the same CPU limit): "answer, confirmed" when astrometry.net then
    solves it within ``WRONG_DEG`` of the answer, WRONG when it solves it elsewhere, "answer,
    unconfirmed" when it still finds nothing (in place). The hinted solves are kept in
    ``WORK/hinted`` (``hinted.json``) and not run again for the same answer."""
    work = corpus.WORK / "hinted"
    work.mkdir(parents=True, exist_ok=True)
    done_file = work / "hinted.json"
    done = json.loads(done_file.read_text()) if done_file.exists() else {}
    for r in rows:
        if r["outcome"] != "answer, no reference" or not r.get("fov_deg"):
            continue
        ra, dec, _, _ = radec_roll_from_attitude(answer_attitude(r))
        key = f"{r['name']} {ra:.3f} {dec:.3f} {r['fov_deg']:.3f}"
        if key not in done:
            status = corpus.solve_one({"name": r["name"]}, folder, near=(ra, dec, r["fov_deg"]),
                                      work=work)  # fmt: skip
            if status["solved"]:
                wcs, _ = corpus.wcs_of(r["name"], work)
                status["reference"] = corpus.convert(wcs, status["width"], status["height"])
            done[key] = status
            done_file.write_text(json.dumps(done, indent=1))
        status = done[key]
        if not status["solved"]:
            r["outcome"] = "answer, unconfirmed"
            continue
        found = {**status["reference"], "solved_by_reference": True}
        r.update(score(found, r))
        r["outcome"] = "answer, confirmed" if r["outcome"] == "right" else "WRONG"
        if r["outcome"] == "WRONG":
            r["hinted_reference"] = status["reference"]


RIGHT = ("right", "right, reference off")


def dispute_failed_references(corpus, folder: Path, references, rows: list[dict]) -> None:
    """A wrong answer against an astrometry.net answer that fails the catalog check
    (``make_reference.attitude_check``: a reference kept for its log-odds,
    ``check_overridden``, or a hinted solve of ``verify_unreferenced``) is checked the same
    way: when it passes and puts more catalog stars on detections, it is "right, reference
    off" (an image with a reference) or "answer, confirmed" (one without), listed under the
    tables with both checks; in place."""
    from starnav.catalog import load_catalog

    catalog = None
    for r in rows:
        ref = references[r["name"]]
        hinted = r.get("hinted_reference")
        if r["outcome"] != "WRONG" or ("check_overridden" not in ref and hinted is None):
            continue
        if catalog is None:
            catalog = load_catalog(None, mag_limit=corpus.CHECK_MAG_LIMIT)
        if hinted is None:
            theirs = ref["check"]["reference"]
        else:
            check = corpus.attitude_check(
                answer_attitude(hinted), hinted["fov_deg"], folder / r["name"], catalog
            )
            if corpus.check_passes(check):
                continue
            theirs = check["reference"]
        check = corpus.attitude_check(answer_attitude(r), r["fov_deg"], folder / r["name"], catalog)
        if corpus.check_passes(check) and check["reference"]["n_matched"] > theirs["n_matched"]:
            r["outcome"] = "answer, confirmed" if hinted else "right, reference off"
            r["dispute"] = {"answer": check["reference"], "reference": theirs}


def dispute_lines(rows: list[dict]) -> list[str]:
    """The answers counted right against a reference that failed the catalog check."""
    lines = []
    for r in rows:
        if "dispute" in r:
            a, ref = r["dispute"]["answer"], r["dispute"]["reference"]
            lines.append(
                f"- `{r['name']}`, {r['solver']}: {r.get('boresight_arcsec', 0) / 3600:.2f}° "
                f"from astrometry.net's boresight, roll {r.get('roll_error_deg', 0):.2f}° off; the "
                f"catalog check (Hp <= 6.5 on the detections) puts {a['n_matched']} of "
                f"{a['n_catalog']} stars on detections with this answer (median "
                f"{a['median_px']} px), {ref['n_matched']} of {ref['n_catalog']} with "
                f"astrometry.net's{' hinted solve' if 'hinted_reference' in r else ''} "
                f"(median {ref['median_px']} px)"
            )
    return lines


def counts(rows: list[dict]) -> tuple[int, int]:
    right = sum(r["outcome"] in RIGHT for r in rows)
    return right, sum(r["outcome"] == "WRONG" for r in rows)


def band_table(entries, references, rows, labels, before) -> list[str]:
    """Per band: images, astrometry.net's solved, each solver's right / wrong (and starnav's
    before, when given), starnav's median time."""
    by = {(r["name"], r["solver"]): r for r in rows}
    bands = [band_name(lo, hi) for lo, hi in BANDS] + [NO_REFERENCE]
    head = ["band (astrometry.net's field)", "images", "astrometry.net solved"]
    if before is not None:
        head.append("starnav before: right")
    head += [f"{label}: right / wrong" for label in labels]
    head += ["starnav median ms (right)", "astrometry.net median s"]
    lines = table_head(*head)
    groups = [(b, [e for e in entries if band_of(references[e["name"]]) == b]) for b in bands]
    in_range = [e for b, g in groups[1:5] for e in g]
    solved = [e for b, g in groups[:-1] for e in g]
    groups += [("all astrometry.net solved", solved), ("3-60° (the target band)", in_range)]
    for band, group in groups:
        if not group:
            continue
        names = [e["name"] for e in group]
        refs = [references[n] for n in names]
        ref_solved = sum(r["solved_by_reference"] for r in refs)
        cells = [band, len(group), ref_solved if band != NO_REFERENCE else 0]
        if before is not None:
            old = [before[n] for n in names if n in before]
            cells.append(sum(r["outcome"] == "right" for r in old) if old else "-")
        for label in labels:
            got = [by[(n, label)] for n in names if (n, label) in by]
            if band == NO_REFERENCE:
                kinds = Counter(r["outcome"] for r in got)
                cells.append(
                    f"{kinds['answer, confirmed']} confirmed, "
                    f"{kinds['answer, unconfirmed']} unconfirmed / {kinds['WRONG']}"
                )
            else:
                right, wrong = counts(got)
                cells.append(f"{right} / {wrong}")
        times = [by[(n, STARNAV_LABEL)]["time_ms"] for n in names if (n, STARNAV_LABEL) in by
                 and by[(n, STARNAV_LABEL)]["outcome"] in RIGHT]  # fmt: skip
        seconds = [r["seconds"] for r in refs if r["solved_by_reference"] and r.get("seconds")]
        cells.append(f"{np.median(times):.0f}" if times else "-")
        cells.append(f"{np.median(seconds):.1f}" if seconds else "-")
        lines.append(table_row(*cells))
    return lines


def failure_table(entries, references, rows) -> list[str]:
    """starnav's unsolved images per failure class and band (astrometry.net solved them or
    not)."""
    mine = {r["name"]: r for r in rows if r["solver"] == STARNAV_LABEL}
    bands = [band_name(lo, hi) for lo, hi in BANDS] + [NO_REFERENCE]
    classes = Counter()
    cells = Counter()
    for e in entries:
        r = mine.get(e["name"])
        if r is None or r["outcome"] != "unsolved":
            continue
        cls = r["failure"] or "(none named)"
        classes[cls] += 1
        cells[(cls, band_of(references[e["name"]]))] += 1
    lines = table_head("failure", "images", *bands)
    for cls, n in classes.most_common():
        lines.append(table_row(cls, n, *(cells[(cls, b)] or "" for b in bands)))
    return lines


POSITION_HINTS = ("RA/DEC", "OBJCTRA/OBJCTDEC", "CRVAL1/CRVAL2")  # ``detect.header``'s names


def hint_lines(entries, rows) -> list[str]:
    """The files whose FITS header gave starnav a position (as ``starnav solve`` reads it;
    astrometry.net's references were made without it), and starnav's outcome on each."""
    mine = {r["name"]: r for r in rows if r["solver"] == STARNAV_LABEL}
    told = [
        (e["name"], mine[e["name"]]["outcome"])
        for e in entries
        if e["name"] in mine and set(mine[e["name"]].get("hints") or ()) & set(POSITION_HINTS)
    ]
    if not told:
        return []
    outcomes = Counter(outcome for _, outcome in told)
    said = ", ".join(f"{n} {outcome}" for outcome, n in outcomes.most_common())
    return [
        f"{len(told)} of these files give a position in their FITS header, which starnav "
        f"searches first as `starnav solve` does ({said}): "
        + ", ".join(f"`{name}`" for name, _ in told),
        "",
    ]


def image_table(entries, references, rows, labels) -> list[str]:
    by = {(r["name"], r["solver"]): r for r in rows}
    lines = table_head("image", "source", "kind", "band", "astrometry.net s",
                       *labels, "starnav ms", "starnav's reason (not solved)")  # fmt: skip
    for e in entries:
        name, ref = e["name"], references[e["name"]]
        cells = []
        for label in labels:
            r = by.get((name, label))
            if r is None:
                cells.append("absent")
                continue
            cells.append({"unsolved": "no"}.get(r["outcome"], r["outcome"]))
        mine = by.get((name, STARNAV_LABEL))
        ms = "" if mine is None or mine["time_ms"] is None else f"{mine['time_ms']:.0f}"
        why = ""
        if mine is not None and mine["outcome"] == "unsolved":
            why = (mine["error"] or "").replace("|", "/")[:200]
        seconds = f"{ref['seconds']:.1f}" if ref.get("seconds") else ""
        lines.append(table_row(f"`{name}`", e["repository"], e["kind"], band_of(ref), seconds,
                               *cells, ms, why))  # fmt: skip
    return lines


def source_table(entries, references) -> list[str]:
    """The corpus by source: its set, kinds, licence, and images per band."""
    bands = [band_name(lo, hi) for lo, hi in BANDS] + [NO_REFERENCE]
    lines = table_head("source", "set", "kind", "licence", "images", *bands)
    repos = sorted({e["repository"] for e in entries}, key=str.lower)
    for repo in repos:
        mine = [e for e in entries if e["repository"] == repo]
        per = Counter(band_of(references[e["name"]]) for e in mine)
        kinds = ", ".join(sorted({e["kind"] for e in mine}))
        lines.append(table_row(repo, mine[0]["set"], kinds, mine[0]["licence"], len(mine),
                               *(per[b] or "" for b in bands)))  # fmt: skip
    return lines


def write_doc(args, entries, references, rows, labels, installs, before, t_start) -> str:
    parts = [
        "# starnav on real photographs: the corpus by field width",
        "",
        "Generated by `benchmarks/peers/real_images.py` (its docstring says what is measured "
        "and how) on the corpus of `tests/data/real` (its README: sources, licences, "
        "references). Peers: "
        + ("; ".join(f"{k}: `pip install {v}`" for k, v in installs.items()) or "none")
        + ". starnav and cedar-solve with the field of view unknown, tetra3rs with the "
        f"reference's given. Right: within {WRONG_DEG:g}° of astrometry.net's answer in "
        "boresight and roll, its parity.",
        "",
    ]
    for name in SETS:
        chosen = [e for e in entries if e["set"] == name]
        if not chosen:
            continue
        sources = len({e["repository"] for e in chosen})
        title = {
            "development": "Development set",
            "held_back": "Held-back set",
            "held_back_2": "Second held-back set",
            "held_back_3": "Third held-back set",
        }[name]
        parts += [
            f"## {title}: {len(chosen)} photographs from {sources} sources",
            "",
            *band_table(chosen, references, rows, labels, before),
            "",
            "starnav's unsolved images by the failure it names (all bands):",
            "",
            *failure_table(chosen, references, rows),
            "",
            *hint_lines(chosen, rows),
        ]
    disputed = dispute_lines(rows)
    if disputed:
        parts += [
            "Answers counted right (or confirmed) against an astrometry.net answer that fails "
            "the catalog check (a reference kept for its log-odds, or a hinted solve; "
            "`dispute_failed_references`):",
            "",
            *disputed,
            "",
        ]
    parts += [
        "## Every image",
        "",
        *image_table(entries, references, rows, labels),
        "",
        "## The corpus by source",
        "",
        *source_table(entries, references),
        "",
        *(
            [
                "The answers are the saved rows of earlier runs (`--rows`), scored and verified "
                "when these tables were written: the times are those runs', the line below is "
                "the writing's.",
                "",
            ]
            if args.from_rows
            else []
        ),
        f"{machine()}; `nice python benchmarks/peers/real_images.py {' '.join(sys.argv[1:])}`"
        f", {time.time() - t_start:.0f} s.",
    ]
    text = "\n".join(parts) + "\n"
    if str(args.out) != "-":
        Path(args.out).write_text(text)
    return text


def read_rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=(*SETS, "all"), default="all")
    parser.add_argument("--solvers", default="starnav,cedar-solve,tetra3rs")
    parser.add_argument("--rows", type=Path, help="write one JSON line per image and solver")
    parser.add_argument("--from-rows", type=Path, nargs="+", help="tables of saved rows, no run")
    parser.add_argument("--before", type=Path, help="rows of an earlier run (starnav's)")
    parser.add_argument("--out", type=Path, default=DOC, help="markdown file ('-': none)")
    parser.add_argument("only", nargs="*", help="only these files (a trial run)")
    args = parser.parse_args()
    t_start = time.time()
    corpus = load_corpus()
    folder = corpus.corpus_dir()
    references = json.loads((DATA / "reference.json").read_text())["images"]
    entries = [
        e
        for e in corpus.sources()
        if (args.set == "all" or e["set"] == args.set) and (not args.only or e["name"] in args.only)
    ]
    if args.from_rows:
        rows = [r for path in args.from_rows for r in read_rows(path)]
        labels = list(dict.fromkeys(r["solver"] for r in rows))
        _, installs = solvers(cache_dir(), labels)  # the peers' install lines
    else:
        runs, installs = solvers(cache_dir(), args.solvers.split(","))
        rows = run(folder, entries, runs, references)
        labels = [s.label for s in runs]
    if args.rows:
        args.rows.write_text("".join(json.dumps(r) + "\n" for r in rows))
    rows = [{**r, **score(references[r["name"]], r)} for r in rows if r["name"] in references]
    verify_unreferenced(corpus, folder, rows)
    dispute_failed_references(corpus, folder, references, rows)
    before = None
    if args.before:
        old = [r for r in read_rows(args.before) if r["solver"] == STARNAV_LABEL]
        before = {r["name"]: score(references[r["name"]], r) for r in old}
    print(write_doc(args, entries, references, rows, labels, installs, before, t_start))


if __name__ == "__main__":
    main()
