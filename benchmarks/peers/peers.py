"""starnav, cedar-solve and tetra3rs on the same simulated frames, into docs/peers.md.

    python benchmarks/peers/peers.py --frames 300 [--scenarios a b c d]

Scenarios (boresights uniform on the sphere, random roll, pinhole, Hipparcos Hp <= 6 as starnav
loads it, brightest first): (a) 12°, 512 px, 0.1 px noise; (b) as (a) with 0.5 px, 2 false
stars, 10 % of the stars dropped; (c) 20°, 1024 px, 0.2 px; (d) as (a) but only frames with 3
to 6 catalog stars in the image (drawn until one has). Frame i of scenario s is made from the
seed (``--seed``, s, i), so every solver gets the same frames and any one can be remade.

starnav runs in this process (catalog and pair database loaded first; time =
``SolveResult.time_ms``, ``sigma_px`` = the scenario's noise). Each peer runs in its own virtual
environment under ``$STARNAV_CACHE_DIR/venvs/<peer>`` (made on first use; cedar-solve pins
numpy<2 and Pillow<9, starnav needs numpy 2), through ``benchmarks/peers/peer_cedar.py`` /
``benchmarks/peers/peer_tetra3rs.py`` in a subprocess that times each solve itself and reports its
peak memory. Each peer is run with its stock database and with one built from the same
Hp <= 6 stars for the scenario's field (cached under ``$STARNAV_CACHE_DIR/peers``, with the
build time, size and build memory). Peak memory is that of the solving process (``VmHWM``;
not ``ru_maxrss``, which on Linux a subprocess inherits from its parent at the fork); for
starnav the frames are solved again in a subprocess (``--starnav-worker``) that reports it.

Before any score counts, every solver is run on noise-free frames of both parities at each
field used, and every answer must agree with the truth within 0.01° in boresight and roll,
with the right parity (the script stops otherwise). Scoring (``harness.verdict``): correct =
boresight within 0.05° and roll within 0.5° (with the right parity, when the solver reports
one): ``starnav evaluate``'s rule, whose "within 5 of its own sigmas" no answer here takes, as
none reports sigmas; wrong = boresight or roll 0.5° or more off, or the wrong parity; inexact =
the rest of the answers; none = no answer.
"""

from __future__ import annotations

import argparse
import gc
import json
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
from benchmarks.harness import (
    DOCS,
    AttitudeScore,
    machine,
    replace_block,
    score_answer,
    table_head,
    table_row,
    verdict,
)
from starnav.api import get_database, make_camera, solve_stars
from starnav.catalog import load_catalog
from starnav.errors import StarnavError
from starnav.identify import cache_dir
from starnav.simulate import simulate_frame

BENCH = Path(__file__).resolve().parent  # this script, the adapters and the other peer scripts
DOC = DOCS / "peers.md"
MAG_LIMIT = 6.0
CHECK_TOL_DEG = 0.01

SCENARIOS = {
    "a": {
        "title": "(a) 12°, 512 px, Hp <= 6, 0.1 px",
        "fov_deg": 12.0,
        "width": 512,
        "noise_px": 0.1,
    },
    "b": {
        "title": "(b) 12°, 512 px, Hp <= 6, 0.5 px, 2 false stars, 10 % missing",
        "fov_deg": 12.0,
        "width": 512,
        "noise_px": 0.5,
        "false_stars": 2,
        "missing_frac": 0.1,
    },
    "c": {
        "title": "(c) 20°, 1024 px, Hp <= 6, 0.2 px",
        "fov_deg": 20.0,
        "width": 1024,
        "noise_px": 0.2,
    },
    "d": {
        "title": "(d) few stars: 3-6 Hp <= 6 stars in view, 12°, 512 px, 0.1 px",
        "fov_deg": 12.0,
        "width": 512,
        "noise_px": 0.1,
        "in_view": (3, 6),
    },
}


@dataclass(frozen=True)
class Peer:
    name: str
    adapter: str
    requirements: tuple[str, ...]
    fallback: tuple[tuple[str, ...], ...] = ()  # pip install steps, if the pinned set fails
    db_suffix: str = ".bin"
    stock_built: bool = False  # no database shipped: "build-stock" makes its default one
    tuned: tuple[str, ...] = ()  # adapter options of an extra, non-default row

    @property
    def version(self) -> str:
        return self.requirements[0].split("==")[1]


