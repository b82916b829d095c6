"""Independent references for the real all-sky corpus (tests/data/real/allsky_manifest.json).

The frames are other projects' files and are not in the repository: the manifest lists each by
repository, commit, path, git blob and SHA-256 (gathered into a folder such as
/work/allsky/files). This script gives each frame a reference that does not come from starnav:
astrometry.net (``solve-field``, Tycho-2 index files 4107-4119) on crops of the frame where a
fisheye is nearly gnomonic, its matched stars (the ``.corr`` file) mapped back to full-image
pixels::

    python benchmarks/images/make_allsky_reference.py solve --files DIR --astrometry WORK
    python benchmarks/images/make_allsky_reference.py build --files DIR --astrometry WORK \
        [--manifest /work/allsky/manifest.json] [--set SET | --only NAME ...]
    python benchmarks/images/make_allsky_reference.py table   # docs/allsky.md "The frames"

``build --set SET`` (or ``--only NAME ...``) rebuilds the references of those frames only: every
other frame of the manifest keeps its entry of the committed allsky_manifest.json unchanged
(a new set is added without the earlier sets' astrometry.net outputs at hand).

``solve`` reads each frame as starnav reads it (``starnav.detect.read.read_image``; a
gzip-compressed PGM, which starnav does not read, by ``read_frame`` here: the first image of
the stack, row 0 at the top), finds the sky disc (``starnav.detect.circle.find_image_circle``,
used only to place the crops; the image centre and half the shorter side without a disc) and
cuts square crops of side 0.5 R (about 40-45° of sky for a 180° fisheye of disc radius R) at
the disc centre, then 0.7 R and 0.35 R when that fails, then the whole frame (told 5°-100°:
a camera that is not a fisheye), and, once the centre solves, two more at 0.45 R right of and
above the centre. Each crop goes to solve-field as a FITS file with
``data[0]`` as FITS row 1, so FITS pixel (X, Y) of the crop is our (X - 0.5 + x0, Y - 0.5 + y0)
in the full frame (x0, y0: the crop's top-left corner in whole pixels; our convention: the
top-left pixel's centre at (0.5, 0.5)). solve-field runs as::

    solve-field CROP.fits --crpix-center --no-plots --overwrite --new-fits none \
        --scale-units degwidth --scale-low LO --scale-high HI --cpulimit 40 \
        [--downsample 2 above 1500 px]

with LO-HI a third to three times the width the disc radius implies (R px for 85°), or
5°-100° without a disc, its process group killed after 70 s of wall time.

``solve --only NAME --at X Y`` adds a crop of side 0.3 R centred on the pixel (X, Y) of a
frame already solved (label ``at_X_Y``): a second opinion where a star lies far from the
centres of the first crops, whose TAN-SIP fits of the fisheye may be off by 10 px there
(``real_allsky.py`` reads a star's sky direction through the crop holding it farthest
inside, so a crop centred on it wins).

``build`` writes tests/data/real/allsky_manifest.json: the manifest's metadata (no image bytes)
and per frame ``reference``: ``stars`` [[x_px, y_px, ra_deg, dec_deg, source], ...] (at most
40, spread over the crops), astrometry.net's catalog (Tycho-2) positions of the stars it
matched, at the field pixel it matched them to (a match whose pixel lies more than 2 px from
where the crop's WCS puts the catalog star is dropped); ``centre_radec_deg``: the sky
direction at the disc centre through the centre crop's WCS (TAN + SIP); ``zenith_offset_deg``:
its angle from the zenith at the manifest's site and UTC (astropy AltAz), a check of both the
reference and the metadata for an upward camera; ``crops``: what was solved. Frames without an
astrometry.net answer get ``stars`` from a hand identification where one exists
(tests/data/allsky/kho_20201211_star_ids.csv: the KHO Sony frame of 2020-12-11, positions
clicked on the frame, stars named with Stellarium), else no reference (``method`` says so).
"""

from __future__ import annotations

import argparse
import csv
import gzip
import json
import re
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "data" / "real"))  # make_reference: shared helpers
from make_reference import _run_bounded, fits_from_starnav  # noqa: E402

