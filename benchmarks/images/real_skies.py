"""starnav on real photographs with astrometry.net references, into docs/images.md.

    python benchmarks/images/real_skies.py --manifest /work/corpus/manifest.json --json after.jsonl
    python benchmarks/images/real_skies.py --manifest ... --table after.jsonl --before before.jsonl

For each image of the manifest (a JSON ``{"files": [{"name", "path", "reference": {...}}]}``,
the reference being astrometry.net's answer in starnav's conventions: ``ra_deg``,
``dec_deg``, ``roll_deg``, ``parity``, ``fov_deg``, ``solved_by_reference``):

* bright: the 3 and the 10 brightest Hipparcos stars (Hp <= 8) that the reference attitude
  puts inside the frame (3 % margin, pinhole camera of the reference field of view) that
  lie within max(4 px, 1.2 % of the width) of one of the detections handed to the solver
  (``starnav.pipeline.image.detect_image``: the first 50);
* solve: ``starnav.solve_image`` with the field of view unknown; right when the answer is not
  wrong by ``harness.verdict`` against the reference (the reference's parity, boresight and
  roll within 0.5°, as benchmarks/peers/real_images.py scores the same corpus) and the field
  of view within 2 %, else wrong;
* the detection time (ms, one run, on whatever else the machine was doing).

``--json`` writes one line per image; ``--table`` renders lines (and ``--before``: those of
another checkout, run with the same script) as the markdown table docs/images.md holds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import score_solution, table_head, verdict

MAX_FOV_ERROR = 0.02


def run(manifest: Path, out: Path, only: list[str]) -> None:
    import starnav
    from starnav.camera import Camera
    from starnav.catalog import load_catalog
    from starnav.detect.read import read_image
    from starnav.geometry import attitude_from_radec_roll
    from starnav.pipeline.image import detect_image
    from starnav.simulate import project_catalog

    catalog = load_catalog(None, mag_limit=8.0)
    files = json.loads(manifest.read_text())["files"]
    with out.open("w") as fh:
        for entry in files:
            ref = entry.get("reference") or {}
            if not ref.get("solved_by_reference") or (only and entry["name"] not in only):
                continue
            image = read_image(entry["path"])
            height, width = image.shape
            t0 = time.perf_counter()
            found = detect_image(image)
            detect_ms = (time.perf_counter() - t0) * 1e3
            R = attitude_from_radec_roll(
                ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"]
            )
            rows, xy = project_catalog(catalog, R, Camera.from_fov(ref["fov_deg"], width, height))
            edge = 0.03 * width
            inside = (xy > edge).all(axis=1) & (xy < np.array([width, height]) - edge).all(axis=1)
            xy = xy[inside][np.argsort(catalog.mag[rows[inside]], kind="stable")][:10]
            tol = max(4.0, 0.012 * width)
            hit = cKDTree(found.xy).query(xy)[0] < tol if len(found) else np.zeros(len(xy), bool)
            result = starnav.solve_image(image)
            s = result.solution
            row = {
                "name": entry["name"],
                "bright3": int(hit[:3].sum()),
                "bright10": int(hit.sum()),
                "n_bright": len(xy),
                "psf_sigma_px": round(found.psf_sigma_px, 2),
                "detect_ms": round(detect_ms, 1),
                "solved": s is not None,
            }
            if s is not None:
                score = score_solution(s, R)
                row["boresight_arcsec"] = round(score.boresight_arcsec, 1)
                row["right"] = bool(
                    verdict(score) != "wrong"
                    and abs(s.fov_deg / ref["fov_deg"] - 1.0) < MAX_FOV_ERROR
                )
            print(json.dumps(row), file=fh, flush=True)


def _read(path: Path) -> dict[str, dict]:
    return {r["name"]: r for r in map(json.loads, path.read_text().splitlines()) if r}


def _answer(row: dict | None) -> str:
    if row is None:
        return "-"
    if not row["solved"]:
        return "unsolved"
    return f"right ({row['boresight_arcsec']:.0f}″)" if row["right"] else "WRONG"


def table(after: Path, before: Path | None) -> str:
    rows, old = _read(after), _read(before) if before else {}
    lines = table_head(
        "image",
        "brightest 3 / 10 handed on, before → after",
        "solved, before → after",
        "PSF sigma px after",
        "detect ms after",
    )
    for name in sorted(rows):
        r, o = rows[name], old.get(name)
        bright = f"{r['bright3']}/{r['bright10']}"
        if o:
            bright = f"{o['bright3']}/{o['bright10']} → {bright}"
        answer = _answer(r) if o is None else f"{_answer(o)} → {_answer(r)}"
        lines.append(
            f"| {name} | {bright} | {answer} | {r['psf_sigma_px']:g} | {r['detect_ms']:.0f} |"
        )
    for label, runs in (("before", old), ("after", rows)):
        if runs:
            right = sum(r["solved"] and r["right"] for r in runs.values())
            wrong = sum(r["solved"] and not r["right"] for r in runs.values())
            lines.append("")
            lines.append(
                f"{label}: {right} of {len(runs)} right, {wrong} wrong, "
                f"{len(runs) - right - wrong} unsolved"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--manifest", type=Path)
    parser.add_argument("--json", type=Path, help="run and write one JSON line per image")
    parser.add_argument("--only", nargs="*", default=[])
    parser.add_argument("--table", type=Path, help="render these lines as markdown")
    parser.add_argument("--before", type=Path)
    args = parser.parse_args()
    if args.json:
        run(args.manifest, args.json, args.only)
    if args.table:
        print(table(args.table, args.before))


if __name__ == "__main__":
    main()