PEERS = (
    Peer(
        "cedar-solve",
        "peer_cedar.py",
        # the wheel's own pins (numpy<2, Pillow<9, scipy<2); Pillow 8.4.0 has no wheel for
        # Python 3.11 and is built from its sdist (needs a C compiler, zlib and libjpeg headers)
        ("cedar-solve==0.5.1", "numpy==1.26.4", "scipy==1.17.1", "Pillow==8.4.0"),
        # without them: cedar-solve without its pins and Pillow 9.5.0 (a cp311 wheel); cedar
        # uses Pillow only to load images and draw its debug picture, not to solve centroids
        (
            ("--no-deps", "cedar-solve==0.5.1"),
            ("numpy==1.26.4", "scipy==1.17.1", "Pillow==9.5.0"),
        ),
        db_suffix=".npz",
    ),
    # tuned: tetra3rs's pattern tolerance defaults to the database's 0.001, too tight for 0.5 px
    # at 12° / 512 px; 0.002 is cedar-solve's default (an extra row, marked)
    Peer(
        "tetra3rs",
        "peer_tetra3rs.py",
        ("tetra3rs==0.14.0",),
        stock_built=True,
        tuned=("--match-max-error", "0.002"),
    ),
)


# ----------------------------------------------------------------------------------------------
# environments and databases