OUT = ROOT / "tests" / "data" / "real" / "allsky_manifest.json"
KHO_IDS = ROOT / "tests" / "data" / "allsky" / "kho_20201211_star_ids.csv"
CPU_LIMIT_S = 40
WALL_S = 70
MAX_STARS = 40
MATCH_RESIDUAL_PX = 2.0
PX_PER_DISC_RADIUS_DEG = 85.0  # a 180° fisheye's disc radius R spans ~85-90° near the centre


def read_frame(path: Path) -> np.ndarray:
    """The frame as a 2-D float array in starnav's orientation (row 0 at the top): starnav's
    reader, or for a (gzip-compressed) PGM stack the first image of the stack."""
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b" and not path.name.lower().endswith((".fits.gz", ".fit.gz")):
        raw = gzip.decompress(raw)
        if raw[:2] == b"P5":
            return _first_pgm(raw)
    from starnav.detect.read import read_image

    return read_image(path)


def _first_pgm(raw: bytes) -> np.ndarray:
    """First image of a binary PGM (P5) stack, comments allowed between the header fields."""
    pos, fields = 2, []
    while len(fields) < 3:
        while raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":
            pos = raw.index(b"\n", pos) + 1
            continue
        token = re.match(rb"\d+", raw[pos : pos + 20]).group()
        fields.append(int(token))
        pos += len(token)
    width, height, maxval = fields
    dtype = ">u2" if maxval > 255 else np.uint8
    size = width * height * np.dtype(dtype).itemsize
    return (
        np.frombuffer(raw[pos + 1 : pos + 1 + size], dtype=dtype)
        .reshape(height, width)
        .astype(np.float32)
    )


def crop_plan(
    shape: tuple[int, int], circle
) -> tuple[list[tuple[str, float, float, float]], float]:
    """[(label, centre x, centre y, side px), ...] in the order tried, and R (px)."""
    height, width = shape
    if circle is not None:
        cx, cy, r = circle.cx, circle.cy, circle.radius_px
    else:
        cx, cy, r = width / 2, height / 2, min(width, height) / 2
    plan = [("centre", cx, cy, 0.5 * r), ("centre_wide", cx, cy, 0.7 * r)]
    plan += [("centre_narrow", cx, cy, 0.35 * r)]
    plan += [("centre_full", width / 2, height / 2, max(width, height))]  # a narrow camera
    plan += [("right", cx + 0.45 * r, cy, 0.5 * r), ("up", cx, cy - 0.45 * r, 0.5 * r)]
    return plan, r


def solve_crop(pixels, label, cx, cy, side, scale, stem, work: Path) -> dict:
    """solve-field on one crop; its .wcs, .corr and the crop offset kept in ``work``."""
    from astropy.io import fits

    height, width = pixels.shape
    x0 = int(max(0, min(width - 1, round(cx - side / 2))))
    y0 = int(max(0, min(height - 1, round(cy - side / 2))))
    x1 = int(min(width, round(cx + side / 2)))
    y1 = int(min(height, round(cy + side / 2)))
    out = {"label": label, "x0": x0, "y0": y0, "width": x1 - x0, "height": y1 - y0}
    if x1 - x0 < 64 or y1 - y0 < 64:
        return out | {"solved": False, "why": "crop outside the frame"}
    crop = np.nan_to_num(pixels[y0:y1, x0:x1]).astype(np.float32)
    name = f"{stem}.{label}"
    with tempfile.TemporaryDirectory() as tmp:
        image = Path(tmp) / f"{name}.fits"
        fits.PrimaryHDU(crop).writeto(image)
        cmd = ["solve-field", str(image), "--dir", tmp, "--crpix-center", "--no-plots"]
        cmd += ["--overwrite", "--new-fits", "none", "--scale-units", "degwidth"]
        cmd += ["--scale-low", f"{scale[0]:.2f}", "--scale-high", f"{scale[1]:.2f}"]
        cmd += ["--cpulimit", str(CPU_LIMIT_S)]
        if max(crop.shape) > 1500:
            cmd += ["--downsample", "2"]
        started = time.perf_counter()
        log, err = _run_bounded(cmd, WALL_S)
        out["seconds"] = round(time.perf_counter() - started, 1)
        out["scale_deg"] = [round(scale[0], 2), round(scale[1], 2)]
        wcs, corr = Path(tmp) / f"{name}.wcs", Path(tmp) / f"{name}.corr"
        out["solved"] = wcs.exists() and corr.exists()
        match = re.search(r"log-odds ratio ([-\d.]+)", log)
        out["log_odds"] = float(match.group(1)) if match else None
        if out["solved"]:
            (work / wcs.name).write_bytes(wcs.read_bytes())
            (work / corr.name).write_bytes(corr.read_bytes())
        (work / f"{name}.log").write_text(log + err)
    return out


