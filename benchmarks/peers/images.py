"""starnav, cedar-solve and tetra3rs solving the same rendered image FILES, into docs/images.md.

    python benchmarks/peers/images.py --frames 200 [--seed 2026] [--keep DIR]

Frames: ``--frames`` attitudes uniform on SO(3) (parity +1, as a real camera sees the sky),
rendered with ``starnav.simulate.render`` and its ``seed-1024`` preset (1024 px, 20°, Gaussian PSF,
photon, read and quantisation noise) from the Hipparcos stars with Hp <= 7, written as 16-bit
PNG files in a temporary folder (``--keep DIR`` keeps them there). Frame i's attitude and noise
come from the seed (``--seed``, i). Every solver gets the same files.

Solvers, each in a process of its own, pinned to one core with OMP/OPENBLAS/MKL/RAYON threads
1, reading the file names as JSON lines and timing every step itself with ``perf_counter``:

* starnav (this script in ``--starnav-worker`` mode): ``starnav.detect.read.read_image`` (file
  to array, "decode", with a FITS file's header hints) then ``starnav.solve_image(array,
  fov_deg=...)`` ("array to attitude": detection, identification, fit), FOV unknown
  (``fov_deg=None``: searched in its default range) and FOV given (20°). A first solve of the
  first file, not counted, loads the catalog and pair database (the peers load their databases
  before the first file too).
* cedar-solve (``benchmarks/peers/peer_cedar_image.py`` in its own environment): ``Image.open`` +
  ``load`` (decode), then ``solve_from_image`` (its conversion to a float array, its own
  centroiding with its defaults, and the solve) with ``fov_estimate`` None and 20.
* tetra3rs (``benchmarks/peers/peer_tetra3rs_image.py``; Pillow added to its environment):
  ``Image.open`` + ``numpy.asarray`` (decode), then its centroid extractor (``extract_centroids``
  through a ``CentroidExtractor``, or ``extract_centroids_fast``; ``threads=1``) and
  ``solve_from_centroids`` with the FOV estimate, which it needs.

Each peer runs with its stock database and with one built from the same Hp <= 7 stars for a
20° field (``benchmarks/peers/peers.py`` makes the environments and databases and caches them).

Conventions are checked on the first ``--check-frames`` files before anything is scored, and
the script stops when one fails: (1) each extractor's centroids (starnav's, cedar's, both of
tetra3rs's) against the rendered stars' true positions: the mean offset in x and in y must be
under 0.1 px (a half-pixel origin slip would show as 0.5 px); (2) every FOV-given solve with a
database built from the rendered stars must put the boresight within 10″ (median) of the truth
(a 0.5 px slip is about 35″ at 20° / 1024 px).

Scores: solved = an answer; wrong = boresight or roll 0.5° or more off, or the wrong parity
(``harness.verdict``); within 20″ = boresight error <= 20″ with the right parity. The error
statistics (boresight, roll about the boresight, relative FOV error) are over the answers that
are not wrong.
"""

from __future__ import annotations

import os

# one core: thread pools of 1, set before numpy loads, here and in every process started here
os.environ.update(
    dict.fromkeys(
        ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"), "1"
    )
)

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
from benchmarks.harness import (
    DOCS,
    WRONG_DEG,
    machine,
    replace_block,
    score_answer,
    table_head,
    table_row,
    verdict,
)
from benchmarks.peers.peers import (
    PEERS,
    Peer,
    peak_rss_mb,
    peer_database,
    peer_python,
    run_adapter,
    write_catalog_csv,
)
from starnav.catalog import load_catalog
from starnav.errors import StarnavError
from starnav.identify import cache_dir