def peer_python(peer: Peer, root: Path) -> tuple[Path, str]:
    """The interpreter of the peer's environment (made on first use) and how it was installed."""
    venv = root / "venvs" / peer.name
    python = venv / "bin" / "python"
    marker = venv / "starnav-peer.json"
    if python.exists() and marker.exists():
        return python, json.loads(marker.read_text())["install"]
    print(f"making {venv} ...", file=sys.stderr)
    subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True)
    pip = [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    done = subprocess.run([*pip, *peer.requirements])
    install = " ".join(peer.requirements)
    if done.returncode != 0:
        if not peer.fallback:
            raise SystemExit(f"pip could not install {install}")
        print(f"{install} failed; trying {peer.fallback}", file=sys.stderr)
        for step in peer.fallback:
            subprocess.run([*pip, *step], check=True)
        install = "; ".join(" ".join(step) for step in peer.fallback)
    marker.write_text(json.dumps({"install": install}))
    return python, install


def run_adapter(python: Path, peer: Peer, args: list[str], frames: list[dict] | None = None):
    """Run a peer adapter; (per-frame rows, final summary line) or the build report. A peer's
    runs isolated (``-I``: its own environment only); starnav's own worker (``images.py``)
    runs in this interpreter's environment as given, ``PYTHONPATH`` included, so that it
    solves with the starnav this script imports."""
    isolated = [] if peer.name == "starnav" else ["-I"]
    cmd = [str(python), *isolated, str(BENCH / peer.adapter), *args]
    text = None if frames is None else "".join(json.dumps(f) + "\n" for f in frames)
    proc = subprocess.run(cmd, input=text, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    lines = proc.stdout.splitlines()
    if frames is None:
        return json.loads(lines[-1])
    rows = [json.loads(line) for line in lines[:-1]]
    if len(rows) != len(frames):
        raise SystemExit(f"{peer.name}: {len(rows)} answers for {len(frames)} frames")
    return rows, json.loads(lines[-1])


def write_catalog_csv(catalog, root: Path) -> Path:
    path = root / "peers" / f"catalog-{catalog.fingerprint}.csv"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        rows = zip(
            catalog.ids.tolist(),
            catalog.ra_deg.tolist(),
            catalog.dec_deg.tolist(),
            catalog.mag.tolist(),
            strict=True,
        )
        tmp = path.with_suffix(".tmp")
        tmp.write_text(
            "id,ra_deg,dec_deg,mag\n" + "".join(f"{i},{r!r},{d!r},{m!r}\n" for i, r, d, m in rows)
        )
        tmp.replace(path)
    return path


def peer_database(
    python: Path, peer: Peer, root: Path, which, catalog_csv: Path, fp: str, tag: str = "hp6"
):
    """(database argument for ``solve``, build report) of the stock database (``which`` None)
    or of the one built from the catalog for a field of ``which`` degrees; cached (``tag``
    names the catalog's magnitude cut in the file name)."""
    folder = root / "peers" / peer.name
    if which is None:
        if not peer.stock_built:
            return "stock", {"shipped": True}
        path = folder / f"stock{peer.db_suffix}"
        args = ["build-stock", "--out", str(path)]
    else:
        fov = f"{which:g}".replace(".", "p")
        path = folder / f"{tag}-{fp}-fov{fov}{peer.db_suffix}"
        args = ["build", "--catalog", str(catalog_csv), "--fov-deg", f"{which:g}"]
        args += ["--out", str(path)]
    report_path = path.with_suffix(".json")
    if path.exists() and report_path.exists():
        return str(path), json.loads(report_path.read_text())
    print(f"{peer.name}: building {path.name} ...", file=sys.stderr)
    report = run_adapter(python, peer, args)
    report_path.write_text(json.dumps(report))
    return str(path), report


# ----------------------------------------------------------------------------------------------
# frames, solving, scoring


@dataclass
class Frame:
    xy: np.ndarray
    brightness: np.ndarray
    R: np.ndarray
    parity: int
    n_in_view: int
    n_true: int

    def json(self, fov_deg: float, width: int, sigma_px: float) -> dict:
        return {
            "xy": self.xy.tolist(),
            "width": width,
            "height": width,
            "fov_deg": fov_deg,
            "sigma_px": sigma_px,
        }


def make_frames(catalog, name: str, n: int, seed: int) -> list[Frame]:
    spec = SCENARIOS[name]
    camera = make_camera(width=spec["width"], height=None, fov_deg=spec["fov_deg"])
    options = {k: spec[k] for k in ("noise_px", "false_stars", "missing_frac") if k in spec}
    lo, hi = spec.get("in_view", (0, 10**9))
    frames = []
    for i in tqdm(range(n), desc=f"frames {name}", file=sys.stderr, leave=False):
        rng = np.random.default_rng([seed, *name.encode(), i])
        while True:
            f = simulate_frame(catalog, camera, seed=rng, **options)
            if lo <= f.n_in_view <= hi:
                break
        frames.append(
            Frame(
                f.xy, f.brightness, f.R_cam_from_icrs, 1, f.n_in_view, int(np.sum(f.true_id >= 0))
            )
        )
    return frames


def check_frames(catalog, fov_deg: float, width: int, seed: int) -> list[Frame]:
    """Noise-free frames, 12 of each parity, for the convention check."""
    camera = make_camera(width=width, height=None, fov_deg=fov_deg)
    frames = []
    for i in range(24):
        parity = 1 if i % 2 == 0 else -1
        f = simulate_frame(
            catalog, camera, parity=parity, seed=np.random.default_rng([seed, 99, i])
        )
        frames.append(Frame(f.xy, f.brightness, f.R_cam_from_icrs, parity, f.n_in_view, len(f.xy)))
    return frames


def starnav_solve(frame: Frame, catalog, fov_deg: float, width: int, sigma_px: float) -> dict:
    """starnav's answer in the adapters' form (attitude kept as the matrix)."""
    t0 = time.perf_counter()
    try:
        r = solve_stars(
            frame.xy,
            width=width,
            fov_deg=fov_deg,
            brightness=frame.brightness,
            catalog=catalog,
            sigma_px=sigma_px,
        )
    except StarnavError as exc:  # fewer than 3 points, for example
        return {"error": str(exc), "time_ms": None}
    call_ms = (time.perf_counter() - t0) * 1e3  # the whole call, input checks included
    s = r.solution
    if s is None:
        return {"error": r.reason, "time_ms": r.time_ms, "call_ms": call_ms}
    out = {"error": None, "time_ms": r.time_ms, "call_ms": call_ms}
    return {**out, "R": s.R_cam_from_icrs, "parity": s.parity}


def answer_score(frame: Frame, out: dict) -> AttitudeScore | None:
    """An answer (the adapters' form) against the frame's truth, None when there is none."""
    return score_answer(out, frame.R)


def outcome(frame: Frame, out: dict) -> str:
    """none, correct, inexact or wrong (``harness.verdict``)."""
    return verdict(answer_score(frame, out))


def peak_rss_mb() -> float:
    """Peak resident memory of this process, MB (as the adapters measure it): ``VmHWM`` of
    /proc/self/status. ``getrusage``'s ``ru_maxrss`` would do in a process of its own, but on
    Linux it survives ``exec``: a subprocess reports at least its parent's size at the fork."""
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def starnav_worker() -> None:
    """Solve JSON-line frames from stdin with starnav (peers' protocol) and report memory."""
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    for line in sys.stdin:
        fr = json.loads(line)
        xy = np.asarray(fr["xy"], dtype=float).reshape(-1, 2)
        get_database(catalog, make_camera(width=fr["width"], height=None, fov_deg=fr["fov_deg"]))
        frame = Frame(xy, np.arange(len(xy), 0, -1, dtype=float), np.eye(3), 1, 0, 0)
        out = starnav_solve(frame, catalog, fr["fov_deg"], fr["width"], fr["sigma_px"])
        out.pop("R", None)
        print(json.dumps(out))
    print(json.dumps({"done": True, "peak_rss_mb": peak_rss_mb()}))


# ----------------------------------------------------------------------------------------------
# the run


@dataclass
class Solver:
    label: str  # e.g. "cedar-solve 0.5.1"
    database: str  # e.g. "stock: ..." or "Hp <= 6, built"
    peer: Peer | None
    python: Path | None
    stock: bool
    options: tuple[str, ...] = ()  # extra adapter arguments (not the peer's defaults)

    @property
    def key(self) -> tuple[str, str]:
        return (self.label, self.database)


def check_conventions(solver: Solver, db_arg, frames, fov, width, catalog) -> dict:
    """Run the noise-free frames; stop unless every answer is within CHECK_TOL_DEG."""
    if solver.peer is None:
        outs = [starnav_solve(f, catalog, fov, width, 0.1) for f in frames]
    else:
        outs, _ = run_adapter(
            solver.python,
            solver.peer,
            ["solve", "--db", db_arg, *solver.options],
            [f.json(fov, width, 0.1) for f in frames],
        )
    worst_b = worst_r = 0.0
    solved = 0
    for i, (f, out) in enumerate(zip(frames, outs, strict=True)):
        e = answer_score(f, out)
        if e is None:
            continue
        solved += 1
        b, r, parity_ok = e.boresight_deg, e.roll_deg, e.same_parity
        if not parity_ok or b > CHECK_TOL_DEG or r > CHECK_TOL_DEG:
            raise SystemExit(
                f"convention check failed: {solver.label} ({solver.database}), {fov:g}° frame "
                f"{i} (parity {f.parity}): boresight {b:.4f}°, roll {r:.4f}°, parity "
                f"{'right' if parity_ok else 'wrong'}; answer {out}"
            )
        worst_b, worst_r = max(worst_b, b), max(worst_r, r)
    if solved < len(frames) // 2:
        raise SystemExit(f"convention check: {solver.label} solved {solved}/{len(frames)}")
    return {"solved": solved, "frames": len(frames), "boresight": worst_b, "roll": worst_r}


def summarize(frames, outs) -> dict:
    kinds = [outcome(f, o) for f, o in zip(frames, outs, strict=True)]
    t = np.array([o["time_ms"] for o in outs if o.get("time_ms") is not None])
    row = {k: kinds.count(k) for k in ("correct", "wrong", "inexact", "none")}
    row.update(
        kinds=kinds,
        median_ms=float(np.median(t)),
        p95_ms=float(np.percentile(t, 95)),
        max_ms=float(np.max(t)),
    )
    return row


def targets(rows: list[tuple[Solver, dict, dict]]) -> list[str]:
    """The issue's targets for one scenario, from this run's rows (the first row is starnav)."""
    ours = rows[0][1]
    peers = [(solver, r) for solver, r, _ in rows if solver.peer is not None]
    best = max(r["correct"] for _, r in peers)
    wrong = ours["wrong"] + ours["inexact"]
    out = [
        f"Targets: solved {ours['correct']} vs the best peer's {best} "
        f"({'met' if ours['correct'] >= best else 'NOT met'}), {wrong} wrong; max "
        f"{fmt_ms(ours['max_ms'])} ms (<= 50: {'met' if ours['max_ms'] <= 50 else 'NOT met'}); "
        "median against"
    ]
    for solver, r in peers:
        ratio = ours["median_ms"] / r["median_ms"]
        goal = 1 / 3 if solver.peer.name == "cedar-solve" else 3.0
        verdict = "met" if ratio <= goal else "NOT met"
        out.append(
            f"{solver.label} ({solver.database}): x{ratio:.2f} (target x{goal:.2g}: {verdict})"
        )
    return [out[0] + " " + "; ".join(out[1:]) + "."]


def fmt_ms(v: float) -> str:
    return f"{v:.2f}" if v < 10 else f"{v:.1f}"


def table(name: str, n: int, rows: list[tuple[Solver, dict, dict]]) -> list[str]:
    lines = [
        f"#### {SCENARIOS[name]['title']}, {n} frames",
        "",
        *table_head(
            "solver",
            "database",
            "correct",
            "wrong",
            "inexact",
            "none",
            "correct %",
            "median ms",
            "p95 ms",
            "max ms",
            "database build s",
            "database MB",
            "peak memory MB",
        ),
    ]
    for solver, r, db in rows:
        build = db.get("build_s")
        build_s = "shipped" if db.get("shipped") else f"{build:.2f}" if build is not None else "-"
        size = f"{db['bytes'] / 1e6:.1f}" if db.get("bytes") else "-"
        lines.append(
            table_row(
                solver.label,
                solver.database,
                r["correct"],
                r["wrong"],
                r["inexact"],
                r["none"],
                f"{100 * r['correct'] / n:.1f}",
                fmt_ms(r["median_ms"]),
                fmt_ms(r["p95_ms"]),
                fmt_ms(r["max_ms"]),
                build_s,
                size,
                f"{r['peak_rss_mb']:.0f}",
            )
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, default=DOC, help="markdown file ('-': none)")
    parser.add_argument("--starnav-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.starnav_worker:
        starnav_worker()
        return
    t_start = time.time()
    root = cache_dir()
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    catalog_csv = write_catalog_csv(catalog, root)
    fields = sorted({(SCENARIOS[s]["fov_deg"], SCENARIOS[s]["width"]) for s in args.scenarios})

    # solvers and databases: starnav's pair database per field, peers' stock and built ones
    starnav_dbs = {}
    for fov, width in fields:
        db = get_database(catalog, make_camera(width=width, height=None, fov_deg=fov))
        size = db.path.stat().st_size if db.path else db.nbytes
        starnav_dbs[fov] = {"build_s": db.build_s, "bytes": size}
    solvers = [
        Solver(f"starnav {starnav.__version__}", "Hp <= 6 pairs", None, None, False),
    ]
    installs = {}
    for peer in PEERS:
        python, installs[peer.name] = peer_python(peer, root)
        label = f"{peer.name} {peer.version}"
        stock = "stock (bundled Gaia, 10-30°)" if peer.stock_built else "stock (shipped, 10-30°)"
        solvers.append(Solver(label, stock, peer, python, True))
        solvers.append(Solver(label, "Hp <= 6, built", peer, python, False))
        if peer.tuned:
            flags = " ".join(peer.tuned)
            solvers.append(
                Solver(label, f"Hp <= 6, built; `{flags}`", peer, python, False, peer.tuned)
            )

    def database_for(solver: Solver, fov: float):
        if solver.peer is None:
            return None, starnav_dbs[fov]
        which = None if solver.stock else fov
        return peer_database(
            solver.python, solver.peer, root, which, catalog_csv, catalog.fingerprint
        )

    # conventions first, on noise-free frames of both parities
    checks = {}
    for fov, width in fields:
        frames = check_frames(catalog, fov, width, args.seed)
        for solver in solvers:
            db_arg, _ = database_for(solver, fov)
            c = check_conventions(solver, db_arg, frames, fov, width, catalog)
            checks[(*solver.key, fov)] = c
            print(
                f"check {fov:g}°: {solver.label} ({solver.database}): {c['solved']}/{c['frames']}"
                f" solved, worst boresight {c['boresight']:.5f}°, roll {c['roll']:.5f}°",
                file=sys.stderr,
            )

    sections, findings = [], []
    for name in args.scenarios:
        spec = SCENARIOS[name]
        fov, width, sigma = spec["fov_deg"], spec["width"], spec["noise_px"] or 0.1
        frames = make_frames(catalog, name, args.frames, args.seed)
        payload = [f.json(fov, width, sigma) for f in frames]
        rows, answers = [], {}
        for solver in solvers:
            db_arg, db_info = database_for(solver, fov)
            t0 = time.time()
            if solver.peer is None:
                # the answers kept so far are this script's, not the solver's: out of the
                # collector's sight, so that no full collection over them lands in a solve
                gc.collect()
                gc.freeze()
                outs = [
                    starnav_solve(f, catalog, fov, width, sigma)
                    for f in tqdm(frames, desc=f"starnav {name}", file=sys.stderr, leave=False)
                ]
                cmd = [sys.executable, str(Path(__file__).resolve()), "--starnav-worker"]
                proc = subprocess.run(
                    cmd,
                    input="".join(json.dumps(p) + "\n" for p in payload),
                    capture_output=True,
                    text=True,
                    check=True,
                    cwd=BENCH,
                )
                summary = json.loads(proc.stdout.splitlines()[-1])
            else:
                outs, summary = run_adapter(
                    solver.python, solver.peer, ["solve", "--db", db_arg, *solver.options], payload
                )
            r = summarize(frames, outs)
            r["peak_rss_mb"] = summary["peak_rss_mb"]
            if db_info.get("shipped"):  # the size of the file the adapter loaded
                db_info = {**db_info, "bytes": summary["database"]["bytes"]}
            rows.append((solver, r, db_info))
            answers[solver.key] = (r["kinds"], outs)
            print(
                f"{name}: {solver.label} ({solver.database}): {r['correct']} correct, "
                f"{r['wrong']} wrong, {r['inexact']} inexact, {r['none']} none, "
                f"median {r['median_ms']:.2f} ms ({time.time() - t0:.0f} s)",
                file=sys.stderr,
            )
        calls = [o["call_ms"] for o in answers[solvers[0].key][1] if "call_ms" in o]
        sections += [
            *table(name, len(frames), rows),
            "",
            f"starnav's time is `SolveResult.time_ms` (identification and fit); its whole "
            f"`solve_stars` call, input checks and database look-up included, took "
            f"{np.median(calls):.2f} ms median, {np.percentile(calls, 95):.2f} ms p95.",
            "",
            *targets(rows),
            "",
        ]
        if "in_view" in spec:
            sections += [*by_stars_in_view(frames, rows), ""]
        findings += frame_findings(name, frames, solvers, answers)

    lines = [
        f"Frames per scenario: {args.frames}; seed {args.seed}. "
        + "; ".join(f"{p.name}: `pip install {installs[p.name]}`" for p in PEERS)
        + ".",
        "",
        *sections,
        "Convention check (noise-free frames, 12 of each parity, per field): largest "
        "boresight / roll difference of the answers from the truth, all with the right parity:",
        "",
        *[
            f"- {label} ({database}), {fov:g}°: {c['solved']}/{c['frames']} solved, "
            f"{c['boresight'] * 3600:.2f}″ / {c['roll'] * 3600:.2f}″"
            for (label, database, fov), c in checks.items()
        ],
        "",
        "Frames to look at (scenario, frame index):",
        "",
        *(findings or ["- none"]),
        "",
        f"{machine()}; `python benchmarks/peers/peers.py --frames {args.frames} --scenarios "
        f"{' '.join(args.scenarios)}`, {time.time() - t_start:.0f} s.",
    ]
    text = "\n".join(lines)
    print(text)
    if str(args.out) != "-":
        replace_block(args.out, "peers", text, missing="# starnav and its peers")


def by_stars_in_view(frames, rows) -> list[str]:
    counts = sorted({f.n_in_view for f in frames})
    head = [f"{c} in view ({sum(f.n_in_view == c for f in frames)})" for c in counts]
    lines = table_head("correct, by stars in view", *head)
    for solver, r, _ in rows:
        cells = []
        for c in counts:
            n_ok = sum(
                k == "correct" for f, k in zip(frames, r["kinds"], strict=True) if f.n_in_view == c
            )
            cells.append(str(n_ok))
        lines.append(table_row(f"{solver.label}, {solver.database}", *cells))
    return lines


def frame_findings(name, frames, solvers, answers) -> list[str]:
    """Wrong or inexact answers of any solver, and frames that starnav leaves unsolved (or gets
    wrong) where a peer is correct."""
    out = []
    starnav_key = solvers[0].key
    starnav_kinds = answers[starnav_key][0]
    for (label, database), (kinds, outs) in answers.items():
        bad = [i for i, k in enumerate(kinds) if k in ("wrong", "inexact")]
        for i in bad:
            e = answer_score(frames[i], outs[i])
            b, r, parity_ok = e.boresight_deg, e.roll_deg, e.same_parity
            out.append(
                f"- ({name}) {label} ({database}) frame {i}: {kinds[i]}, boresight {b:.3f}°, "
                f"roll {r:.3f}°{'' if parity_ok else ', wrong parity'}, "
                f"{frames[i].n_true} true stars of {len(frames[i].xy)} points"
            )
        if (label, database) == starnav_key:
            continue
        better = [
            i for i, k in enumerate(kinds) if k == "correct" and starnav_kinds[i] != "correct"
        ]
        if better:
            out.append(
                f"- ({name}) starnav not correct, {label} ({database}) correct: frames "
                + ", ".join(
                    f"{i} ({starnav_kinds[i]}, {frames[i].n_true} true stars)" for i in better
                )
            )
    return out


if __name__ == "__main__":
    main()