def cmd_solve(args) -> None:
    from starnav.detect.circle import find_image_circle

    manifest = json.loads(Path(args.manifest).read_text())["files"]
    work = Path(args.astrometry)
    work.mkdir(parents=True, exist_ok=True)
    status_path = work / "crops.json"
    status = json.loads(status_path.read_text()) if status_path.exists() else {}
    for entry in manifest:
        name = entry["name"]
        if args.only and name not in args.only:
            continue
        if args.set and entry["set"] != args.set:
            continue
        if args.at:
            _solve_at(entry, status, args)
            continue
        if name in status and not args.again:
            continue
        path = Path(args.files) / name
        if not path.exists():
            print(f"{name}: not in {args.files}", flush=True)
            continue
        pixels = read_frame(path)
        stretch = 1.0
        if entry.get("pixel_aspect"):  # non-square pixels: rows resampled, all else on that
            from scipy import ndimage

            rows = pixels.shape[0]
            zoom = (1.0 / entry["pixel_aspect"], 1.0)
            pixels = ndimage.zoom(pixels, zoom, order=1, grid_mode=True, mode="nearest")
            stretch = pixels.shape[0] / rows  # row centres scale by what zoom made of it
        circle = find_image_circle(pixels)
        plan, r = crop_plan(pixels.shape, circle)
        stem = Path(name).name.split(".")[0]
        crops = []
        for label, cx, cy, side in plan:
            centre_done = any(c["solved"] for c in crops)
            if label.startswith("centre") and centre_done:
                continue
            if not label.startswith("centre") and not centre_done:
                continue
            width_deg = side / (r / PX_PER_DISC_RADIUS_DEG)
            scale = (width_deg / 3, min(150, width_deg * 3))
            if circle is None or label == "centre_full":
                scale = (5.0, 100.0)
            crops.append(solve_crop(pixels, label, cx, cy, side, scale, stem, work))
            if stretch != 1.0:
                crops[-1]["stretch"] = stretch  # x0, y0, width, height: in stretched rows
            print(name, json.dumps(crops[-1]), flush=True)
        if status_path.exists():  # another process may have added frames meanwhile
            status = json.loads(status_path.read_text()) | {
                k: v for k, v in status.items() if k == name
            }
        status[name] = {
            "shape": list(pixels.shape),
            "circle": None if circle is None else [circle.cx, circle.cy, circle.radius_px],
            "crops": crops,
        }
        status_path.write_text(json.dumps(status, indent=1))


def _solve_at(entry: dict, status: dict, args) -> None:
    """Crops centred on the pixels ``args.at`` of a frame ``solve`` already tried, added to
    its crops (see the module's docstring)."""
    name = entry["name"]
    if name not in status:
        raise SystemExit(f"{name}: run solve on it first (--at adds to its crops)")
    got = status[name]
    pixels = read_frame(Path(args.files) / name)
    if entry.get("pixel_aspect"):
        raise SystemExit(f"{name}: --at is not done for non-square pixels")
    r = got["circle"][2] if got["circle"] else min(pixels.shape) / 2
    side = 0.3 * r
    width_deg = side / (r / PX_PER_DISC_RADIUS_DEG)
    stem = Path(name).name.split(".")[0]
    if len(args.at) % 2:
        raise SystemExit("--at takes pixel pairs: X Y [X Y ...]")
    for x, y in zip(args.at[::2], args.at[1::2], strict=True):
        label = f"at_{x:.0f}_{y:.0f}"
        crop = solve_crop(pixels, label, x, y, side, (width_deg / 3, width_deg * 3), stem,
                          Path(args.astrometry))  # fmt: skip
        got["crops"] = [c for c in got["crops"] if c["label"] != label] + [crop]
        print(name, json.dumps(crop), flush=True)
    status_path = Path(args.astrometry) / "crops.json"
    status_path.write_text(json.dumps(status, indent=1))


def _wcs(path: Path):
    from astropy.io import fits
    from astropy.wcs import WCS, FITSFixedWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FITSFixedWarning)
        return WCS(fits.getheader(path))