DOC = DOCS / "images.md"
MAG_LIMIT = 7.0
PRESET = "seed-1024"
FOV_GIVEN_DEG = 20.0
WITHIN_ARCSEC = 20.0
CHECK_OFFSET_PX = 0.1
CHECK_BORESIGHT_ARCSEC = 10.0
MATCH_PX = 1.0  # a centroid this close to a true star is that star (for the offset check)
ISOLATED_PX = 6.0  # true stars with a neighbour closer than this are left out of that check
STARNAV = Peer("starnav", "images.py", (f"starnav=={starnav.__version__}",))
TARGETS = {  # the targets for images, starnav with the FOV unknown
    "solved %": (">=", 99.0),
    "boresight median ″": ("<=", 5.0),
    "FOV error max %": ("<=", 0.1),
    "array to attitude median ms": ("<=", 15.0),
}


# ----------------------------------------------------------------------------------------------
# frames


@dataclasses.dataclass(frozen=True, eq=False)
class Truth:
    """One rendered file and what it shows: attitude, drawn stars' pixels, the FOV."""

    path: str
    R_cam_from_icrs: np.ndarray
    xy: np.ndarray
    fov_deg: float


def render_files(catalog, n: int, seed: int, folder: Path) -> list[Truth]:
    """Render ``n`` frames of the preset camera at random attitudes into 16-bit PNG files."""
    from starnav.simulate.render import PRESETS, render_frame, write_image

    camera, settings = PRESETS[PRESET]
    truths = []
    for i in tqdm(range(n), desc="render", file=sys.stderr, leave=False):
        seq = np.random.SeedSequence([seed, i])
        R = Rotation.random(random_state=np.random.default_rng(seq)).as_matrix()
        frame_seed = int(seq.generate_state(1)[0])
        frame = render_frame(
            catalog, camera, R, dataclasses.replace(settings, mag_limit=MAG_LIMIT, seed=frame_seed)
        )
        path = folder / f"frame{i:04d}.png"
        write_image(path, frame.image)
        truths.append(Truth(str(path), R, np.asarray(frame.xy), camera.fov_deg))
    return truths


# ----------------------------------------------------------------------------------------------
# starnav's worker (same protocol as the peers' adapters)


def starnav_worker(mode: str) -> None:
    """Solve (or centroid) the files named as JSON lines on stdin; one JSON line each."""
    from starnav.detect.header import fits_hints
    from starnav.detect.read import read_image
    from starnav.detect.stars import detect_stars

    items = [json.loads(line) for line in sys.stdin if line.strip()]
    t0 = time.perf_counter()
    if mode == "solve" and items:  # loads the catalog and the pair database; not counted
        starnav.solve_image(read_image(items[0]["path"]), fov_deg=items[0]["fov_deg"])
    load_s = time.perf_counter() - t0
    for item in items:
        t0 = time.perf_counter()
        image = read_image(item["path"])
        hints = fits_hints(item["path"])  # a FITS header's, as ``starnav solve FILE`` reads them
        t1 = time.perf_counter()
        read_ms = (t1 - t0) * 1e3
        if mode == "centroids":
            xy = detect_stars(image).xy
            out = {"xy": xy.tolist(), "time_ms": (time.perf_counter() - t1) * 1e3}
        else:
            out = starnav_solve(image, item["fov_deg"], read_ms, hints)
        print(json.dumps(out), flush=True)
    summary = {"done": True, "peak_rss_mb": peak_rss_mb(), "load_s": load_s}
    print(json.dumps({**summary, "version": starnav.__version__}), flush=True)


def starnav_solve(image: np.ndarray, fov_deg: float | None, read_ms: float, hints) -> dict:
    t0 = time.perf_counter()
    try:
        res = starnav.solve_image(image, fov_deg=fov_deg, hints=hints)
    except StarnavError as exc:
        return {"read_ms": read_ms, "time_ms": None, "error": str(exc)}
    out = {
        "read_ms": read_ms,
        "time_ms": (time.perf_counter() - t0) * 1e3,
        "extract_ms": res.detect_ms,
        "peer_ms": res.solve_ms,
        "n_centroids": len(res.detections.xy),
        "hints": list(hints.sources),
    }
    s = res.solution
    if s is None:
        return {**out, "error": res.reason or "unsolved", "failure": getattr(res, "failure", None)}
    attitude = {"R": s.R_cam_from_icrs.tolist(), "parity": s.parity, "fov_deg": s.fov_deg}
    return {**out, **attitude, "n_matched": s.n_matched, "error": None}


