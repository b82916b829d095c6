"""Reference answers for the real-image corpus (reference.json), from astrometry.net.

Run from the repository root, with starnav importable and the files present: in
``$STARNAV_REAL_CORPUS`` when set, else in ``../shared/data/real`` beside the repository (the
files whose licence allows it; sources.json says where each comes from, by repository,
commit, path and SHA-256)::

    python tests/data/real/make_reference.py solve      # astrometry.net on every file
    python tests/data/real/make_reference.py reference  # its WCS -> starnav's conventions
    python tests/data/real/make_reference.py check --missing  # catalog stars onto detections
    python tests/data/real/make_reference.py table      # the table of README.md

``solve`` decodes each file as starnav reads it (``starnav.detect.read.read_image``: 2-D
float32, colour to Rec. 709 luminance, row 0 = top of the picture) and writes that array
to a FITS file with ``data[0]`` as FITS row y = 1. The FITS pixel (X, Y) (1-based, the centre
of array element [row, col] at (col + 1, row + 1)) is then starnav's (X - 0.5, Y - 0.5) with
no flip: the one conversion between the two frames, written in ``fits_from_starnav``. Going
through FITS rather than handing astrometry.net the JPEG/PNG keeps it from choosing its own
row order (it reads PNM/JPEG top row first as FITS row 1 too, but 16-bit TIFF and RGBA PNG
are not all handled by its converters). astrometry.net (Debian package ``astrometry.net``
0.93, index files ``astrometry-data-tycho2-07`` to ``-10-19``: Tycho-2, quads 22′-2000′;
the first 50 files were solved with ``-10-19`` only) runs as::

    solve-field --crpix-center --no-plots --overwrite --new-fits none ... \
        --scale-units degwidth --scale-low LO --scale-high HI --cpulimit 30 \
        [--downsample 2 when the image is larger than 2000 px, 4 above 4000 px]

its process group killed after 60 s of wall time (astrometry-engine looks at the CPU limit
only between index files), with a loose width hint: 0.3°-100°, or half to twice
``fov_guess_deg`` where sources.json has one (what the source says of its lens, or the
lens's focal length and sensor);
``solve --again --cpulimit 150 FILE...`` retries unsolved ones with more time, and two
processes can share the work (``--status solve2.json --reverse``). Its wall time per file
is kept as ``seconds`` and its ``.wcs`` header in ``STARNAV_CORPUS_WORK`` (default
``/work/corpus/astrometry``).

``reference`` converts each WCS with astropy.wcs (TAN + SIP as astrometry.net fitted it):

* boresight: the sky position of starnav's image centre (W/2, H/2);
* the camera axes: the sky directions of a small step (1 px) along +x and +y from the centre,
  in the tangent plane, made orthonormal by the polar decomposition (the rotation part of the
  local Jacobian: a fitted skew or unequal scales are split evenly between the axes, as in
  astrometry.net's own orientation); parity +1 (the sky as seen: a proper camera frame x
  right, y down, z out) when (x × y) · boresight > 0, else -1; the attitude
  ``R_cam_from_icrs`` has rows x, y, z, and roll is the position angle of its image up (-y)
  from North through East (``starnav.geometry.radec_roll_from_attitude``);
* ``fov_deg``: the angle between the sky directions of the left and right edge midpoints
  (0, H/2) and (W, H/2), i.e. the horizontal field (2 atan(W / 2f) for a pinhole);
* ``scale_arcsec_per_px``: sqrt(|det CD|) in arcseconds.

astrometry.net's own "up is X degrees E of N" and "parity" (printed by ``wcsinfo``) are
recorded beside it; for these top-row-first images its parity is "neg" where ours is +1, and
our roll is (X + 180) mod 360, which ``reference`` checks (within 0.01°) for every solved
image whose CRPIX is at the centre (its "up" is the position angle at CRVAL).

``check`` is the independent test of the conversion: with the converted attitude and a
pinhole camera of the converted field (no WCS involved), the Hipparcos stars to Hp 6.5
that fall in the image are projected to pixels and matched to starnav's detections
(``starnav.pipeline.image.detect_image``); the median distance and the number matched are written
into reference.json (``check``), with the same for the attitude turned by 180°, mirrored
and with the rows flipped: these put the stars nowhere near the detections. An answer of
astrometry.net that does no better than three times those is rejected
(``reject_failed_check``: ``solved_by_reference`` false, the reason in ``rejected``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCES = HERE / "sources.json"
REFERENCE = HERE / "reference.json"
SHARED_DIR = HERE.parents[2].parent / "shared" / "data" / "real"
WORK = Path(os.environ.get("STARNAV_CORPUS_WORK", "/work/corpus/astrometry"))
CPU_LIMIT_S = 30
SCALE_DEG = (0.3, 100.0)  # loose width hint (degrees)
CHECK_MAG_LIMIT = 6.5
CHECK_MAX_DETECTIONS = 1000
CHECK_VARIANTS = ("roll_plus_180", "mirrored", "rows_flipped")  # wrong on purpose
CHECK_MIN_IN_VIEW = 3  # fewer catalog stars in view: the check says nothing
# an answer whose check fails may still be right: a processed deep-sky picture (the Witch Head,
# M45 stacks) hides bright stars in halos and nebulosity (0 of 8 and 16 of 25 on detections,
# too few against the crowded field's chance matches), a narrow field holds 3-5 Hp <= 6.5
# stars, and astrometry.net's TAN-SIP of a 44° ISS frame is 19 px off its own bright stars
# (24 of 181). With log-odds of 140-410 (its own threshold: 20.7, i.e. 1e9) such an answer
# stands; below this the check rejects (GranaSAT's trailed 30 s polar frame: log-odds 55, a
# field 5 % short of the camera's, 7 of 92 stars, as random)
CHECK_OVERRIDE_LOG_ODDS = 100.0
CHECK_BRIGHTEST = 10  # the answer test without a reference: the brightest stars in view


def sources() -> list[dict]:
    """The corpus table (sources.json): one dict per file."""
    return json.loads(SOURCES.read_text())["files"]


def corpus_dir() -> Path:
    """Where the image files are: ``$STARNAV_REAL_CORPUS``, else ``../shared/data/real``
    beside the repository. Never inside the repository: they are other projects' files."""
    found = Path(os.environ.get("STARNAV_REAL_CORPUS") or SHARED_DIR)
    if not found.is_dir():
        raise SystemExit(f"no corpus folder {found}: set STARNAV_REAL_CORPUS")
    return found