def crop_stars(work: Path, stem: str, crop: dict) -> list[list]:
    """astrometry.net's matched stars of one solved crop, in full-frame pixels (ours)."""
    from astropy.io import fits

    name = f"{stem}.{crop['label']}"
    wcs = _wcs(work / f"{name}.wcs")
    table = fits.getdata(work / f"{name}.corr")
    fx, fy = np.asarray(table["field_x"], float), np.asarray(table["field_y"], float)
    ra, dec = np.asarray(table["index_ra"], float), np.asarray(table["index_dec"], float)
    px, py = wcs.all_world2pix(ra, dec, 1)  # FITS 1-based pixels of the crop
    keep = np.hypot(px - fx, py - fy) <= MATCH_RESIDUAL_PX
    x, y = fits_from_starnav(0, 0)  # our (0, 0) in FITS pixels: (0.5, 0.5)
    out = []
    for i in np.nonzero(keep)[0]:
        xf, yf = fx[i] - x + crop["x0"], (fy[i] - y + crop["y0"]) / crop.get("stretch", 1.0)
        src = f"astrometry.net crop {crop['label']} (log-odds {crop.get('log_odds')})"
        out.append([round(xf, 2), round(yf, 2), round(ra[i], 6), round(dec[i], 6), src])
    return out


def wcs_cards(path: Path) -> dict:
    """The WCS cards of astrometry.net's .wcs header (TAN + SIP), enough to rebuild it."""
    from astropy.io import fits

    header = fits.getheader(path)
    keep = re.compile(
        r"^(CTYPE|CUNIT|CRVAL|CRPIX|CD\d_\d|[AB]P?_(ORDER|\d_\d)|IMAGE[WH]|EQUINOX|RADESYS|LONPOLE|LATPOLE)"
    )
    return {k: header[k] for k in header if keep.match(k)}


def corroboration(ref: dict, solved: list[dict]) -> list[str]:
    """Why the astrometry.net answer is believed beyond its own log-odds threshold (ln 1e9 =
    20.7): a log-odds of 40 or more; a second crop solved; the disc centre within 15° of the
    zenith at the manifest's site and UTC (an upward camera). Empty: one weak crop only."""
    why = []
    best = max((c.get("log_odds") or 0) for c in solved)
    if best >= 40:
        why.append(f"log-odds {best:.0f}")
    if len(solved) >= 2:
        why.append(f"{len(solved)} crops solved")
    if ref.get("zenith_offset_deg") is not None and ref["zenith_offset_deg"] < 15:
        why.append(
            f"disc centre {ref['zenith_offset_deg']:.1f} deg from the zenith at site and UTC"
        )
    return why


def zenith_radec_deg(site: dict, utc: str) -> tuple[float, float]:
    """ICRS RA/Dec (deg) of the zenith at the site and time (astropy AltAz -> ICRS)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    here = EarthLocation(
        lat=site["lat_deg"] * u.deg,
        lon=site["lon_deg"] * u.deg,
        height=(site["height_m"] or 0) * u.m,
    )
    up = SkyCoord(alt=90 * u.deg, az=0 * u.deg, frame=AltAz(obstime=Time(utc), location=here))
    return float(up.icrs.ra.deg), float(up.icrs.dec.deg)


def _angle_deg(a: tuple[float, float], b: tuple[float, float]) -> float:
    ra1, de1, ra2, de2 = np.radians([a[0], a[1], b[0], b[1]])
    c = np.sin(de1) * np.sin(de2) + np.cos(de1) * np.cos(de2) * np.cos(ra1 - ra2)
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def hand_ids(entry: dict) -> list[list] | None:
    """The KHO frame's hand identifications as reference stars (HIP positions from starnav's
    catalog by name: the identification is by hand, the catalog only gives its RA/Dec)."""
    if not entry["name"].startswith("kho_lyr-sony-111220"):
        return None
    from starnav.catalog import load_catalog
    from starnav.catalog.names import star_names

    hip_of = {name: hip for hip, name in star_names().items()}
    cat = load_catalog()
    rows = []
    with KHO_IDS.open() as fh:
        for row in csv.DictReader(fh):
            k = int(np.nonzero(cat.ids == hip_of[row["name"]])[0][0])
            rows.append(
                [
                    float(row["sony_x0"]) + 0.5,
                    float(row["sony_y0"]) + 0.5,
                    round(float(cat.ra_deg[k]), 6),
                    round(float(cat.dec_deg[k]), 6),
                    f"hand identification ({KHO_IDS.name}: {row['name']})",
                ]
            )
    return rows


def enu_of(radec: np.ndarray, site: dict, utc: str) -> np.ndarray:
    """East-north-up unit vectors of ICRS (RA, Dec) degrees at the site and time (astropy
    AltAz, no refraction)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    here = EarthLocation(
        lat=site["lat_deg"] * u.deg,
        lon=site["lon_deg"] * u.deg,
        height=(site["height_m"] or 0) * u.m,
    )
    sky = SkyCoord(ra=radec[:, 0] * u.deg, dec=radec[:, 1] * u.deg)
    aa = sky.transform_to(AltAz(obstime=Time(utc), location=here))
    alt, az = aa.alt.rad, aa.az.rad
    return np.stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)], axis=-1)


