"""Telescope fields of 1-3.5°: real frames and renders solved with N.I.N.A.-style hints and
blind, into docs/narrow_fields.md (blocks ``narrow-real``, ``narrow-renders``, ``gaia-bands``).

    python benchmarks/accuracy/telescope_fields.py [--frames 20] [--fov 1 1.5 2 3]
        [--skip-real] [--skip-renders] [--skip-blind]

Hints, as N.I.N.A. sends them (``tests/data/real/make_narrow_reference.hints``): a position
off the true centre by 0-5° (uniform, random direction), searched within 5°, and a pixel
scale off by up to ±10 %, searched over the widths it allows (hinted width / 1.1 to / 0.9).
Blind: the same width range, no position. Each answer is scored against the reference
attitude (``benchmarks.harness.verdict``: wrong = boresight or roll 0.5° or more off, or the
other parity); times are the whole ``solve_image`` call (reading, detection, tables near the
hint, search, fit) on this machine, and the solve's own share.

Real frames: the development set is the corpus frames (tests/data/real/reference.json) of
0.95-4° that astrometry.net solves, the held-back set tests/data/real/narrow_heldback.json
(gathered for issue 36, measured once, never tuned on). The files are other projects':
looked for in ``$STARNAV_REAL_CORPUS``, ``$STARNAV_NARROW_FILES`` (default
/work/narrow/files) and ../shared/data/real; a missing file is counted as such.

Renders: a 3:2 camera (1200 x 800 px) at a boresight uniform on the sky and a random roll,
the stars of the embedded Gaia DR3 (G <= 10) around it and, as a telescope sees them, the
fainter stars no embedded catalog holds: G 10-13 at 14.8 times the local G <= 10 count
(whole-sky counts rise 0.42 dex from V 10 to 11 and 0.40 from 11 to 12 in Allen's
Astrophysical Quantities: 0.40 dex a magnitude taken to G 13), placed at random, rendered
with ``starnav.simulate.render`` (PSF sigma 1.2 px, 15 s: stars are detected to G ~12.5, as
a small telescope's short sub-exposure sees them, and the brightest saturate).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "data" / "real"))
from make_narrow_reference import hints as nina_hints

from benchmarks.harness import DOCS, machine, replace_block, score_solution, table_head, verdict
from starnav.camera import Camera
from starnav.catalog import Catalog, load_gaia
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll, radec_to_unit
from starnav.pipeline.fov import fov_limits_deg
from starnav.pipeline.image import solve_image
from starnav.simulate.render import RenderSettings, render_frame

REPO = Path(__file__).resolve().parents[2]
DOC = DOCS / "narrow_fields.md"
REAL = REPO / "tests" / "data" / "real"
HINT_RADIUS_DEG = 5.0
SCALE_ERROR = 0.10
DEV_FOV_DEG = (0.95, 4.0)
FAINTEST_MAG = 13.0
FAINT_SLOPE_DEX = 0.40  # log N(<m) rises this much a magnitude beyond G 10
FAINT_RATIO = 10 ** (FAINT_SLOPE_DEX * (FAINTEST_MAG - 10.0)) - 1.0  # G 10-13 per G <= 10
SETTINGS = dict(exposure_s=15.0, psf_sigma_px=1.2)  # stars detected to G ~12.5, G < 6 saturate
BANDS = ((0.3, 1.0), (1.0, 1.5), (1.5, 2.0), (2.0, 3.0), (3.0, 4.0))


def find_file(name: str) -> Path | None:
    for folder in (
        os.environ.get("STARNAV_REAL_CORPUS"),
        os.environ.get("STARNAV_NARROW_FILES", "/work/narrow/files"),
        str(REPO.parent / "shared" / "data" / "real"),
    ):
        if folder and (Path(folder) / name).is_file():
            return Path(folder) / name
    return None


def width_range(fov_hint_deg: float) -> tuple[float, float]:
    return fov_hint_deg / (1.0 + SCALE_ERROR), fov_hint_deg / (1.0 - SCALE_ERROR)


def solve_one(image, R_true: np.ndarray, fov_hint_deg: float, position, shape) -> dict:
    """One solve: its verdict, the whole call's and the solve's time (s), the reason. The
    width range is clipped to the narrowest field the image's ``shape`` (width, height px)
    allows (``fov_limits_deg``: 1° along its longer side)."""
    lo, hi = width_range(fov_hint_deg)
    floor = fov_limits_deg("pinhole", shape)[0]
    kw = (
        {}
        if position is None
        else {"position_hint_deg": position, "position_radius_deg": HINT_RADIUS_DEG}
    )
    t0 = time.perf_counter()
    try:
        res = solve_image(image, fov_range_deg=(max(lo, floor), max(hi, floor + 1e-6)), **kw)
    except StarnavError as exc:
        return {
            "verdict": "refused",
            "wall_s": time.perf_counter() - t0,
            "solve_s": 0.0,
            "reason": str(exc),
        }
    wall = time.perf_counter() - t0
    s = res.solution
    v = verdict(None if s is None else score_solution(s, R_true))
    return {
        "verdict": v,
        "wall_s": wall,
        "solve_s": res.solve_ms / 1e3,
        "reason": res.reason if s is None else "",
    }


def real_frames() -> list[dict]:
    """(set, name, fov, R_true, hints) of the development and held-back real frames."""
    out = []
    ref = json.loads((REAL / "reference.json").read_text())["images"]
    for name, r in sorted(ref.items()):
        fov = r.get("fov_deg")
        if r.get("solved_by_reference") and fov and DEV_FOV_DEG[0] <= fov < DEV_FOV_DEG[1]:
            out.append(
                {
                    "set": "development",
                    "name": name,
                    "fov_deg": fov,
                    "shape": (r["width"], r["height"]),
                    "R": np.array(r["R_cam_from_icrs"]),
                    "hints": nina_hints(name, r),
                }
            )
    held = json.loads((REAL / "narrow_heldback.json").read_text())
    for f in held["files"]:
        r = f.get("reference") or {}
        if f.get("in_set") and r.get("R_cam_from_icrs"):  # solved by astrometry.net, in band
            out.append(
                {
                    "set": "held back",
                    "name": f["name"],
                    "fov_deg": r["fov_deg"],
                    "shape": (r["width"], r["height"]),
                    "R": np.array(r["R_cam_from_icrs"]),
                    "hints": f.get("hints") or nina_hints(f["name"], r),
                }
            )
    return out


def band_of(fov: float) -> str:
    for lo, hi in BANDS:
        if lo <= fov < hi:
            return f"{lo:g}-{hi:g}°"
    return "other"


def summary_rows(rows: list[dict], key: str) -> list[str]:
    lines = table_head(
        "set",
        "field",
        "frames",
        "mode",
        "solved",
        "wrong",
        "not solved",
        "median call s",
        "max call s",
        "median solve s",
    )
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["set"], r[key], r["mode"]), []).append(r)
    for (set_, band, mode), rs in sorted(groups.items()):
        ok = [r for r in rs if r["verdict"] in ("correct", "inexact")]
        wrong = sum(r["verdict"] == "wrong" for r in rs)
        walls = [r["wall_s"] for r in rs]
        solves = [r["solve_s"] for r in rs]
        lines.append(
            f"| {set_} | {band} | {len(rs)} | {mode} | {len(ok)} ({len(ok) / len(rs):.0%}) "
            f"| {wrong} | {len(rs) - len(ok) - wrong} | {np.median(walls):.2f} | "
            f"{max(walls):.2f} | {np.median(solves):.2f} |"
        )
    return lines


def run_real(args) -> None:
    rows, missing = [], []
    frames = [f for f in real_frames() if args.set in ("all", f["set"])]
    modes = ("hinted",) if args.skip_blind else ("hinted", "blind")
    for mode in modes:
        for f in tqdm(frames, desc=f"real frames, {mode}", file=sys.stderr):
            path = find_file(f["name"])
            if path is None:
                if mode == "hinted":
                    missing.append(f["name"])
                continue
            h = f["hints"]
            position = (h["ra_deg"], h["dec_deg"]) if mode == "hinted" else None
            r = solve_one(path, f["R"], h["fov_deg"], position, f["shape"])
            rows.append(
                {
                    **r,
                    "set": f["set"],
                    "name": f["name"],
                    "mode": mode,
                    "band": band_of(f["fov_deg"]),
                }
            )
    lines = [f"Machine: {machine(load_at_end=True)}.", "", *summary_rows(rows, "band")]
    lines += ["", "Not solved (hinted), by frame:", ""]
    lines += [
        f"- {r['set']}: `{r['name']}` ({r['band']}): {r['verdict']}: {r['reason'][:160]}"
        for r in rows
        if r["mode"] == "hinted" and r["verdict"] not in ("correct", "inexact")
    ]
    if missing:
        lines += ["", f"Files not found here ({len(missing)}): {', '.join(missing)}"]
    text = "\n".join(lines)
    print(text)
    if args.rows:
        Path(args.rows).write_text(
            "".join(json.dumps({k: v for k, v in r.items()}) + "\n" for r in rows)
        )
    if args.out != "-":
        replace_block(args.out, "narrow-real", text)


def sky_near(gaia: Catalog, centre: np.ndarray, radius_rad: float, rng) -> Catalog:
    """The Gaia stars within ``radius_rad`` of ``centre`` and the fainter ones it lacks."""
    rows = np.flatnonzero(gaia.vectors @ centre >= math.cos(radius_rad))
    n_faint = rng.poisson(FAINT_RATIO * len(rows))
    # uniform on the cap: cos of the distance uniform in [cos r, 1]
    cos_d = rng.uniform(math.cos(radius_rad), 1.0, n_faint)
    az = rng.uniform(0.0, 2.0 * math.pi, n_faint)
    a = np.cross(centre, [0.0, 0.0, 1.0] if abs(centre[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(centre, a)
    sin_d = np.sqrt(1.0 - cos_d**2)
    v = cos_d[:, None] * centre + sin_d[:, None] * (
        np.cos(az)[:, None] * a + np.sin(az)[:, None] * b
    )
    # magnitudes 10-FAINTEST_MAG with log N rising FAINT_SLOPE_DEX a magnitude
    u = rng.uniform(0.0, 1.0, n_faint)
    k = FAINT_SLOPE_DEX * math.log(10.0)
    mag = 10.0 + np.log1p(u * (math.exp((FAINTEST_MAG - 10.0) * k) - 1.0)) / k
    ra = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0
    dec = np.degrees(np.arcsin(np.clip(v[:, 2], -1.0, 1.0)))
    return Catalog(
        np.concatenate([gaia.ids[rows], -10_000_000 - np.arange(n_faint)]),
        np.concatenate([gaia.ra_deg[rows], ra]),
        np.concatenate([gaia.dec_deg[rows], dec]),
        np.concatenate([gaia.mag[rows], mag]),
        "rendered sky",
    )


def run_renders(args) -> None:
    gaia = load_gaia()
    rows = []
    for fov in args.fov:
        camera = Camera.from_fov(fov, 1200, 800)
        rng = np.random.default_rng([args.seed, int(fov * 100)])
        for k in tqdm(range(args.frames), desc=f"renders {fov:g}°", file=sys.stderr):
            v = rng.normal(size=3)
            v /= np.linalg.norm(v)
            ra, dec = math.degrees(math.atan2(v[1], v[0])) % 360.0, math.degrees(math.asin(v[2]))
            R = attitude_from_radec_roll(ra, dec, rng.uniform(0.0, 360.0))
            sky = sky_near(
                gaia,
                radec_to_unit(math.radians(ra), math.radians(dec)),
                math.radians(camera.diagonal_deg),
                rng,
            )
            frame = render_frame(sky, camera, R, RenderSettings(**SETTINGS, seed=k))
            h = nina_hints(
                f"render-{fov:g}-{k}",
                {"ra_deg": ra, "dec_deg": dec, "fov_deg": fov, "scale_arcsec_per_px": fov * 3.0},
            )
            for mode in ("hinted",) if args.skip_blind else ("hinted", "blind"):
                position = (h["ra_deg"], h["dec_deg"]) if mode == "hinted" else None
                r = solve_one(frame.image, R, h["fov_deg"], position, frame.image.shape[::-1])
                rows.append(
                    {
                        **r,
                        "set": "renders",
                        "name": f"{fov:g}-{k}",
                        "mode": mode,
                        "band": f"{fov:g}°",
                    }
                )
    text = "\n".join([f"Machine: {machine(load_at_end=True)}.", "", *summary_rows(rows, "band")])
    print(text)
    if args.out != "-":
        replace_block(args.out, "narrow-renders", text)


def run_tables(args) -> None:
    """The Gaia bands' catalogs and whole-sky tables: stars, patterns, MB, build seconds."""
    from starnav.pipeline.fov import (
        GAIA_BELOW_DEG,
        band_grid,
        band_source,
        load_band,
        search_catalog,
    )

    lines = [f"Machine: {machine()}.", ""]
    lines += table_head(
        "table diagonal",
        "catalog",
        "stars",
        "stars a field",
        "patterns",
        "MB",
        "build s (first use)",
    )
    full = search_catalog(None, None)
    for lo, hi, top in tqdm(band_grid(1.0, GAIA_BELOW_DEG), desc="Gaia tables", file=sys.stderr):
        band = load_band(top, lo, hi, band_source(top, None, full))
        t = band.table
        lines.append(
            f"| {top:.3g}° | {band.catalog.name} | {len(band.catalog)} | "
            f"{t.fields.shape[1]} | {len(t)} | {t.nbytes / 1e6:.0f} | {t.build_s:.0f} |"
        )
    text = "\n".join(lines)
    print(text)
    if args.out != "-":
        replace_block(args.out, "gaia-bands", text)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=20, help="renders per field width")
    p.add_argument("--fov", nargs="+", type=float, default=(1.0, 1.5, 2.0, 3.0))
    p.add_argument("--seed", type=int, default=36)
    p.add_argument("--skip-real", action="store_true")
    p.add_argument("--skip-renders", action="store_true")
    p.add_argument("--skip-tables", action="store_true")
    p.add_argument("--skip-blind", action="store_true")
    p.add_argument(
        "--set",
        choices=("all", "development", "held back"),
        default="all",
        help="the real frames solved (default all)",
    )
    p.add_argument("--rows", help="write the real frames' rows (JSON lines) here")
    p.add_argument("--out", default=str(DOC), help="markdown file ('-': print only)")
    args = p.parse_args()
    if not args.skip_real:
        run_real(args)
    if not args.skip_renders:
        run_renders(args)
    if not args.skip_tables:
        run_tables(args)


if __name__ == "__main__":
    main()
