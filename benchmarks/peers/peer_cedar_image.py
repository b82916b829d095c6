"""Run cedar-solve (PyPI ``cedar-solve``, import ``tetra3``) on image FILES.

Runs INSIDE cedar-solve's own virtual environment, like ``peer_cedar.py`` (whose database
loading, parity and memory helpers it imports), and must not import starnav.
``benchmarks/peers/images.py`` drives it; by hand::

    VENV/bin/python -I benchmarks/peers/peer_cedar_image.py solve --db stock < files.jsonl
    VENV/bin/python -I benchmarks/peers/peer_cedar_image.py centroids < files.jsonl

``solve``: JSON lines on stdin, ``{"path": "frame.png", "fov_deg": 20.0}`` (``fov_deg`` null:
FOV unknown, cedar searches its database's range); one JSON line per file on stdout with
``read_ms`` (``PIL.Image.open`` and ``load``: the file decoded into the PIL image cedar takes),
``time_ms`` (the ``solve_from_image`` call: cedar's own conversion to a float array, its
centroiding ``get_centroids_from_image`` with its defaults, and ``solve_from_centroids``),
``extract_ms`` / ``peer_ms`` (cedar's ``T_extract`` / ``T_solve``), ``ra_deg``, ``dec_deg``,
``roll_deg``, ``parity``, ``fov_deg`` (solved), ``n_matched`` and ``error`` (null or cedar's
status). Both times come from ``perf_counter`` in this process; interpreter
start-up, imports and the database load are excluded. Then one summary line
``{"done": true, "peak_rss_mb": ..., "load_s": ..., "version": ..., "database": {...}}``.

``centroids``: the same input; per file ``{"xy": [[x, y], ...], "time_ms": ...}``, cedar's
centroids (brightest first) converted to starnav's pixels, for the pixel-origin check.

Conventions (cedar-solve 0.5.1 -> starnav; see ``peer_cedar.py``, verified again by
``images.py`` on rendered files): ``get_centroids_from_image`` returns (y, x) rows with
"x=y=0.5 the centre of the top-left pixel", i.e. starnav's pixels with the columns swapped;
the answer is converted as in ``peer_cedar.py`` (parity from the matches, after the timed call;
starnav roll = -Roll for parity +1).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import tetra3
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run with -I: no script dir on path
from peer_cedar import PEER, STOCK, answer, database_info, load, peak_rss_mb


def decode(path: str) -> tuple[Image.Image, float]:
    t0 = time.perf_counter()
    image = Image.open(path)
    image.load()
    return image, (time.perf_counter() - t0) * 1e3


def solve_file(t3: tetra3.Tetra3, item: dict) -> dict:
    image, read_ms = decode(item["path"])
    width, height = image.size
    fov = item.get("fov_deg")
    t0 = time.perf_counter()
    result = t3.solve_from_image(
        image, fov_estimate=None if fov is None else float(fov), return_matches=True
    )
    time_ms = (time.perf_counter() - t0) * 1e3
    out = {
        "read_ms": read_ms,
        "time_ms": time_ms,
        "extract_ms": result.get("T_extract"),
        "peer_ms": result.get("T_solve"),
    }
    return {**out, **answer(result, width, height)}


def centroid_file(item: dict) -> dict:
    image, _ = decode(item["path"])
    t0 = time.perf_counter()
    yx = np.asarray(tetra3.get_centroids_from_image(image), dtype=float).reshape(-1, 2)
    time_ms = (time.perf_counter() - t0) * 1e3
    return {"xy": yx[:, ::-1].tolist(), "time_ms": time_ms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("solve", help="solve the image files named on stdin")
    p.add_argument("--db", default="stock", help="'stock' or a database built by peer_cedar.py")
    sub.add_parser("centroids", help="cedar's centroids of the image files named on stdin")
    args = parser.parse_args()
    t0 = time.perf_counter()
    t3 = load(args.db) if args.cmd == "solve" else None
    load_s = time.perf_counter() - t0
    for line in sys.stdin:
        if not line.strip():
            continue
        item = json.loads(line)
        try:
            out = solve_file(t3, item) if t3 is not None else centroid_file(item)
        except Exception as exc:  # report and go on: one bad file must not stop the run
            out = {"ra_deg": None, "time_ms": None, "error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(out), flush=True)
    summary = {"done": True, "peak_rss_mb": peak_rss_mb(), "load_s": load_s}
    summary["version"] = version(PEER)
    if t3 is not None:
        summary["database"] = database_info(t3)
        db_path = STOCK if args.db == "stock" else Path(args.db)
        summary["database"]["bytes"] = db_path.stat().st_size
    print(json.dumps(summary), flush=True)


if __name__ == "__main__":
    main()