def _project(params: np.ndarray, enu: np.ndarray, lens: str, parity: int) -> np.ndarray:
    """Pixels of ENU directions through a fisheye looking along the rotated up axis."""
    from scipy.spatial.transform import Rotation

    cam = Rotation.from_rotvec(params[:3]).apply(enu)  # camera frame: z the optical axis
    theta = np.arccos(np.clip(cam[:, 2], -1, 1))
    r = params[3] * (theta if lens == "equidistant" else 2 * np.sin(theta / 2))
    phi = np.arctan2(cam[:, 1], cam[:, 0])
    return np.stack([params[4] + r * np.cos(phi), params[5] + parity * r * np.sin(phi)], axis=-1)


def fit_camera(xy: np.ndarray, enu: np.ndarray, scale_px: float, centre: tuple[float, float]):
    """Best (rms px, params, lens, parity) of an upward fisheye fitted to stars' pixels and
    ENU directions: optical axis and roll (a rotation vector), focal length, centre; both
    parities, equidistant and equisolid, twelve starting rolls."""
    from scipy.optimize import least_squares

    best = None
    for lens in ("equidistant", "equisolid"):
        for parity in (1, -1):
            for roll in np.radians(np.arange(0, 360, 30)):
                start = np.array([0.0, 0.0, roll, scale_px, centre[0], centre[1]])
                fit = least_squares(
                    lambda p, lens=lens, parity=parity: (
                        _project(p, enu, lens, parity) - xy
                    ).ravel(),
                    start,
                    loss="soft_l1",
                    f_scale=3.0,
                )
                resid = np.hypot(*(_project(fit.x, enu, lens, parity) - xy).T)
                rms = float(np.sqrt(np.mean(resid**2)))
                if best is None or rms < best[0]:
                    best = (rms, fit.x, lens, parity, float(np.max(resid)))
    return best


TRANSFER_MAX_RMS_PX = 3.0
TRANSFER_MAG = 3.0  # the bright stars predicted on the target frame
TRANSFER_MIN_ALT_DEG = 20.0


ROTATION_MAX_S = 3600.0  # a fixed camera's frames this close in time share one reference


def rotated_reference(entry: dict, files: list[dict]) -> dict | None:
    """The reference of another frame of the same fixed camera taken within an hour, turned
    with the sky: what a fixed camera sees at a pixel keeps its hour angle, so its RA grows by
    the local sidereal time elapsed (astropy, apparent sidereal time at the site); every
    crop's CRVAL1 and every star's RA are shifted by it (a rotation about the celestial pole,
    exact for a TAN-SIP WCS referred to north; precession and aberration over an hour are
    below 0.01°)."""
    from astropy.time import Time

    if not (entry.get("site") and entry.get("utc")):
        return None
    for sib in files:
        ref = sib["reference"]
        if sib is entry or not ref.get("crops") or not ref.get("stars") or not sib.get("utc"):
            continue
        if (sib["project"], sib["camera"], sib.get("site")) != (
            entry["project"], entry["camera"], entry["site"],
        ):  # fmt: skip
            continue
        t0, t1 = Time(sib["utc"]), Time(entry["utc"])
        if abs((t1 - t0).sec) > ROTATION_MAX_S:
            continue
        lon = entry["site"]["lon_deg"]
        shift = float((t1.sidereal_time("apparent", lon) - t0.sidereal_time("apparent", lon)).deg)
        shift = (shift + 180.0) % 360.0 - 180.0
        dt = (t1 - t0).sec
        src = f"sky rotation of {sib['name']}'s reference ({dt:+.0f} s: RA {shift:+.3f} deg)"
        crops = []
        for crop in ref["crops"]:
            crop = dict(crop)
            if "wcs" in crop:
                crop["wcs"] = dict(crop["wcs"], CRVAL1=(crop["wcs"]["CRVAL1"] + shift) % 360.0)
            crops.append(crop)
        stars = [
            [x, y, round((ra + shift) % 360.0, 6), dec, src] for x, y, ra, dec, _ in ref["stars"]
        ]
        out = {"method": src, "stars": stars, "crops": crops, "uncertainty_deg": 0.05}
        for key in ("circle_px", "centre_px", "confirmed_by"):
            if key in ref:
                out[key] = ref[key]
        return out
    return None


