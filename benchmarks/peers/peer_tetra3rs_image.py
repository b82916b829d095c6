"""Run tetra3rs (PyPI ``tetra3rs``, a Rust extension) on image FILES.

Runs INSIDE tetra3rs's own virtual environment, like ``peer_tetra3rs.py`` (whose memory and
database helpers it imports), and must not import starnav. tetra3rs takes numpy arrays only,
so the files are decoded with Pillow, which ``benchmarks/peers/images.py`` adds to that environment.
By hand::

    VENV/bin/python -I benchmarks/peers/peer_tetra3rs_image.py solve --db db.bin < files.jsonl
    VENV/bin/python -I benchmarks/peers/peer_tetra3rs_image.py centroids --extractor fast \\
        < files.jsonl

``solve``: JSON lines on stdin, ``{"path": "frame.png", "fov_deg": 20.0}`` (tetra3rs needs the
FOV estimate: a null one is reported as an error, not solved); one JSON line per file on stdout
with ``read_ms`` (``PIL.Image.open`` and ``numpy.asarray``: the file decoded into a uint16
array), ``time_ms`` (the array to the attitude: extraction and ``solve_from_centroids``),
``extract_ms``, ``peer_ms`` (tetra3rs's own ``solve_time_ms``), ``ra_deg``, ``dec_deg``,
``roll_deg``, ``parity``, ``fov_deg`` (solved), ``n_matched``, ``n_centroids`` and ``error``
(null or tetra3rs's status). Times from ``perf_counter`` in this process; interpreter
start-up, imports and the database load are excluded. Then one summary line
``{"done": true, "peak_rss_mb": ..., "load_s": ..., "version": ..., "database": {...}}``.

``--extractor standard`` (default): a ``CentroidExtractor`` (``extract_centroids`` with its
working buffers kept between frames, same results) with all defaults; ``fast``:
``extract_centroids_fast`` with all defaults. Both with ``threads=1`` (one core, like the
other solvers). ``centroids``: per file ``{"xy": [[x, y], ...], "time_ms": ...}``, the
extractor's centroids (brightest first) in starnav's pixels, for the pixel-origin check.

Conventions (tetra3rs 0.14.0 -> starnav; see ``peer_tetra3rs.py``, verified again by
``images.py`` on rendered files): centroids have their origin at the image centre, +x right,
+y down, so starnav's x = x + W/2, y = y + H/2; they go to ``solve_from_centroids`` as returned
(the same frame). ``rotation_matrix_icrs_to_camera`` is starnav's ``R_cam_from_icrs`` for an
ordinary image; starnav roll = roll_deg + 180; ``parity_flip`` True is parity -1.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import tetra3rs
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run with -I: no script dir on path
from peer_tetra3rs import PEER, answer, database_info, peak_rss_mb


def decode(path: str) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    with Image.open(path) as image:
        array = np.asarray(image)
        if array.ndim == 3:  # tetra3rs takes one channel: colour (and alpha) to Pillow's "L"
            array = np.asarray(image.convert("L"))
    return array, (time.perf_counter() - t0) * 1e3


def extractor_for(name: str):
    """A function image -> ExtractionResult, one core."""
    if name == "fast":
        return lambda image: tetra3rs.extract_centroids_fast(image, threads=1)
    extractor = tetra3rs.CentroidExtractor()
    return lambda image: extractor.extract(image, threads=1)


def solve_file(db: tetra3rs.SolverDatabase, extract, item: dict) -> dict:
    image, read_ms = decode(item["path"])
    height, width = image.shape[:2]
    fov = item.get("fov_deg")
    if fov is None:
        raise ValueError("tetra3rs needs an FOV estimate")
    t0 = time.perf_counter()
    found = extract(image)
    t1 = time.perf_counter()
    result = db.solve_from_centroids(
        found.centroids, fov_estimate_deg=float(fov), image_width=width, image_height=height
    )
    t2 = time.perf_counter()
    out = {
        "read_ms": read_ms,
        "time_ms": (t2 - t0) * 1e3,
        "extract_ms": (t1 - t0) * 1e3,
        "peer_ms": float(result.solve_time_ms),
        "n_centroids": len(found.centroids),
    }
    return {**out, **answer(result)}


def centroid_file(extract, item: dict) -> dict:
    image, _ = decode(item["path"])
    height, width = image.shape[:2]
    t0 = time.perf_counter()
    found = extract(image)
    time_ms = (time.perf_counter() - t0) * 1e3
    xy = [[c.x + width / 2.0, c.y + height / 2.0] for c in found.centroids]
    return {"xy": xy, "time_ms": time_ms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    solve = sub.add_parser("solve", help="solve the image files named on stdin")
    solve.add_argument("--db", required=True, help="a database made by peer_tetra3rs.py")
    centroids = sub.add_parser("centroids", help="centroids of the image files named on stdin")
    for p in (solve, centroids):
        p.add_argument("--extractor", choices=("standard", "fast"), default="standard")
    args = parser.parse_args()
    extract = extractor_for(args.extractor)
    t0 = time.perf_counter()
    db = tetra3rs.SolverDatabase.load_from_file(args.db) if args.cmd == "solve" else None
    load_s = time.perf_counter() - t0
    for line in sys.stdin:
        if not line.strip():
            continue
        item = json.loads(line)
        try:
            out = solve_file(db, extract, item) if db is not None else centroid_file(extract, item)
        except Exception as exc:  # report and go on: one bad file must not stop the run
            out = {"ra_deg": None, "time_ms": None, "error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(out), flush=True)
    summary = {"done": True, "peak_rss_mb": peak_rss_mb(), "load_s": load_s}
    summary["version"] = version(PEER)
    if db is not None:
        summary["database"] = {**database_info(db), "bytes": Path(args.db).stat().st_size}
    print(json.dumps(summary), flush=True)


if __name__ == "__main__":
    main()