# ----------------------------------------------------------------------------------------------
# solvers


@dataclasses.dataclass(frozen=True)
class Mode:
    """One row of the table: a solver with a database, an FOV setting and its adapter."""

    solver: str
    database: str
    fov_deg: float | None  # None: unknown
    centroids: str  # who finds the stars
    adapter: Peer
    python: Path
    args: tuple[str, ...]

    @property
    def label(self) -> str:
        fov = "unknown" if self.fov_deg is None else f"{self.fov_deg:g}° given"
        return f"{self.solver}, {self.database}, {self.centroids}, FOV {fov}"

    def run(self, truths: list[Truth]) -> tuple[list[dict], dict]:
        items = [{"path": t.path, "fov_deg": self.fov_deg} for t in truths]
        return run_adapter(self.python, self.adapter, list(self.args), items)


def ensure_pillow(python: Path) -> str:
    """tetra3rs takes arrays only: Pillow (starnav's version) decodes the files for it."""
    pillow = f"pillow=={version('pillow')}"
    if subprocess.run([str(python), "-I", "-c", "import PIL"], capture_output=True).returncode:
        print(f"adding {pillow} to {python.parents[1]} ...", file=sys.stderr)
        pip = [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
        subprocess.run([*pip, pillow], check=True)
    return pillow


def make_modes(root: Path, catalog) -> tuple[list[Mode], list, dict, dict]:
    """The table's rows, the centroid extractors (name, adapter, interpreter, arguments), the
    peers' install lines and their databases' build reports."""
    csv = write_catalog_csv(catalog, root)
    py = Path(sys.executable)
    worker = ("--starnav-worker", "solve")
    modes = [
        Mode(
            f"starnav {starnav.__version__}", "embedded Hipparcos", fov, "sep", STARNAV, py, worker
        )
        for fov in (None, FOV_GIVEN_DEG)
    ]
    extractors = [("starnav (sep)", STARNAV, py, ("--starnav-worker", "centroids"))]
    installs, databases = {}, {}
    for peer in PEERS:
        python, installs[peer.name] = peer_python(peer, root)
        label = f"{peer.name} {peer.version}"
        if peer.name == "cedar-solve":
            adapter = dataclasses.replace(peer, adapter="peer_cedar_image.py")
            extractors.append((f"{label} (its own)", adapter, python, ("centroids",)))
        else:
            installs[peer.name] += f" {ensure_pillow(python)}"
            adapter = dataclasses.replace(peer, adapter="peer_tetra3rs_image.py")
            for extractor in ("standard", "fast"):
                name = f"{label} ({extractor_name(extractor)})"
                extractors.append((name, adapter, python, ("centroids", "--extractor", extractor)))
        for which in (None, FOV_GIVEN_DEG):
            db_arg, report = peer_database(
                python, peer, root, which, csv, catalog.fingerprint, tag="hp7"
            )
            stock = (
                "stock (bundled Gaia, 10-30°)" if peer.stock_built else "stock (shipped, 10-30°)"
            )
            database = stock if which is None else f"Hp <= 7, built, {which:g}°"
            databases[(label, database)] = report
            if peer.name == "cedar-solve":
                for fov in (None, FOV_GIVEN_DEG):
                    args = ("solve", "--db", db_arg)
                    modes.append(Mode(label, database, fov, "its own", adapter, python, args))
            else:
                for extractor in ("standard", "fast"):
                    name = extractor_name(extractor)
                    args = ("solve", "--db", db_arg, "--extractor", extractor)
                    modes.append(Mode(label, database, FOV_GIVEN_DEG, name, adapter, python, args))
    return modes, extractors, installs, databases


def extractor_name(extractor: str) -> str:
    return "extract_centroids" + ("_fast" if extractor == "fast" else "")


# ----------------------------------------------------------------------------------------------
# conventions


def centroid_offsets(truths: list[Truth], found: list[dict]) -> dict:
    """Mean and rms offset (px) of the centroids from the isolated true stars they match."""
    d = []
    for t, f in zip(truths, found, strict=True):
        xy = np.asarray(f.get("xy") or [], dtype=float).reshape(-1, 2)
        tree = cKDTree(t.xy)
        isolated = tree.query(t.xy, k=2)[0][:, 1] > ISOLATED_PX
        dist, idx = tree.query(xy, distance_upper_bound=MATCH_PX)
        hit = np.isfinite(dist)
        keep = hit.copy()
        keep[hit] = isolated[idx[hit]]
        d.append(xy[keep] - t.xy[idx[keep]])
    d = np.vstack(d)
    if len(d) == 0:
        return {"n": 0, "dx": np.nan, "dy": np.nan, "rms": np.nan}
    rms = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    return {"n": len(d), "dx": float(d[:, 0].mean()), "dy": float(d[:, 1].mean()), "rms": rms}


def check_conventions(truths: list[Truth], modes: list[Mode], extractors: list) -> list[str]:
    """Stop unless every extractor's origin and every built-database attitude is right."""
    lines = []
    items = [{"path": t.path} for t in truths]
    for name, adapter, python, args in extractors:
        found, _ = run_adapter(python, adapter, list(args), items)
        c = centroid_offsets(truths, found)
        line = (
            f"- centroids, {name}: {c['n']} stars matched, mean offset x {c['dx']:+.3f} px, "
            f"y {c['dy']:+.3f} px, rms {c['rms']:.3f} px"
        )
        print(line, file=sys.stderr)
        if not (abs(c["dx"]) < CHECK_OFFSET_PX and abs(c["dy"]) < CHECK_OFFSET_PX):
            raise SystemExit(f"convention check failed: {line[2:]}")
        lines.append(line)
    for m in modes:
        if m.fov_deg is None:
            continue
        outs, _ = m.run(truths)
        errs = [score_answer(o, t.R_cam_from_icrs) for t, o in zip(truths, outs, strict=True)]
        bore = [e.boresight_arcsec for e in errs if e is not None and e.same_parity]
        median = float(np.median(bore)) if bore else np.inf
        line = (
            f"- attitude, {m.label}: {len(bore)}/{len(truths)} solved with the right parity, "
            f"boresight error median {median:.2f}″"
        )
        print(line, file=sys.stderr)
        if "built" in m.database and not median <= CHECK_BORESIGHT_ARCSEC:
            raise SystemExit(f"convention check failed: {line[2:]}")
        lines.append(line)
    return lines


# ----------------------------------------------------------------------------------------------
# scores


def score(truths: list[Truth], outs: list[dict]) -> dict:
    solved = wrong = within = 0
    bore, roll, fov = [], [], []
    for t, o in zip(truths, outs, strict=True):
        e = score_answer(o, t.R_cam_from_icrs)
        if e is None:
            continue
        solved += 1
        if verdict(e) == "wrong":
            wrong += 1
            continue
        within += e.boresight_arcsec <= WITHIN_ARCSEC
        bore.append(e.boresight_arcsec)
        roll.append(e.roll_arcsec)
        if o.get("fov_deg") is not None:
            fov.append(100 * abs(o["fov_deg"] / t.fov_deg - 1))

    def times(key: str) -> np.ndarray:
        return np.array([o[key] for o in outs if o.get(key) is not None], dtype=float)

    whole = [
        o["read_ms"] + o["time_ms"]
        for o in outs
        if None not in (o.get("read_ms"), o.get("time_ms"))
    ]
    n = len(truths)
    return {
        "solved %": 100 * solved / n,
        "within %": 100 * within / n,
        "wrong": wrong,
        "boresight median ″": stat(bore, 50),
        "boresight p95 ″": stat(bore, 95),
        "roll median ″": stat(roll, 50),
        "FOV error median %": stat(fov, 50),
        "FOV error max %": stat(fov, 100),
        "decode median ms": stat(times("read_ms"), 50),
        "array to attitude median ms": stat(times("time_ms"), 50),
        "array to attitude p95 ms": stat(times("time_ms"), 95),
        "array to attitude max ms": stat(times("time_ms"), 100),
        "centroiding median ms": stat(times("extract_ms"), 50),
        "file to attitude median ms": stat(whole, 50),
    }


def stat(values, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else float("nan")


def fmt(v: float, digits: int = 2) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{v:.{digits}f}" if abs(v) < 10 else f"{v:.1f}"


def table(rows: list[tuple[Mode, dict]]) -> list[str]:
    lines = table_head(
        "solver",
        "database",
        "centroids",
        "FOV",
        "solved %",
        "within 20″ %",
        "wrong",
        "boresight ″ median / p95",
        "roll ″ median",
        "FOV error % median / max",
        "decode ms",
        "array to attitude ms median / p95 / max",
        "of which centroids ms",
        "file to attitude ms",
    )
    for m, r in rows:
        fov = "unknown" if m.fov_deg is None else f"{m.fov_deg:g}° given"
        lines.append(
            table_row(
                m.solver,
                m.database,
                m.centroids,
                fov,
                f"{r['solved %']:.1f}",
                f"{r['within %']:.1f}",
                r["wrong"],
                f"{fmt(r['boresight median ″'])} / {fmt(r['boresight p95 ″'])}",
                fmt(r["roll median ″"], 1),
                f"{fmt(r['FOV error median %'], 3)} / {fmt(r['FOV error max %'], 3)}",
                fmt(r["decode median ms"], 1),
                f"{fmt(r['array to attitude median ms'], 1)} / "
                f"{fmt(r['array to attitude p95 ms'], 1)} / "
                f"{fmt(r['array to attitude max ms'], 1)}",
                fmt(r["centroiding median ms"], 1),
                fmt(r["file to attitude median ms"], 1),
            )
        )
    return lines


def target_lines(r: dict) -> list[str]:
    lines = []
    for key, (op, goal) in TARGETS.items():
        value = r[key]
        met = value >= goal if op == ">=" else value <= goal
        lines.append(
            f"- {key}: {fmt(value, 3)} (target {op} {goal:g}): {'met' if met else 'NOT met'}"
        )
    return lines


def findings(truths: list[Truth], rows: list[tuple[Mode, dict]], answers: dict) -> list[str]:
    """Wrong answers of any row, and frames starnav (FOV unknown) leaves unsolved."""
    out = []
    for m, _ in rows:
        for i, (t, o) in enumerate(zip(truths, answers[m.label], strict=True)):
            e = score_answer(o, t.R_cam_from_icrs)
            if e is None:
                if m.adapter is STARNAV and m.fov_deg is None:
                    out.append(f"- {m.label}: frame {i} unsolved ({o.get('error')})")
                continue
            if verdict(e) == "wrong":
                out.append(
                    f"- {m.label}: frame {i} wrong, boresight {e.boresight_deg:.3f}°, roll "
                    f"{e.roll_deg:.3f}°{'' if e.same_parity else ', wrong parity'}"
                )
    return out


# ----------------------------------------------------------------------------------------------
# the run


def pin_one_core() -> int:
    core = max(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})  # inherited by every process started from here
    return core


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--check-frames", type=int, default=8)
    parser.add_argument("--keep", type=Path, help="write the files here and keep them")
    parser.add_argument("--out", type=Path, default=DOC, help="markdown file ('-': none)")
    parser.add_argument("--starnav-worker", choices=("solve", "centroids"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.starnav_worker:
        starnav_worker(args.starnav_worker)
        return
    t_start = time.time()
    core = pin_one_core()
    root = cache_dir()
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    modes, extractors, installs, databases = make_modes(root, catalog)
    with tempfile.TemporaryDirectory(prefix="starnav-images-") as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        truths = render_files(catalog, args.frames, args.seed, folder)
        checks = check_conventions(truths[: args.check_frames], modes, extractors)
        rows, answers = [], {}
        for m in modes:
            t0 = time.time()
            outs, _ = m.run(truths)
            r = score(truths, outs)
            rows.append((m, r))
            answers[m.label] = outs
            print(
                f"{m.label}: solved {r['solved %']:.1f} %, within 20″ {r['within %']:.1f} %, "
                f"wrong {r['wrong']}, boresight median {r['boresight median ″']:.2f}″, "
                f"array to attitude {r['array to attitude median ms']:.1f} ms median "
                f"({time.time() - t0:.0f} s)",
                file=sys.stderr,
            )
    write_doc(args, truths, rows, answers, checks, installs, databases, core, t_start)


def write_doc(args, truths, rows, answers, checks, installs, databases, core, t_start) -> None:
    n_stars = [len(t.xy) for t in truths]
    unknown = next(r for m, r in rows if m.adapter is STARNAV and m.fov_deg is None)
    built = "; ".join(
        f"{label} {database}: {report['build_s']:.1f} s, {report['bytes'] / 1e6:.1f} MB"
        for (label, database), report in databases.items()
        if "build_s" in report and "built" in database
    )
    lines = [
        f"{len(truths)} frames, `{PRESET}` preset (1024 px, {truths[0].fov_deg:g}°), Hipparcos "
        f"Hp <= {MAG_LIMIT:g}: {int(np.median(n_stars))} stars drawn per frame (median, "
        f"{min(n_stars)}-{max(n_stars)}); seed {args.seed}. One core (CPU {core}), thread "
        "pools of 1. Peers: "
        + "; ".join(f"{name}: `pip install {how}`" for name, how in installs.items())
        + f". Databases built from the rendered stars: {built}.",
        "",
        *table(rows),
        "",
        "Each solver read every PNG file itself, in a process of its own. decode: the file to "
        "the array (or PIL image) the solver takes; array to attitude: everything after that, "
        "centroiding included (cedar: `solve_from_image`, whose centroiding time is its own "
        "`T_extract`); file to attitude: the sum, per file. solved: an answer; wrong: "
        f"boresight or roll {WRONG_DEG:g}° or more off, or the wrong parity; within "
        f"{WITHIN_ARCSEC:g}″: boresight error <= {WITHIN_ARCSEC:g}″. Error statistics over the "
        "answers that are not wrong (roll: rotation about the boresight); FOV error relative to "
        "the true horizontal FOV. tetra3rs needs an FOV estimate, so it has no FOV-unknown row.",
        "",
        "starnav with the FOV unknown against the targets for images:",
        "",
        *target_lines(unknown),
        "",
        f"Convention checks on the first {args.check_frames} files (the script stops when one "
        "fails):",
        "",
        *checks,
        "",
        "Frames to look at (wrong answers; frames starnav leaves unsolved with the FOV unknown):",
        "",
        *(findings(truths, rows, answers) or ["- none"]),
        "",
        f"{machine()}; `python benchmarks/peers/images.py --frames {args.frames} --seed "
        f"{args.seed}`, "
        f"{time.time() - t_start:.0f} s.",
    ]
    text = "\n".join(lines)
    print(text)
    if str(args.out) != "-":
        missing = (
            "# Solving image files: starnav, cedar-solve and tetra3rs\n\n"
            "Generated by `benchmarks/peers/images.py` (its docstring says what is measured and "
            "how)."
        )
        replace_block(args.out, "images", text, missing=missing)


if __name__ == "__main__":
    main()