def transferred_stars(entry: dict, files: list[dict]) -> dict | None:
    """Reference stars for a frame astrometry.net did not solve, from another frame of the
    same camera (same project, camera and disc) that has reference stars: an upward fisheye
    fitted to that frame's stars (site and UTC: their altitude and azimuth), the Hipparcos
    stars to magnitude 3 above 20° put through it at this frame's UTC. Only when the fit's rms
    is under 3 px; the camera must not have moved between the two frames (a check: the fit of
    one sibling predicting the other's stars, when there are two)."""
    if not (entry.get("site") and entry.get("utc")):
        return None
    siblings = [
        f for f in files
        if f is not entry and f["project"] == entry["project"] and f["camera"] == entry["camera"]
        and f.get("utc") and f["reference"].get("stars")
        and "transfer" not in f["reference"]["method"]
    ]  # fmt: skip
    for sib in siblings:
        stars = sib["reference"]["stars"]
        xy = np.array([s[:2] for s in stars], float)
        enu = enu_of(np.array([s[2:4] for s in stars], float), sib["site"], sib["utc"])
        circle = sib["reference"].get("circle_px") or [*xy.mean(axis=0), 0.0]
        scale = (circle[2] or 500.0) / (np.pi / 2)
        rms, params, lens, parity, worst = fit_camera(xy, enu, scale, tuple(circle[:2]))
        if rms > TRANSFER_MAX_RMS_PX:
            continue
        from starnav.catalog import load_catalog

        cat = load_catalog().brighter_than(TRANSFER_MAG)
        radec = np.stack([cat.ra_deg, cat.dec_deg], axis=-1)
        target = enu_of(radec, entry["site"], entry["utc"])
        up = target[:, 2] > np.sin(np.radians(TRANSFER_MIN_ALT_DEG))
        pix = _project(params, target[up], lens, parity)
        src = (
            f"transfer from {sib['name']} ({lens} fisheye fitted to its {len(stars)} reference "
            f"stars: rms {rms:.2f} px, worst {worst:.1f} px; Hp <= {TRANSFER_MAG:g}, alt >= "
            f"{TRANSFER_MIN_ALT_DEG:g} deg)"
        )
        out = [
            [round(float(x), 2), round(float(y), 2), round(float(ra), 6), round(float(dec), 6), src]
            for (x, y), (ra, dec) in zip(pix, radec[up], strict=True)
        ]
        checks = {}  # the fit predicting the other siblings' reference stars (px)
        for other in siblings:
            if other is sib:
                continue
            o_xy = np.array([s[:2] for s in other["reference"]["stars"]], float)
            o_enu = enu_of(
                np.array([s[2:4] for s in other["reference"]["stars"]], float),
                other["site"],
                other["utc"],
            )
            miss = np.hypot(*(_project(params, o_enu, lens, parity) - o_xy).T)
            checks[other["name"]] = round(float(np.median(miss)), 2)
        return {
            "method": src,
            "stars": out[:MAX_STARS],
            "transfer_fit_rms_px": round(rms, 2),
            "scale_deg_per_px": round(float(np.degrees(1.0 / abs(params[3]))), 5),  # at the axis
            "uncertainty_deg": round(float(2 * rms * np.degrees(1.0 / abs(params[3]))), 3),
            "transfer_check_median_px": checks,
        }
    return None


