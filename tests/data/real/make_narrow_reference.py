"""Reference answers and N.I.N.A.-style hints for the held-back narrow-field frames
(narrow_heldback.json), from astrometry.net.

A set that nobody tunes on: real telescope and long-lens frames of 0.3-3.5° horizontal field
from public repositories that are not in sources.json, listed in narrow_heldback.json by
repository, commit, path, git blob and SHA-256 (the files themselves are not in this
repository). Run from the repository root, with starnav importable::

    python tests/data/real/make_narrow_reference.py solve      # astrometry.net on each file
    python tests/data/real/make_narrow_reference.py reference  # WCS -> starnav, and hints

The files are read from ``$STARNAV_NARROW_FILES`` (default ``/work/narrow/files``);
solve-field's ``.wcs`` and log files go to ``$STARNAV_NARROW_WORK`` (default
``/work/narrow/astrometry``). ``solve`` is make_reference.py's ``solve_one`` (the file decoded
as starnav decodes it, written as FITS with the picture's top row as FITS row 1,
``--crpix-center``, a width hint of half to twice ``fov_guess_deg`` where the source states a
field, else 0.3°-100°, ``--downsample 2`` above 2000 px and 4 above 4000 px) with a CPU limit
of 120 s; run it under ``nice``. ``reference`` converts each WCS with make_reference.py's
``convert`` (boresight at the image centre W/2, H/2, roll, parity, horizontal ``fov_deg``,
``scale_arcsec_per_px``, ``R_cam_from_icrs``: README.md beside this file says how) and keeps a
solved frame in the set when its horizontal field is within ``FOV_BAND_DEG``.

Hints, as N.I.N.A. sends them to a plate solver, for each frame in the set: a position
``HINT_OFFSET_MAX_DEG`` or less from the true centre (a random direction, a distance uniform
in 0-5°) and a pixel scale with a random error uniform in ±``HINT_SCALE_ERROR`` (±10 %), drawn
from ``numpy.random.default_rng`` seeded with ``HINT_SEED`` and the file's name, so that a
frame's hints do not change when frames are added or removed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
from make_reference import add_solve_command, convert, raw_wcs, solve_one, wcs_of

HERE = Path(__file__).resolve().parent
MANIFEST = HERE / "narrow_heldback.json"
FILES = Path(os.environ.get("STARNAV_NARROW_FILES", "/work/narrow/files"))
WORK = Path(os.environ.get("STARNAV_NARROW_WORK", "/work/narrow/astrometry"))
CPU_LIMIT_S = 120
FOV_BAND_DEG = (0.3, 3.5)  # horizontal field of the frames kept
HINT_SEED = 36
HINT_OFFSET_MAX_DEG = 5.0
HINT_SCALE_ERROR = 0.10  # fraction


def manifest() -> dict:
    return json.loads(MANIFEST.read_text())


def solve_status() -> dict:
    """What ``solve`` recorded per file (``WORK/solve*.json``: one file per process)."""
    status: dict = {}
    for path in sorted(WORK.glob("solve*.json")):
        status.update(json.loads(path.read_text() or "{}"))
    return status


def cmd_solve(args) -> None:
    """solve-field on each file not run before (``--again``: run again; ``only``: these
    files); processes can share the work (``--status solve2.json --reverse``). A later
    status file's answer for a file replaces an earlier one's."""
    WORK.mkdir(parents=True, exist_ok=True)
    status_file = WORK / args.status
    status = json.loads(status_file.read_text()) if status_file.exists() else {}
    for entry in manifest()["files"][:: -1 if args.reverse else 1]:
        name = entry["name"]
        if args.only and name not in args.only:
            continue
        if name in solve_status() and not args.again:
            continue
        status[name] = solve_one(entry, FILES, args.cpulimit, work=WORK)
        print(name, json.dumps(status[name]), flush=True)
        status_file.write_text(json.dumps(status, indent=1))


def hints(name: str, ref: dict) -> dict:
    """N.I.N.A.-style hints for a frame: a centre off the true one by a random direction and
    a distance uniform in 0-``HINT_OFFSET_MAX_DEG`` degrees, a pixel scale (and the field
    width it gives) off by a factor uniform in 1 ± ``HINT_SCALE_ERROR``."""
    from starnav.geometry import north_east, radec_to_unit, unit_to_radec

    rng = np.random.default_rng([HINT_SEED, *name.encode()])
    pa = rng.uniform(0.0, 360.0)
    offset = rng.uniform(0.0, HINT_OFFSET_MAX_DEG)
    error = rng.uniform(-HINT_SCALE_ERROR, HINT_SCALE_ERROR)
    centre = radec_to_unit(np.radians(ref["ra_deg"]), np.radians(ref["dec_deg"]))
    north, east = north_east(centre)
    d, theta = np.radians(offset), np.radians(pa)
    hinted = np.cos(d) * centre + np.sin(d) * (np.cos(theta) * north + np.sin(theta) * east)
    ra, dec = unit_to_radec(hinted)
    return {
        "ra_deg": round(float(np.degrees(ra)), 6),
        "dec_deg": round(float(np.degrees(dec)), 6),
        "offset_deg": round(float(offset), 4),
        "offset_position_angle_deg": round(float(pa), 3),
        "scale_arcsec_per_px": round(ref["scale_arcsec_per_px"] * (1.0 + error), 4),
        "fov_deg": round(ref["fov_deg"] * (1.0 + error), 5),
        "scale_error": round(float(error), 5),
    }


POINTING_KEYS = ("CRVAL1", "CRVAL2", "OBJCTRA", "OBJCTDEC", "RA", "DEC", "FOCALLEN", "SECPIX1")


def header_pointing(name: str) -> list[str]:
    """The FITS keywords of a file that already say where it points or its scale (a solver
    that reads them is not solving from the hints alone)."""
    if not name.lower().endswith((".fit", ".fits", ".fts")):
        return []
    from astropy.io import fits

    header = fits.getheader(FILES / name)
    return [key for key in POINTING_KEYS if key in header]


def astrometry_record(name: str, solved: dict, header) -> dict:
    """What astrometry.net said: index, log-odds and matches (its log), "up", parity, the
    command and its WCS numbers."""
    log = (WORK / f"{Path(name).stem}.log").read_text()
    odds = re.findall(r"log-odds ratio ([\d.]+) \([^)]*\), (\d+) match", log)
    return {
        "index": (solved.get("index") or "").rstrip("."),
        "log_odds": float(odds[-1][0]) if odds else None,
        "n_match": int(odds[-1][1]) if odds else None,
        "up_deg_e_of_n": solved.get("up_deg_e_of_n"),
        "parity": solved.get("parity_text"),
        "seconds": solved.get("seconds"),
        "command": solved.get("command"),
        "wcs": raw_wcs(header),
    }


def cmd_reference(args) -> None:
    """Each file's reference (or why it is not in the set) and its hints, into the manifest."""
    data = manifest()
    status = solve_status()
    for entry in data["files"]:
        name = entry["name"]
        for key in (
            "reference",
            "astrometry_net",
            "hints",
            "in_set",
            "why_not",
            "header_pointing_keys",
        ):
            entry.pop(key, None)
        solved = status.get(name)
        wcs, header = wcs_of(name, WORK) if solved and solved["solved"] else (None, None)
        if wcs is None:
            entry["in_set"] = False
            entry["why_not"] = "not run" if solved is None else "astrometry.net did not solve it"
            continue
        entry["reference"] = {
            "width": solved["width"],
            "height": solved["height"],
            **convert(wcs, solved["width"], solved["height"]),
        }
        entry["astrometry_net"] = astrometry_record(name, solved, header)
        up, ref = solved.get("up_deg_e_of_n"), entry["reference"]
        if up is not None and solved.get("parity_text") == "neg":  # CRVAL is the centre
            gap = (ref["roll_deg"] - (up + 180.0) + 180.0) % 360.0 - 180.0
            if abs(gap) > 0.01:
                raise SystemExit(f"{name}: roll {ref['roll_deg']} but up {up} E of N")
        entry["header_pointing_keys"] = header_pointing(name)
        entry["in_set"] = FOV_BAND_DEG[0] <= ref["fov_deg"] <= FOV_BAND_DEG[1]
        if not entry["in_set"]:
            entry["why_not"] = f"field {ref['fov_deg']:.3f}° outside {FOV_BAND_DEG}"
            continue
        entry["hints"] = hints(name, ref)
        print(name, ref["ra_deg"], ref["dec_deg"], ref["fov_deg"], flush=True)
    MANIFEST.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    add_solve_command(sub, "run astrometry.net on each file", CPU_LIMIT_S)
    sub.add_parser("reference", help="convert the WCS files and draw the hints")
    args = parser.parse_args()
    {"solve": cmd_solve, "reference": cmd_reference}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
