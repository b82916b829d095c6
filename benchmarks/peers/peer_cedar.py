"""Run cedar-solve (PyPI ``cedar-solve``, import ``tetra3``) on star-centroid frames.

Runs INSIDE cedar-solve's own virtual environment (cedar-solve 0.5.1 pins numpy<2 and
Pillow<9, so it cannot share starnav's) and must not import starnav. ``benchmarks/peers/peers.py``
makes the environment and drives this script; by hand::

    python -m venv VENV && VENV/bin/pip install cedar-solve==0.5.1
    VENV/bin/python benchmarks/peers/peer_cedar.py solve --db stock < frames.jsonl
    VENV/bin/python benchmarks/peers/peer_cedar.py build --catalog cat.csv --fov-deg 12 --out db.npz

``solve``: frames as JSON lines on stdin, ``{"xy": [[x, y], ...], "width": W, "height": H,
"fov_deg": F}`` (starnav's pixels, brightest first); one JSON line per frame on stdout with
``ra_deg``, ``dec_deg``, ``roll_deg``, ``parity``, ``time_ms``, ``peer_ms`` (cedar's own
``T_solve``), ``n_matched``, ``fov_deg`` (solved) and ``error`` (null, or cedar's status, e.g.
``NO_MATCH``, ``TOO_FEW``, ``TIMEOUT``; the angles are then null). ``time_ms`` is the
``solve_from_centroids`` call alone, timed here with ``perf_counter`` (interpreter start-up,
imports and the database load are excluded). After the last frame one more line:
``{"done": true, "peak_rss_mb": ..., "load_s": ..., "version": ..., "database": {...}}``
(``peak_rss_mb``: this process's peak resident memory, ``VmHWM``: interpreter, numpy, scipy,
the database and the solves).

``--db stock`` is the database shipped in the wheel (``tetra3/data/default_database.npz``:
Hipparcos ``hip_main`` to magnitude 8.0, FOV 10-30°, 712 068 patterns); ``--db PATH`` loads
one made by ``build``.

``build``: a database from a CSV ``id,ra_deg,dec_deg,mag`` (header row; positions at the epoch
wanted, no proper motion applied). cedar-solve reads only its own catalog formats (``bsc5``
binary, ``hip_main``/``tyc_main`` pipe-separated text from CDS I/239), so the stars are written
as a ``hip_main.dat`` (HIP in field 1, magnitude in field 5, RA/Dec in degrees in fields 8/9,
proper motions 0 in fields 12/13) and ``generate_database(max_fov=F, star_catalog=that file,
epoch_proper_motion=None)`` is called with cedar's defaults for everything else (single scale,
magnitude limit from 150 verification stars per field: deeper than Hp 6, so every star is kept).
Prints one JSON line with ``build_s``, ``bytes``, ``peak_rss_mb`` and the database properties.

Conventions, cedar-solve 0.5.1 -> starnav (from ``tetra3.py`` and checked by ``peers.py`` on
noise-free frames, both parities: parity right, boresight and roll within 0.2″ with a database
built from the frames' stars, within 11″ with the stock one, whose star positions differ):

* Pixels: cedar takes centroids as (y, x) rows "measured from the top left corner" with the
  image centre at (height/2, width/2) (``_compute_vectors``): starnav's origin and axes, only
  the columns swapped. ``size`` is (height, width). Input order is taken as brightest first.
* Camera frame: cedar's vector is (boresight, -x, -y) = (i, j, k); its rotation matrix has these
  axes as rows in ICRS. ``RA``/``Dec`` are those of the image centre (the boresight).
* Roll: cedar's ``Roll`` = atan2(R[1, 2], R[2, 2]) is the angle of celestial North
  counter-clockwise from image up, i.e. minus starnav's position angle of up: for an ordinary
  (parity +1) image starnav roll = (-Roll) mod 360.
* Parity: cedar knows none. Edge-ratio patterns are mirror-blind, so a mirrored image matches
  too, and its rotation matrix (SVD without determinant guard) then comes out improper with
  Roll = +starnav roll. cedar reports no flag, so the adapter derives the parity from the
  matches it returns (``return_matches=True``): the sign of det(sum c_i s_i^T) of the matched
  camera directions (starnav's pinhole at the solved FOV) and catalog directions; roll =
  (-Roll) mod 360 for parity +1, Roll for parity -1. This runs after the timed call.
* FOV: ``fov_estimate`` is the horizontal FOV in degrees, as starnav's ``fov_deg``; cedar then
  refines FOV (and a radial distortion) itself. Everything else is cedar's default
  (``fov_max_error`` None, ``match_radius`` 0.01, ``match_threshold`` 1e-4,
  ``solve_timeout`` 5000 ms, ``distortion`` 0).
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import resource
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import tetra3

PEER = "cedar-solve"


def peak_rss_mb() -> float:
    """Peak resident memory of this process, MB: ``VmHWM`` of /proc/self/status where there
    is one. (``getrusage``'s ``ru_maxrss`` survives ``exec`` on Linux, so in a subprocess it is
    at least the parent's size at the fork; ``VmHWM`` belongs to this program alone.)"""
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def quiet(t3: tetra3.Tetra3) -> None:
    t3._logger.setLevel(logging.WARNING)
    for handler in t3._logger.handlers:
        handler.setLevel(logging.WARNING)


STOCK = Path(tetra3.__file__).parent / "data" / "default_database.npz"


def load(db: str) -> tetra3.Tetra3:
    t3 = tetra3.Tetra3(load_database=None)
    quiet(t3)
    t3.load_database(STOCK if db == "stock" else Path(db))
    return t3


def unit(ra_deg, dec_deg) -> np.ndarray:
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def parity_of_matches(result: dict, width: float, height: float) -> int:
    """+1 or -1: the handedness of the matched image directions against the catalog's."""
    yx = np.asarray(result["matched_centroids"], dtype=float)
    stars = np.asarray(result["matched_stars"], dtype=float)
    focal = 0.5 * width / np.tan(0.5 * np.radians(result["FOV"]))
    cam = np.column_stack(
        [(yx[:, 1] - width / 2) / focal, (yx[:, 0] - height / 2) / focal, np.ones(len(yx))]
    )
    cam /= np.linalg.norm(cam, axis=1)[:, None]
    sky = unit(stars[:, 0], stars[:, 1])
    return 1 if np.linalg.det(cam.T @ sky) > 0 else -1


def solve_frame(t3: tetra3.Tetra3, frame: dict) -> dict:
    xy = np.asarray(frame["xy"], dtype=float).reshape(-1, 2)
    width, height = float(frame["width"]), float(frame.get("height") or frame["width"])
    t0 = time.perf_counter()
    result = t3.solve_from_centroids(
        xy[:, ::-1],
        (height, width),
        fov_estimate=float(frame["fov_deg"]),
        return_matches=True,
    )
    time_ms = (time.perf_counter() - t0) * 1e3
    out = {"time_ms": time_ms, "peer_ms": result.get("T_solve")}
    return {**out, **answer(result, width, height)}


def answer(result: dict, width: int, height: int) -> dict:
    """A cedar-solve result in our conventions: RA, Dec, our roll and parity, FOV, matches
    (all None with the error when unsolved)."""
    if result.get("RA") is None:
        none = dict.fromkeys(("ra_deg", "dec_deg", "roll_deg", "parity", "fov_deg"))
        return {**none, "error": str(result.get("status"))}
    parity = parity_of_matches(result, width, height)
    roll = (-result["Roll"]) % 360.0 if parity > 0 else result["Roll"] % 360.0
    return {
        "ra_deg": float(result["RA"]),
        "dec_deg": float(result["Dec"]),
        "roll_deg": float(roll),
        "parity": parity,
        "n_matched": int(result["Matches"]),
        "fov_deg": float(result["FOV"]),
        "error": None,
    }


def database_info(t3: tetra3.Tetra3) -> dict:
    props = t3.database_properties
    keep = ("star_catalog", "max_fov", "min_fov", "star_max_magnitude", "pattern_max_error")
    info = {k: (v.item() if hasattr(v, "item") else v) for k, v in props.items() if k in keep}
    info["num_patterns"] = int(t3.num_patterns)
    info["num_stars"] = len(t3.star_table)
    return info


def cmd_solve(args) -> None:
    t0 = time.perf_counter()
    t3 = load(args.db)
    load_s = time.perf_counter() - t0
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            out = solve_frame(t3, json.loads(line))
        except Exception as exc:  # report and go on: one bad frame must not stop the run
            out = {"ra_deg": None, "dec_deg": None, "roll_deg": None, "parity": None}
            out.update(time_ms=None, error=f"{type(exc).__name__}: {exc}")
        print(json.dumps(out), flush=True)
    summary = {"done": True, "peak_rss_mb": peak_rss_mb(), "load_s": load_s}
    summary.update(version=version(PEER), database=database_info(t3))
    summary["database"]["bytes"] = (STOCK if args.db == "stock" else Path(args.db)).stat().st_size
    print(json.dumps(summary), flush=True)


def write_hip_main(catalog_csv: Path, out: Path) -> int:
    """The CSV's stars as a pipe-separated hip_main.dat, the fields cedar reads filled."""
    n = 0
    with open(catalog_csv, newline="") as src, open(out, "w") as dst:
        for row in csv.DictReader(src):
            fields = [" "] * 15
            fields[0] = "H"
            fields[1] = str(int(float(row["id"])))
            fields[5] = repr(float(row["mag"]))
            fields[8] = repr(float(row["ra_deg"]))
            fields[9] = repr(float(row["dec_deg"]))
            fields[12] = fields[13] = "0.0"
            dst.write("|".join(fields) + "\n")
            n += 1
    return n


def cmd_build(args) -> None:
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    hip_main = out.parent / "hip_main.dat"  # cedar infers the format from the file name
    n = write_hip_main(Path(args.catalog), hip_main)
    t3 = tetra3.Tetra3(load_database=None)
    quiet(t3)
    t0 = time.perf_counter()
    t3.generate_database(
        max_fov=args.fov_deg,
        save_as=out.with_suffix(".npz"),
        star_catalog=str(hip_main),
        epoch_proper_motion=None,
    )
    build_s = time.perf_counter() - t0
    hip_main.unlink()
    path = out.with_suffix(".npz")
    t3.load_database(path)  # the counts are set on load
    info = {"build_s": build_s, "bytes": path.stat().st_size, "path": str(path)}
    info.update(catalog_stars=n, peak_rss_mb=peak_rss_mb(), version=version(PEER))
    info["database"] = database_info(t3)
    print(json.dumps(info), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("solve", help="solve JSON-line frames from stdin")
    p.add_argument("--db", default="stock", help="'stock' or a database built by 'build'")
    p = sub.add_parser("build", help="build a database from a CSV id,ra_deg,dec_deg,mag")
    p.add_argument("--catalog", required=True)
    p.add_argument("--fov-deg", type=float, required=True)
    p.add_argument("--out", required=True, help="database path (.npz)")
    args = parser.parse_args()
    {"solve": cmd_solve, "build": cmd_build}[args.cmd](args)


if __name__ == "__main__":
    main()