def cmd_build(args) -> None:
    manifest = json.loads(Path(args.manifest).read_text())
    work = Path(args.astrometry)
    status = json.loads((work / "crops.json").read_text()) if (work / "crops.json").exists() else {}
    files = []
    kept = _committed_entries(args)
    for entry in manifest["files"]:
        if entry["name"] in kept:
            files.append(kept[entry["name"]])
            continue
        entry = dict(entry)
        got = status.get(entry["name"])
        ref = {"method": "none: astrometry.net " + ("did not solve any crop" if got else "not run")}
        stem = Path(entry["name"]).name.split(".")[0]
        if got is not None:
            solved = [c for c in got["crops"] if c["solved"]]
            stretch = next((c["stretch"] for c in got["crops"] if "stretch" in c), 1.0)
            ref["circle_px"] = (  # centre x, y and radius (in columns: rows may be stretched)
                None
                if got["circle"] is None
                else [
                    round(v, 1)
                    for v in (got["circle"][0], got["circle"][1] / stretch, got["circle"][2])
                ]
            )
            ref["crops"] = [
                {
                    k: c.get(k)
                    for k in (
                        "label",
                        "x0",
                        "y0",
                        "width",
                        "height",
                        "solved",
                        "log_odds",
                        "seconds",
                    )
                }
                | ({"wcs": wcs_cards(work / f"{stem}.{c['label']}.wcs")} if c["solved"] else {})
                for c in got["crops"]
            ]
            stars = _held_by_own_crop(
                [s for c in solved for s in crop_stars(work, stem, c)], ref["crops"]
            )
            if stars:
                ref["method"] = "astrometry.net on crops (Tycho-2 index 4107-4119)"
                ref["stars"] = _spread(stars)
                centre = next((c for c in solved if c["label"].startswith("centre")), None)
                if centre is not None:
                    cx, cy = (got["circle"] or [got["shape"][1] / 2, got["shape"][0] / 2])[:2]
                    fx, fy = fits_from_starnav(cx - centre["x0"], cy - centre["y0"])
                    ra, dec = _wcs(work / f"{stem}.{centre['label']}.wcs").all_pix2world(fx, fy, 1)
                    ref["centre_px"] = [round(cx, 1), round(cy / centre.get("stretch", 1.0), 1)]
                    ref["centre_radec_deg"] = [round(float(ra), 4), round(float(dec), 4)]
                    if entry.get("site") and entry.get("utc"):
                        zen = zenith_radec_deg(entry["site"], entry["utc"])
                        ref["zenith_offset_deg"] = round(
                            _angle_deg(zen, ref["centre_radec_deg"]), 2
                        )
                ref["confirmed_by"] = corroboration(ref, solved)
        if "stars" not in ref:
            hand = hand_ids(entry)
            if hand:
                ref["method"] = f"hand identification ({KHO_IDS.relative_to(ROOT)})"
                ref["stars"] = hand
        entry["reference"] = ref
        files.append(entry)
    for entry in files:  # a frame without stars: a sibling frame's fitted camera, if any
        if entry["name"] not in kept and "stars" not in entry["reference"]:
            transfer = rotated_reference(entry, files) or transferred_stars(entry, files)
            if transfer:
                entry["reference"].update(transfer)
    doc = {
        "about": (
            "Real all-sky / meteor frames (metadata only: the bytes are other projects' files; "
            "gather them by repository, commit, path, SHA-256 into a folder and point "
            "STARNAV_ALLSKY_CORPUS at it) with independent references from "
            "benchmarks/images/make_allsky_reference.py. "
            "Pixels: top-left pixel centre at (0.5, 0.5)."
        ),
        "files": files,
        "rejected": manifest.get("rejected", []),
    }
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    with_ref = sum("stars" in f["reference"] for f in files)
    print(f"{OUT.relative_to(ROOT)}: {len(files)} frames, {with_ref} with reference stars")


def _committed_entries(args) -> dict[str, dict]:
    """The committed manifest's entries of the frames ``build`` leaves as they are (those
    outside ``--set`` / ``--only``; none when neither is given), by name."""
    if not (args.set or args.only):
        return {}
    committed = json.loads(OUT.read_text())["files"]
    return {
        f["name"]: f
        for f in committed
        if not (args.only and f["name"] in args.only) and not (args.set and f["set"] == args.set)
    }


