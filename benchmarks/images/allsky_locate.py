"""Where an upward all-sky camera stands: latitude and longitude from one real frame and its
UTC, against the site its project publishes (issue 37 point 4), into docs/allsky.md (block
``allsky-locate``).

    python benchmarks/images/allsky_locate.py [--files DIR]
        [--set development|heldback|heldback_2|all] [--write-docs] [--json OUT]

Each frame of tests/data/real/allsky_manifest.json with a site, a UTC and an independent
reference of its disc centre (``zenith_offset_deg``: astrometry.net's direction at the disc
centre against the zenith at the published site, i.e. how far from level the camera stands)
is located as a user would, knowing only the frame, its time and that the camera looks up:

1. ``starnav calibrate FRAME -o cam.json --model auto [--lens LENS]``: the lens from the frame's
   own stars (no site given: nothing of the answer goes in);
2. ``starnav locate obs.json --json`` with one camera ``{"image": FRAME, "camera": cam.json,
   "azimuth_deg": 0, "elevation_deg": 90}``, ``gravity_body`` [0, 0, 1] (level) and
   ``gravity_sigma_deg`` 1 (a camera levelled by eye).

The table gives the distance of the fix from the published site, the camera's tilt the
reference measures — the angle between the zenith at the site and the sky direction that
astrometry.net's crop WCS gives at the calibrated principal point (the axis starnav takes for
the vertical) — and the distance that tilt alone implies (x 111.7 km per degree): a levelled
camera is located to its levelling, so the two should agree. Frames whose lens the
calibration cannot solve are listed as such.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, replace_block, table_head, table_row
from benchmarks.images.make_allsky_reference import zenith_radec_deg
from benchmarks.images.real_allsky import (
    DOC,
    ENV,
    MANIFEST,
    SETS,
    Reference,
    _angle_deg,
    _unit,
    file_state,
    frames,
)

TIMEOUT_S = 900
GRAVITY_SIGMA_DEG = 1.0


def _starnav(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "starnav", *args], capture_output=True, text=True,
        timeout=TIMEOUT_S,
    )  # fmt: skip


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def ground_km(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance (km, a 6371 km sphere: enough for tens of km)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dlon = math.radians(lon2 - lon1)
    c = math.sin(p1) * math.sin(p2) + math.cos(p1) * math.cos(p2) * math.cos(dlon)
    return 6371.0 * math.acos(max(-1.0, min(1.0, c)))


def locate_frame(entry: dict, folder: Path) -> dict:
    """Calibrate the lens from the frame, locate it as a levelled upward camera."""
    out = {"name": entry["name"], "set": entry["set"], "project": entry["project"]}
    site, path = entry["site"], (folder / entry["name"]).resolve()
    with tempfile.TemporaryDirectory() as tmp:
        cam = Path(tmp) / "cam.json"
        args = ["calibrate", str(path), "-o", str(cam), "--model", "auto", "--json"]
        if entry.get("lens") not in (None, "unknown"):
            args += ["--lens", entry["lens"]]
        proc = _starnav(*args)
        if proc.returncode != 0:
            return out | {"error": "calibrate: " + _last_line(proc.stderr or proc.stdout)}
        lens = json.loads(cam.read_text())
        out["model"] = lens["model"]
        obs = Path(tmp) / "obs.json"
        obs.write_text(json.dumps({
            "utc": entry["utc"], "gravity_body": [0, 0, 1],
            "gravity_sigma_deg": GRAVITY_SIGMA_DEG,
            "cameras": [{"name": "up", "image": str(path), "camera": str(cam),
                         "azimuth_deg": 0, "elevation_deg": 90}],
        }))  # fmt: skip
        proc = _starnav("locate", str(obs), "--json")
    try:
        fix = json.loads(_last_line(proc.stdout))
    except json.JSONDecodeError:
        return out | {"error": "locate: " + _last_line(proc.stderr)}
    if not fix.get("solved"):
        return out | {"error": "locate: " + str(fix.get("reason"))}
    axis = Reference(entry["reference"]).sky_at(lens["cx"], lens["cy"])
    zenith = _unit(*zenith_radec_deg(site, entry["utc"]))
    tilt = None if axis is None else float(_angle_deg(axis, zenith))
    per_deg_km = fix["gravity_north_m"] / 1e3 / GRAVITY_SIGMA_DEG
    return out | {
        "lat_deg": fix["lat_deg"],
        "lon_deg": fix["lon_deg"],
        "stars": fix["n_stars"],
        "off_km": ground_km(fix["lat_deg"], fix["lon_deg"], site["lat_deg"], site["lon_deg"]),
        "tilt_deg": tilt,
        "tilt_km": None if tilt is None else tilt * per_deg_km,
        "disc_centre_tilt_deg": entry["reference"]["zenith_offset_deg"],
    }


def table(results: list[dict]) -> str:
    rows = table_head(
        "frame", "set", "lens fitted", "stars", "fix (lat, lon)", "off the published site",
        "axis from the zenith (reference)", "that tilt on the ground",
    )  # fmt: skip
    for r in results:
        if "error" in r:
            rows.append(table_row(f"`{r['name']}`", r["set"], r["error"][:150], "", "", "", "", ""))
            continue
        rows.append(table_row(
            f"`{r['name']}`", r["set"], r["model"], r["stars"],
            f"{r['lat_deg']:+.3f}°, {r['lon_deg']:+.3f}°", f"{r['off_km']:.1f} km",
            "no crop" if r["tilt_deg"] is None else f"{r['tilt_deg']:.2f}°",
            "" if r["tilt_km"] is None else f"{r['tilt_km']:.1f} km",
        ))  # fmt: skip
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--files", default=os.environ.get(ENV), help=f"frames (default ${ENV})")
    parser.add_argument("--set", default="all", choices=(*SETS, "all"))
    parser.add_argument("--write-docs", action="store_true", help="the table into docs/allsky.md")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args(argv)
    if not args.files or not Path(args.files).is_dir():
        raise SystemExit(f"no frames folder: give --files DIR or set {ENV}")
    folder = Path(args.files)
    results = []
    for entry in frames(json.loads(MANIFEST.read_text()), args.set, None):
        ref = entry.get("reference") or {}
        if not (
            entry.get("site") and entry.get("utc") and ref.get("zenith_offset_deg") is not None
        ):
            continue
        if ref["zenith_offset_deg"] > 10.0:  # not an upward camera (a tilted meteor camera)
            continue
        if file_state(entry, folder):
            continue
        results.append(locate_frame(entry, folder))
        print(json.dumps(results[-1]), file=sys.stderr, flush=True)
    md = f"Machine: {machine(load_at_end=True)}.\n\n" + table(results)
    print(md)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    if args.write_docs:
        replace_block(DOC, "allsky-locate", md, missing="### Where the camera stands")


if __name__ == "__main__":
    main()