def fits_from_starnav(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """FITS 1-based pixel coordinates of starnav pixels (top-left corner origin) for a FITS
    file written with ``data[0]`` as FITS row 1 (the image's top row)."""
    return np.asarray(x) + 0.5, np.asarray(y) + 0.5


def astrometry_version() -> str:
    out = subprocess.run(["solve-field", "--version"], capture_output=True, text=True)
    return out.stdout.strip() or out.stderr.strip()


def solve_one(
    entry: dict,
    folder: Path,
    cpu_limit_s: int = CPU_LIMIT_S,
    *,
    near: tuple[float, float, float] | None = None,
    work: Path = WORK,
) -> dict:
    """Run solve-field on one file; returns what it reported (and writes the .wcs into
    ``work``). ``near``: (RA, Dec, width) in degrees, another solver's answer to verify: the
    field is then searched within 5° of it and 10 % of its width only."""
    from astropy.io import fits

    from starnav.detect.read import read_image

    pixels = read_image(folder / entry["name"])
    scale_deg = width_hint_deg(entry)
    if near is not None:
        scale_deg = (0.9 * near[2], 1.1 * near[2])
    height, width = pixels.shape
    work.mkdir(parents=True, exist_ok=True)
    stem = Path(entry["name"]).stem
    out = {"width": width, "height": height}
    with tempfile.TemporaryDirectory() as tmp:
        image = Path(tmp) / f"{stem}.fits"
        fits.PrimaryHDU(np.nan_to_num(pixels).astype(np.float32)).writeto(image)
        cmd = [
            "solve-field",
            str(image),
            "--dir",
            tmp,
            "--crpix-center",
            "--no-plots",
            "--overwrite",
            "--new-fits",
            "none",
            "--scale-units",
            "degwidth",
            "--scale-low",
            f"{scale_deg[0]:g}",
            "--scale-high",
            f"{scale_deg[1]:g}",
            "--cpulimit",
            str(cpu_limit_s),
        ]
        if near is not None:
            cmd += ["--ra", f"{near[0]:.6f}", "--dec", f"{near[1]:.6f}", "--radius", "5"]
        if max(width, height) > 2000:
            cmd += ["--downsample", str(2 if max(width, height) <= 4000 else 4)]
        started = time.perf_counter()
        log, err = _run_bounded(cmd, 2 * cpu_limit_s)  # run this script under nice
        out["seconds"] = round(time.perf_counter() - started, 2)  # wall time, FITS to .wcs
        wcs = Path(tmp) / f"{stem}.wcs"
        out["command"] = " ".join(["solve-field", "FILE.fits", *cmd[2:]]).replace(tmp, "TMP")
        out["solved"] = wcs.exists()
        match = re.search(r"Field 1: solved with index (\S+?)\.?\s", log)
        out["index"] = match.group(1) if match else None
        for key, pattern in (
            ("up_deg_e_of_n", r"up is ([-\d.]+) degrees E of N"),
            ("field_rotation_deg", r"Field rotation angle: up is ([-\d.]+) degrees"),
        ):
            match = re.search(pattern, log)
            out[key] = float(match.group(1)) if match else None
        match = re.search(r"Field parity: (\w+)", log)
        out["parity_text"] = match.group(1) if match else None
        if out["solved"]:
            (work / f"{stem}.wcs").write_bytes(wcs.read_bytes())
        (work / f"{stem}.log").write_text(log + err)
    return out


def _run_bounded(cmd: list[str], wall_s: float) -> tuple[str, str]:
    """(stdout, stderr) of ``cmd``, its whole process group killed after ``wall_s`` seconds:
    astrometry-engine looks at ``--cpulimit`` only between index files, and one pass over
    the 22′-44′ files can take minutes of CPU on a wide field."""
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        return proc.communicate(timeout=wall_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        log, err = proc.communicate()
        return log, err + f"\nkilled after {wall_s:g} s of wall time\n"


def width_hint_deg(entry: dict) -> tuple[float, float]:
    """The width range (degrees) solve-field is told: half to twice the field its source
    states or that was estimated from the lens (``fov_guess_deg`` in sources.json), else
    ``SCALE_DEG``; within ``SCALE_DEG`` either way."""
    guess = entry.get("fov_guess_deg")
    if not guess:
        return SCALE_DEG
    lo, hi = max(SCALE_DEG[0], 0.5 * guess), min(SCALE_DEG[1], 2.0 * guess)
    return (lo, hi) if lo < hi else SCALE_DEG


def cmd_solve(args) -> None:
    """solve-field on each file not solved yet (in any ``WORK/solve*.json``: processes run side
    by side with ``--status solve2.json``, ``--reverse``), its outcome in ``--status``."""
    folder = corpus_dir()
    status_file = WORK / args.status
    status = json.loads(status_file.read_text()) if status_file.exists() else {}
    entries = sources()[:: -1 if args.reverse else 1]
    for entry in entries:
        name = entry["name"]
        if args.only and name not in args.only:
            continue
        if name in solve_status() and not args.again:
            continue
        status[name] = solve_one(entry, folder, args.cpulimit)
        print(name, json.dumps(status[name]), flush=True)
        status_file.write_text(json.dumps(status, indent=1))
    status_file.write_text(json.dumps(status, indent=1))


def wcs_of(name: str, work: Path = WORK):
    """astropy WCS of astrometry.net's solution of ``name`` (None when it did not solve)."""
    from astropy.io import fits
    from astropy.wcs import WCS, FITSFixedWarning

    path = work / f"{Path(name).stem}.wcs"
    if not path.exists():
        return None, None
    header = fits.getheader(path)
    with warnings.catch_warnings():  # a header-only file: "more axes than the image"
        warnings.simplefilter("ignore", FITSFixedWarning)
        return WCS(header), header


def sky_unit(wcs, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """ICRS unit vectors of starnav pixels (x, y) through a WCS (TAN + SIP)."""
    from starnav.geometry import radec_to_unit

    fx, fy = fits_from_starnav(x, y)
    ra, dec = wcs.all_pix2world(np.atleast_1d(fx), np.atleast_1d(fy), 1)
    return radec_to_unit(np.radians(ra), np.radians(dec))


def convert(wcs, width: int, height: int) -> dict:
    """starnav's reference (boresight at W/2, H/2; roll; parity; horizontal FOV; scale) and
    the attitude matrix from astrometry.net's WCS (see the module docstring)."""
    from starnav.geometry import angle_between, radec_roll_from_attitude

    cx, cy, step = width / 2.0, height / 2.0, 1.0
    xs, ys = np.array([cx, cx + step, cx]), np.array([cy, cy, cy + step])
    centre, right, down = sky_unit(wcs, xs, ys)
    # the local sky directions of +x and +y, in the tangent plane; the nearest pair of
    # orthonormal axes to them (polar decomposition: the rotation part of the WCS's local
    # Jacobian, free of its skew and unequal scales), as astrometry.net's orientation
    tangent = np.column_stack([right - centre, down - centre])
    tangent -= np.outer(centre, centre @ tangent)
    u, _, vt = np.linalg.svd(tangent, full_matrices=False)
    x_axis, y_axis = (u @ vt).T
    R = np.vstack([x_axis, y_axis, centre])
    ra, dec, roll, parity_r = radec_roll_from_attitude(R)
    left_edge, right_edge = sky_unit(wcs, np.array([0.0, width]), np.array([cy, cy]))
    fov = float(np.degrees(angle_between(left_edge, right_edge)))
    scale = float(np.sqrt(abs(np.linalg.det(wcs.pixel_scale_matrix))) * 3600.0)
    return {
        "ra_deg": round(ra, 6),
        "dec_deg": round(dec, 6),
        "roll_deg": round(roll, 4),
        "parity": parity_r,
        "fov_deg": round(fov, 5),
        "scale_arcsec_per_px": round(scale, 4),
        "R_cam_from_icrs": np.round(R, 9).tolist(),
    }


def raw_wcs(header) -> dict:
    """The WCS numbers astrometry.net wrote (TAN core; the SIP order)."""
    keys = ("CTYPE1", "CTYPE2", "CRPIX1", "CRPIX2", "CRVAL1", "CRVAL2")
    keys += ("CD1_1", "CD1_2", "CD2_1", "CD2_2", "IMAGEW", "IMAGEH", "A_ORDER")
    return {k: header[k] for k in keys if k in header}


def solve_status() -> dict:
    """What ``solve`` recorded per file (``WORK/solve*.json``: one file per process that ran
    it)."""
    status: dict = {}
    for path in sorted(WORK.glob("solve*.json")):
        status.update(json.loads(path.read_text() or "{}"))
    return status


def cmd_reference(args) -> None:
    status = solve_status()
    out: dict = {
        "about": (
            "Reference answers for the real-image corpus in starnav's conventions (pixel origin"
            " at the top-left corner, boresight = image centre W/2, H/2, roll = position angle"
            " of image up (-y) from North through East, parity +1 = the sky as seen, fov_deg"
            " horizontal), converted from astrometry.net's WCS by make_reference.py (read its"
            " docstring); 'astrometry_net' has the raw numbers, 'check' the catalog-star test."
        ),
        "astrometry_net": {
            "version": astrometry_version(),
            "package": "Debian astrometry.net 0.93+dfsg-1+b1, astrometry-data-tycho2-07, -08, -09"
            " and -10-19 2-4 (little-endian)",
            "index": "Tycho-2 index-tycho2-07..19 (quad scales 22-2000 arcmin); the first 50"
            " files were solved with 10..19 only (30-2000 arcmin)",
        },
        "images": {},
    }
    old = json.loads(REFERENCE.read_text())["images"] if REFERENCE.exists() else {}
    for entry in sources():
        name = entry["name"]
        if name not in status and name in old:  # solved in an earlier run: kept as it was
            out["images"][name] = old[name]
            continue
        solved = status.get(name, {})
        record = {
            "file": {k: entry[k] for k in ("bytes", "sha256")},
            "width": solved.get("width"),
            "height": solved.get("height"),
            "solved_by_reference": bool(solved.get("solved")),
            "seconds": solved.get("seconds"),
        }
        wcs, header = wcs_of(name)
        if wcs is not None:
            ref = convert(wcs, solved["width"], solved["height"])
            up = solved.get("up_deg_e_of_n")
            record.update(ref)
            log = (WORK / f"{Path(name).stem}.log").read_text()
            odds = re.findall(r"log-odds ratio ([\d.]+) \([^)]*\), (\d+) match", log)
            record["astrometry_net"] = {
                "index": (solved.get("index") or "").rstrip("."),
                "log_odds": float(odds[-1][0]) if odds else None,
                "n_match": int(odds[-1][1]) if odds else None,
                "up_deg_e_of_n": up,
                "parity": solved.get("parity_text"),
                "command": solved.get("command"),
                "wcs": raw_wcs(header),
            }
            centred = (
                abs(header["CRPIX1"] - (solved["width"] + 1) / 2) < 0.5
                and abs(header["CRPIX2"] - (solved["height"] + 1) / 2) < 0.5
            )
            record["astrometry_net"]["crpix_at_centre"] = centred
            # its "up" is the position angle at CRVAL: comparable when that is the centre
            if centred and up is not None and solved.get("parity_text") == "neg":
                gap = (ref["roll_deg"] - (up + 180.0) + 180.0) % 360.0 - 180.0
                record["astrometry_net"]["roll_minus_up_plus_180_deg"] = round(gap, 4)
                # CRVAL is the centre (--crpix-center): the same point, the same North
                if abs(gap) > 0.01:
                    raise SystemExit(f"{name}: roll {ref['roll_deg']} but up {up} E of N")
        if name in old and "check" in old[name] and not args.drop_checks and "ra_deg" in record:
            record["check"] = old[name]["check"]
            reject_failed_check(record)
        out["images"][name] = record
        print(
            name,
            record.get("ra_deg"),
            record.get("dec_deg"),
            record.get("roll_deg"),
            record.get("fov_deg"),
            flush=True,
        )
    REFERENCE.write_text(json.dumps(out, indent=1, ensure_ascii=False) + "\n")


def project(R: np.ndarray, parity_flip: bool, fov_deg: float, width: int, height: int, vectors):
    """Pinhole pixels (starnav convention) of ICRS unit vectors for an attitude; a parity
    flip mirrors x. Returns (xy, in_front mask)."""
    f = (width / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    c = vectors @ R.T
    front = c[:, 2] > 0.2
    x = width / 2.0 + f * c[:, 0] / np.where(front, c[:, 2], 1.0)
    y = height / 2.0 + f * c[:, 1] / np.where(front, c[:, 2], 1.0)
    if parity_flip:
        x = width - x
    return np.column_stack([x, y]), front


def star_check(
    R, fov_deg, pixels, detections, catalog, brightest: int | None = None, parity_flip=False
) -> dict:
    """How the catalog stars projected with an attitude fall on the detections (within
    3 px or 0.4 % of the width): all in view, or only the ``brightest`` ones in view."""
    from scipy.spatial import cKDTree

    height, width = pixels.shape
    xy, front = project(R, parity_flip, fov_deg, width, height, catalog.vectors)
    inside = front & (xy[:, 0] > 0) & (xy[:, 0] < width) & (xy[:, 1] > 0) & (xy[:, 1] < height)
    if brightest is not None:
        keep = np.flatnonzero(inside)[np.argsort(catalog.mag[inside], kind="stable")[:brightest]]
        inside = np.zeros_like(inside)
        inside[keep] = True
    if len(detections) == 0 or not inside.any():
        return {"n_catalog": int(inside.sum()), "n_matched": 0, "median_px": None}
    tol = max(3.0, 0.004 * width)
    dist, _ = cKDTree(detections).query(xy[inside], distance_upper_bound=tol)
    hit = np.isfinite(dist)
    return {
        "n_catalog": int(inside.sum()),
        "n_matched": int(hit.sum()),
        "median_px": round(float(np.median(dist[hit])), 3) if hit.any() else None,
        "tolerance_px": round(tol, 1),
    }


def attitude_check(R: np.ndarray, fov_deg: float, path: Path, catalog) -> dict:
    """``star_check`` of an attitude ``R_cam_from_icrs`` and horizontal ``fov_deg`` on the
    image at ``path`` (starnav's brightest ``CHECK_MAX_DETECTIONS`` detections): as it is
    (``reference``), its ``CHECK_BRIGHTEST`` brightest catalog stars only, and the variants
    wrong on purpose (``CHECK_VARIANTS``: turned by 180° about the boresight, mirrored,
    with the rows flipped)."""
    from starnav.detect.read import read_image
    from starnav.pipeline.image import detect_image

    pixels = read_image(path)
    xy = detect_image(pixels, max_stars=CHECK_MAX_DETECTIONS).xy
    turned = np.diag([-1.0, -1.0, 1.0]) @ R
    flipped = xy * [1, -1] + [0, pixels.shape[0]]
    return {
        "reference": star_check(R, fov_deg, pixels, xy, catalog),
        "reference_brightest": star_check(R, fov_deg, pixels, xy, catalog, CHECK_BRIGHTEST),
        "roll_plus_180": star_check(turned, fov_deg, pixels, xy, catalog),
        "mirrored": star_check(R, fov_deg, pixels, xy, catalog, parity_flip=True),
        "rows_flipped": star_check(R, fov_deg, pixels[::-1], flipped, catalog),
    }


def check_passes(check: dict) -> bool:
    """Whether an ``attitude_check`` puts at least 3, and three times as many, catalog stars
    on detections as any variant wrong on purpose."""
    others = max(check[k]["n_matched"] for k in CHECK_VARIANTS)
    return check["reference"]["n_matched"] >= max(3, 3 * others)


def reject_failed_check(ref: dict) -> None:
    """An answer of astrometry.net that puts fewer catalog stars on detections than three
    times what a turned, mirrored or flipped attitude does is wrong: not a reference. With
    fewer than ``CHECK_MIN_IN_VIEW`` catalog stars in view (a telescope field narrower than
    ~2°: Hp <= 6.5 holds none) the check says nothing, and astrometry.net's own verification
    (log-odds above 1e9 on Tycho-2) stands: ``check_inconclusive``; so does an answer whose
    log-odds pass ``CHECK_OVERRIDE_LOG_ODDS`` (``check_overridden``)."""
    check = ref["check"]
    if check["reference"]["n_catalog"] < CHECK_MIN_IN_VIEW:
        ref["check_inconclusive"] = True
        return
    if check_passes(check):
        return
    others = max(check[k]["n_matched"] for k in CHECK_VARIANTS)
    odds = (ref.get("astrometry_net") or {}).get("log_odds") or 0.0
    if odds >= CHECK_OVERRIDE_LOG_ODDS:  # see CHECK_OVERRIDE_LOG_ODDS
        ref["check_overridden"] = f"catalog check failed; astrometry.net's log-odds {odds:.0f}"
        return
    ref["solved_by_reference"] = False
    ref["rejected"] = (
        f"astrometry.net's answer fails the catalog check: {check['reference']['n_matched']}"
        f" of {check['reference']['n_catalog']} catalog stars on detections, a turned,"
        f" mirrored or flipped attitude {others}"
    )


def cmd_check(args) -> None:
    from starnav.catalog import load_catalog
    from starnav.geometry import attitude_from_radec_roll

    catalog = load_catalog(None, mag_limit=CHECK_MAG_LIMIT)
    folder = corpus_dir()
    data = json.loads(REFERENCE.read_text())
    for name, ref in data["images"].items():
        if "ra_deg" not in ref or (args.only and name not in args.only):
            continue
        if args.missing and "check" in ref:
            continue
        ref["solved_by_reference"] = True
        for verdict in ("rejected", "check_overridden", "check_inconclusive"):
            ref.pop(verdict, None)
        R = attitude_from_radec_roll(ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"])
        ref["check"] = {
            "about": (
                f"Hipparcos Hp <= {CHECK_MAG_LIMIT} projected (pinhole, fov_deg, this attitude)"
                f" onto starnav's brightest {CHECK_MAX_DETECTIONS} detections"
            ),
            **attitude_check(R, ref["fov_deg"], folder / name, catalog),
        }
        reject_failed_check(ref)
        print(name, json.dumps(ref["check"]["reference"]), flush=True)
    REFERENCE.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")


def cmd_table(args) -> None:
    """The table of files and reference answers, into README.md's block ``references``."""
    data = json.loads(REFERENCE.read_text())["images"]
    lines = [
        "| file | licence | bytes | W x H | astrometry.net | RA° | Dec° | roll° | parity "
        "| FOV° | ″/px | catalog check |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for entry in sources():
        ref = data[entry["name"]]
        size = f"{ref['width']} x {ref['height']}" if ref.get("width") else ""
        head = f"| `{entry['name']}` | {entry['licence']} | {entry['bytes']} | {size} |"
        if not ref["solved_by_reference"]:
            what = "rejected: fails the catalog check" if "rejected" in ref else "not solved"
            lines.append(head + f" {what} |  |  |  |  |  |  |  |")
            continue
        good = ref.get("check", {}).get("reference", {})
        check = f"{good.get('n_matched')}/{good.get('n_catalog')}, {good.get('median_px')} px"
        index = ref["astrometry_net"]["index"].replace("index-tycho2-", "").split(".")[0]
        lines.append(
            head + f" solved (index {index}) | {ref['ra_deg']:.4f} | {ref['dec_deg']:.4f} | "
            f"{ref['roll_deg']:.3f} | {ref['parity']:+d} | {ref['fov_deg']:.3f} | "
            f"{ref['scale_arcsec_per_px']:.2f} | {check} |"
        )
    readme = HERE / "README.md"
    text = readme.read_text()
    begin, end = "<!-- begin references -->", "<!-- end references -->"
    a, b = text.index(begin) + len(begin), text.index(end)
    readme.write_text(text[:a] + "\n" + "\n".join(lines) + "\n" + text[b:])


def add_solve_command(sub, help_text: str, cpulimit_s: int) -> None:
    """The ``solve`` subcommand's options (this script's and make_narrow_reference.py's)."""
    p = sub.add_parser("solve", help=help_text)
    p.add_argument("--again", action="store_true", help="solve files solved before too")
    p.add_argument("--cpulimit", type=int, default=cpulimit_s, help="CPU seconds per image")
    p.add_argument("--status", default="solve.json", help="this process's record (in WORK)")
    p.add_argument("--reverse", action="store_true", help="from the last file")
    p.add_argument("only", nargs="*", help="only these files")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    add_solve_command(sub, "run astrometry.net on every file", CPU_LIMIT_S)
    p = sub.add_parser("reference", help="convert the WCS files into reference.json")
    p.add_argument("--drop-checks", action="store_true", help="forget the earlier checks")
    p = sub.add_parser("check", help="project catalog stars onto the detections")
    p.add_argument("--missing", action="store_true", help="only references with no check yet")
    p.add_argument("only", nargs="*", help="only these files")
    sub.add_parser("table", help="write the table of references into README.md")
    args = parser.parse_args()
    commands = {"solve": cmd_solve, "reference": cmd_reference, "check": cmd_check}
    commands["table"] = cmd_table
    commands[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