def _held_by_own_crop(stars: list[list], crops: list[dict]) -> list[list]:
    """The stars whose pixel the benchmark reads through the crop that matched them (or through
    none): a star near the edge of a small ``--at`` crop is read through a larger crop, whose
    TAN-SIP may disagree with the small one there by a few pixels."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.images.real_allsky import Reference

    reference = Reference({"crops": crops})
    out = []
    for star in stars:
        held = reference.holding(star[0], star[1])
        if held is None or f"crop {held[0]['label']} (" in star[4]:
            out.append(star)
    return out


def _spread(stars: list[list]) -> list[list]:
    """At most MAX_STARS, taken evenly from each crop's list (one entry per catalog star)."""
    seen, unique = set(), []
    for s in stars:
        key = (round(s[2], 4), round(s[3], 4))
        if key not in seen:
            seen.add(key)
            unique.append(s)
    if len(unique) <= MAX_STARS:
        return unique
    pick = np.linspace(0, len(unique) - 1, MAX_STARS).round().astype(int)
    return [unique[i] for i in pick]


def cmd_table(args) -> None:
    """The frames (block ``allsky-sources`` of docs/allsky.md): where from, licence, what makes
    each hard, and its reference, from the committed allsky_manifest.json."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.harness import DOCS, replace_block, table_head, table_row

    doc = json.loads(OUT.read_text())
    rows = table_head(
        "frame", "set", "project", "source (repository @ commit: path)", "licence", "camera",
        "site / UTC", "what makes it hard", "reference",
    )  # fmt: skip
    for f in doc["files"]:
        ref = f["reference"]
        site = "site ✓" if f.get("site") else "no site"
        utc = f"UTC {f['utc']}" if f.get("utc") else "no UTC"
        method = ref["method"].split(" (")[0]
        if ref.get("stars"):
            method += f": {len(ref['stars'])} stars"
            if ref.get("zenith_offset_deg") is not None:
                method += f", disc centre {ref['zenith_offset_deg']:.1f}° from the zenith"
            if ref["method"].startswith("astrometry.net") and not ref.get("confirmed_by"):
                method += " (one crop, log-odds < 40: unconfirmed)"
        licence = f["licence"] + ("" if f["redistributable"] else " (not redistributable)")
        rows.append(table_row(
            f"`{f['name']}`", f["set"], f["project"],
            f"{f['repository']} @ {f['commit'][:8]}: `{f['path']}`", licence,
            f["camera"], f"{site}, {utc}", f["notes"].replace("|", "/"), method,
        ))  # fmt: skip
    from benchmarks.images.real_allsky import SETS

    projects = sorted({f["project"] for f in doc["files"]})
    counts = {name: sum(f["set"] == name for f in doc["files"]) for name in SETS[1:]}
    held = [
        f"{name} ({n} frames): "
        + ", ".join(sorted({f["project"] for f in doc["files"] if f["set"] == name}))
        for name, n in counts.items()
        if n
    ]
    head = (
        f"{len(doc['files'])} frames from {len(projects)} cameras/projects; held back (whole "
        f"projects, not tuned on), {'; '.join(held)}. Rejected when gathered: "
        f"{len(doc.get('rejected', []))} files (listed in the manifest with the reason)."
    )
    replace_block(DOCS / "allsky.md", "allsky-sources", head + "\n\n" + "\n".join(rows))
    print(head)


def main(argv: list[str] | None = None) -> None:
    sys.path.insert(0, str(ROOT))
    from benchmarks.images.real_allsky import SETS

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("table", help="the frames table into docs/allsky.md")
    for name in ("solve", "build"):
        p = sub.add_parser(name)
        p.add_argument("--files", default="/work/allsky/files", help="folder of the frames")
        p.add_argument(
            "--astrometry", default="/work/allsky/astrometry", help="solve-field outputs"
        )
        p.add_argument("--manifest", default="/work/allsky/manifest.json", help="metadata source")
        p.add_argument("--only", nargs="*", help="these file names only")
        p.add_argument("--set", choices=SETS, help="this set only")
        if name == "solve":
            p.add_argument("--again", action="store_true", help="solve files already tried")
            p.add_argument("--at", nargs="+", type=float, metavar="X Y",
                           help="with --only NAME: add crops centred on these pixels")  # fmt: skip
    args = parser.parse_args(argv)
    {"solve": cmd_solve, "build": cmd_build, "table": cmd_table}[args.command](args)


if __name__ == "__main__":
    main()
