"""Real all-sky and meteor-camera frames solved as a user would, scored against their
independent references, into docs/allsky.md (blocks ``allsky-frames``, ``allsky-totals``).

    python benchmarks/images/real_allsky.py [--files DIR]
        [--set development|heldback|heldback_2|heldback_3|all] [--only NAME ...] [--modes a b c]
        [--write-docs] [--json OUT]

The frames: tests/data/real/allsky_manifest.json (metadata and references, no image bytes);
the files are other projects' (the manifest gives repository, commit, path and SHA-256), looked
for in ``--files``, default ``$STARNAV_ALLSKY_CORPUS``; a missing file or one whose SHA-256
differs is reported and skipped. ``--set development`` (the default) runs the frames that may be
tuned on; ``heldback``, ``heldback_2`` and ``heldback_3`` the frames of the projects kept out of
development (each run once, at the end); ``all`` every set.

Each frame is solved through the command line (``python -m starnav solve FILE ... --json``, a
subprocess per solve, as a user runs it) three ways:

* (a) nothing but the file;
* (b) ``--lens MODEL`` only: the manifest's lens, or when it is unknown equidistant then
  equisolid, the first that solves reported;
* (c) the lens and the best description the manifest gives: the sky disc's field and the focal
  length / pixel size, the site and the UTC, each through the option ``starnav solve --help``
  offers for it (``DESCRIPTION_OPTIONS``); a disc field the command line cannot take directly
  is given as ``--fov-deg``, the horizontal field across the image width that the lens model
  and the disc's radius imply (the disc as a user would measure it on the frame:
  ``starnav.detect.circle.find_image_circle``).

Scoring (``score``): an answer is WRONG when any identified star's solved pixel lies more than
0.5° (``WRONG_DEG``) from where the reference puts that catalog star (when the reference
matched the same star: the pixel distance between the two times the reference's pixel scale;
else the angle between the star's catalog position and the sky direction of its pixel through
the reference WCS of a crop holding it in its inner half, where the crop's TAN-SIP is good to
~0.1°), or when the boresight is more than 0.5° from the reference's direction at the solved
principal point. A solved answer with nothing in reach of
the reference is counted as "unchecked", never as correct. A reference transferred from
another frame of the same camera (make_allsky_reference.py: a fisheye fitted to that frame's
stars, the bright stars put through it at this frame's UTC) is only as good as that fit: its
``uncertainty_deg`` (twice the fit's rms) is added to the 0.5°. The KHO hand identifications
(tests/data/allsky/kho_20201211_star_ids.csv) are checked as before on that frame. Times:
the subprocess's wall time (Python start and import included) and starnav's own read + detect
+ solve time from its JSON.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import re
import subprocess
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, machine, replace_block, table_head, table_row

MANIFEST = ROOT / "tests" / "data" / "real" / "allsky_manifest.json"
KHO_IDS = ROOT / "tests" / "data" / "allsky" / "kho_20201211_star_ids.csv"
KHO_FRAME = "kho_lyr-sony-111220_200933.jpg"
DOC = DOCS / "allsky.md"
ENV = "STARNAV_ALLSKY_CORPUS"
# the manifest's sets: frames that may be tuned on, then whole projects held back and run once
# at the end ("heldback", run; "heldback_2" and "heldback_3", gathered later and not yet run)
SETS = ("development", "heldback", "heldback_2", "heldback_3")
WRONG_DEG = 0.5
CROP_EDGE = 0.25  # a crop's WCS is used this far (fraction of its side) inside its edges
SAME_STAR_DEG = 0.05  # a reference star and a solved star are the same catalog star
MATCH_PX = 5.0  # the hand-identification check's radius
TIMEOUT_S = 600
UNKNOWN_LENSES = ("equidistant", "equisolid")
# manifest field -> the options `starnav solve` may offer for it, first found in --help used
DESCRIPTION_OPTIONS = {
    "circle_fov_deg": ("--circle-fov-deg", "--circle-fov", "--disc-fov-deg"),
    "focal_mm": ("--focal-mm", "--focal-length-mm", "--focal-length"),
    "pixel_um": ("--pixel-um", "--pixel-size-um", "--pixel-size"),
    "site": ("--site", "--location"),
    "lat": ("--lat", "--latitude"),
    "lon": ("--lon", "--longitude"),
    "height_m": ("--height-m", "--height"),
    "utc": ("--utc", "--time", "--date-obs"),
}


def frames(manifest: dict, which: str, only: list[str] | None) -> list[dict]:
    out = []
    for entry in manifest["files"]:
        if only and entry["name"] not in only:
            continue
        if which != "all" and entry["set"] != which:
            continue
        out.append(entry)
    return out


def file_state(entry: dict, folder: Path) -> str | None:
    """None when the file is there with the manifest's SHA-256, else what is wrong."""
    path = folder / entry["name"]
    if not path.exists():
        return f"missing from {folder}"
    if hashlib.sha256(path.read_bytes()).hexdigest() != entry["sha256"]:
        return "SHA-256 differs from the manifest"
    return None


def cli_options() -> str:
    """`starnav solve --help` of the checkout measured (which description options it has)."""
    out = subprocess.run(
        [sys.executable, "-m", "starnav", "solve", "--help"], capture_output=True, text=True
    )
    return out.stdout


def run_cli(path: Path, args: list[str]) -> dict:
    """One `starnav solve PATH ARGS --json` in a subprocess: its answer (or error) and times."""
    cmd = [sys.executable, "-m", "starnav", "solve", str(path), *args, "--json"]
    started = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return {"args": args, "wall_s": TIMEOUT_S, "error": f"no answer in {TIMEOUT_S} s"}
    wall = time.perf_counter() - started
    out = {"args": args, "wall_s": round(wall, 2), "exit": proc.returncode}
    try:
        answer = json.loads(proc.stdout.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        err = [line for line in proc.stderr.strip().splitlines() if line.strip()]
        out["error"] = err[-1] if err else f"exit {proc.returncode}, no JSON"
        return out
    out["answer"] = answer
    out["starnav_s"] = round(
        sum((answer.get(k) or 0.0) for k in ("read_ms", "detect_ms", "solve_ms")) / 1e3, 2
    )
    return out


def lenses(entry: dict) -> tuple[str, ...]:
    lens = entry.get("lens") or "unknown"
    return UNKNOWN_LENSES if lens == "unknown" else (lens,)


def description(entry: dict, lens: str, help_text: str) -> list[str]:
    """The best description of the camera the manifest gives, as `starnav solve` options."""
    args: list[str] = []

    offered = set(re.findall(r"(?<![\w-])(--[a-z0-9][a-z0-9-]*)", help_text))

    def option(field: str) -> str | None:
        return next((o for o in DESCRIPTION_OPTIONS[field] if o in offered), None)

    circle_fov = entry.get("circle_fov_deg")
    if circle_fov and option("circle_fov_deg"):
        args += [option("circle_fov_deg"), f"{circle_fov:g}"]
    elif entry.get("focal_mm") and entry.get("pixel_um") and option("focal_mm"):
        args += [option("focal_mm"), f"{entry['focal_mm']:g}"]
        if option("pixel_um"):
            args += [option("pixel_um"), f"{entry['pixel_um']:g}"]
    elif circle_fov:
        width_fov = width_fov_deg(entry, lens, circle_fov)
        if width_fov is not None:
            args += ["--fov-deg", f"{width_fov:.1f}"]
    site = entry.get("site")
    if site and option("site"):
        args += [option("site"), f"{site['lat_deg']},{site['lon_deg']},{site.get('height_m') or 0}"]
    elif site and option("lat"):  # starnav solve's own: --lat --lon [--height-m]
        args += [option("lat"), f"{site['lat_deg']:g}", option("lon"), f"{site['lon_deg']:g}"]
        if site.get("height_m") and option("height_m"):
            args += [option("height_m"), f"{site['height_m']:g}"]
    if entry.get("utc") and option("utc"):
        args += [option("utc"), entry["utc"]]
    return args


def width_fov_deg(entry: dict, lens: str, circle_fov_deg: float) -> float | None:
    """The horizontal field across the image width of a fisheye whose disc of radius R (the
    reference's, measured on the frame) spans ``circle_fov_deg``: r(theta) of the lens model
    through the disc edge, evaluated at half the width (the field beyond the lens's largest
    angle: 360°, the widest the command line takes)."""
    circle = _CIRCLES.get(entry["name"])
    if circle is None:
        return None
    radius, half_width = circle.radius_px, entry_width(entry) / 2
    edge = math.radians(circle_fov_deg / 2)
    forward = {
        "equidistant": (lambda t: t, lambda r: r),
        "equisolid": (lambda t: 2 * math.sin(t / 2), lambda r: 2 * math.asin(min(1.0, r / 2))),
        "stereographic": (lambda t: 2 * math.tan(t / 2), lambda r: 2 * math.atan(r / 2)),
        "orthographic": (lambda t: math.sin(t), lambda r: math.asin(min(1.0, r))),
    }
    if lens not in forward:
        return None
    r_of, theta_of = forward[lens]
    focal = radius / r_of(edge)
    return min(360.0, 2 * math.degrees(theta_of(half_width / focal)))


def entry_width(entry: dict) -> int:
    """The frame's width in pixels as starnav reads it (``run_frame`` reads it first)."""
    return _SHAPES[entry["name"]][1]


_SHAPES: dict[str, tuple[int, int]] = {}
_CIRCLES: dict[str, object] = {}  # the sky disc a user would measure (find_image_circle)


# ----------------------------------------------------------------------------------------------
# scoring


def _wcs(cards: dict):
    from astropy.io import fits
    from astropy.wcs import WCS, FITSFixedWarning

    header = fits.Header()
    for key, value in cards.items():
        header[key] = value
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FITSFixedWarning)
        return WCS(header)


def _unit(ra_deg, dec_deg) -> np.ndarray:
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


class Reference:
    """A frame's reference: its solved crops' WCS and its star list."""

    def __init__(self, ref: dict):
        self.crops = [(c, _wcs(c["wcs"])) for c in ref.get("crops") or [] if "wcs" in c]
        stars = ref.get("stars") or []
        self.xy = np.array([[s[0], s[1]] for s in stars], float).reshape(-1, 2)
        self.sky = _unit([s[2] for s in stars], [s[3] for s in stars]).reshape(-1, 3)
        self.scale_deg_px = ref.get("scale_deg_per_px")  # a transferred reference's, else:
        self.uncertainty_deg = ref.get("uncertainty_deg", 0.0)  # added to WRONG_DEG
        if self.crops:
            from astropy.wcs.utils import proj_plane_pixel_scales

            self.scale_deg_px = float(np.mean(proj_plane_pixel_scales(self.crops[0][1])))

    @property
    def usable(self) -> bool:
        return bool(self.crops) or len(self.xy) > 0

    def sky_at(self, x: float, y: float) -> np.ndarray | None:
        """Unit vector of our pixel (x, y) through the WCS of the solved crop that holds it
        farthest from its edges, not within ``CROP_EDGE`` of them: a crop's TAN-SIP fit of a
        fisheye is extrapolated towards its edges (1.6° off at the edge of one MAGIC crop that
        the next crop, matched there, puts right; 0.7° at 11 % from the edge of the KHO
        frame's centre crop, 0.3° at 21 %). None outside every crop's inner half."""
        best = self.holding(x, y)
        if best is None:
            return None
        ra, dec = best[1].all_pix2world(best[2], best[3], 1)
        return _unit(float(ra), float(dec))

    def holding(self, x: float, y: float):
        """(crop, its WCS, crop FITS x, y) of the crop ``sky_at`` reads pixel (x, y) through,
        or None."""
        best, margin = None, 0.0
        for crop, wcs in self.crops:
            stretch = crop.get("stretch", 1.0)  # rows resampled for non-square pixels
            fx, fy = x - crop["x0"] + 0.5, y * stretch - crop["y0"] + 0.5  # crop FITS pixel
            inside = min(fx, crop["width"] - fx, fy, crop["height"] - fy)
            inside /= min(crop["width"], crop["height"])
            if inside > max(margin, CROP_EDGE):
                best, margin = (crop, wcs, fx, fy), inside
        return best


def score(answer: dict, ref: Reference, catalog) -> dict:
    """Verdict of one solved answer: 'ok', 'WRONG' (why) or 'unchecked'; counts."""
    index = {int(k): i for i, k in enumerate(catalog.ids)}
    checked = wrong = 0
    worst = 0.0
    whys = []
    for star in answer.get("stars") or []:
        if star.get("catalog_id") is None or int(star["catalog_id"]) not in index:
            continue
        k = index[int(star["catalog_id"])]
        cat = _unit(catalog.ra_deg[k], catalog.dec_deg[k])
        same = _angle_deg(ref.sky, cat) < SAME_STAR_DEG if len(ref.xy) else np.zeros(0, bool)
        sky = ref.sky_at(star["x"], star["y"])
        if same.any() and ref.scale_deg_px:  # the reference matched this star: where?
            j = int(np.nonzero(same)[0][0])
            off = float(np.hypot(*(ref.xy[j] - [star["x"], star["y"]]))) * ref.scale_deg_px
        elif sky is not None:  # else the sky direction of its pixel, inside a crop
            off = float(_angle_deg(sky, cat))
        else:
            continue
        checked += 1
        worst = max(worst, off)
        if off > WRONG_DEG + ref.uncertainty_deg:
            wrong += 1
            whys.append(f"HIP {star['catalog_id']} {off:.1f}° off")
    boresight = None
    if answer.get("cx") is not None and answer.get("ra_deg") is not None:
        sky = ref.sky_at(answer["cx"], answer["cy"])
        if sky is not None:
            boresight = float(_angle_deg(sky, _unit(answer["ra_deg"], answer["dec_deg"])))
            if boresight > WRONG_DEG + ref.uncertainty_deg:
                whys.append(f"boresight {boresight:.1f}° off")
    verdict = "WRONG" if whys else ("ok" if checked or boresight is not None else "unchecked")
    return {
        "verdict": verdict,
        "why": "; ".join(whys[:3]),
        "stars_checked": checked,
        "stars_wrong": wrong,
        "worst_star_deg": round(worst, 3),
        "boresight_deg": None if boresight is None else round(boresight, 3),
    }


def score_try(got: dict, name: str, ref: Reference, catalog) -> None:
    """Adds ``score`` (and on the KHO frame ``kho_hand_ids``) to a solved CLI run."""
    answer = got.get("answer")
    if not (answer and answer.get("solved")):
        return
    unchecked = {"verdict": "unchecked", "why": "no reference"}
    got["score"] = score(answer, ref, catalog) if ref.usable else unchecked
    if name == KHO_FRAME:
        agree, wrong, listed = got["kho_hand_ids"] = kho_hand_ids(answer)
        got["score"]["why"] = "; ".join(
            w
            for w in (got["score"].get("why"), f"hand ids {agree} agree, {wrong} wrong of {listed}")
            if w
        )
        if wrong:
            got["score"]["verdict"] = "WRONG"


def kho_hand_ids(answer: dict) -> tuple[int, int, int]:
    """(agreeing, wrong, listed) hand-identified KHO stars: the solved star within MATCH_PX
    of each listed position (0-based px in the table, ours add 0.5) and its Hipparcos number."""
    from starnav.catalog.names import star_names

    hip_of = {name: hip for hip, name in star_names().items()}
    solved = [(s["x"], s["y"], s["catalog_id"]) for s in answer["stars"] if s["catalog_id"]]
    xy = np.array([(x, y) for x, y, _ in solved]).reshape(-1, 2)
    agree = wrong = listed = 0
    with KHO_IDS.open() as fh:
        for row in csv.DictReader(fh):
            listed += 1
            if not len(xy):
                continue
            d = np.hypot(*(xy - [float(row["sony_x0"]) + 0.5, float(row["sony_y0"]) + 0.5]).T)
            if d.min() > MATCH_PX:
                continue
            same = solved[int(np.argmin(d))][2] == hip_of[row["name"]]
            agree, wrong = agree + same, wrong + (not same)
    return agree, wrong, listed


# ----------------------------------------------------------------------------------------------
# running


def run_frame(entry: dict, folder: Path, modes: list[str], help_text: str, catalog) -> dict:
    from starnav.detect.read import read_image

    path = folder / entry["name"]
    from starnav.detect.circle import find_image_circle

    try:
        pixels = read_image(path)
        _SHAPES[entry["name"]] = pixels.shape
        _CIRCLES[entry["name"]] = find_image_circle(pixels)
    except Exception as exc:
        _SHAPES[entry["name"]] = (0, 0)
        print(f"  {entry['name']}: starnav cannot read it: {exc}", file=sys.stderr)
    ref = Reference(entry.get("reference") or {})
    result = {
        "name": entry["name"],
        "project": entry["project"],
        "set": entry["set"],
        "reference": (entry.get("reference") or {}).get("method", "none"),
        "modes": {},
    }
    plans = {
        "a": [[]],
        "b": [["--lens", lens] for lens in lenses(entry)],
        "c": [["--lens", lens, *description(entry, lens, help_text)] for lens in lenses(entry)],
    }
    for mode in modes:
        tries = []
        for args in plans[mode]:
            got = run_cli(path, args)
            answer = got.get("answer")
            score_try(got, entry["name"], ref, catalog)
            tries.append(got)
            print(
                f"  {entry['name']} ({mode}) {' '.join(args) or '(file only)'}: {outcome(got)}",
                file=sys.stderr,
                flush=True,
            )
            if answer and answer.get("solved"):
                break
        result["modes"][mode] = tries
    return result


def outcome(got: dict) -> str:
    """'solved' / 'WRONG' / 'unchecked' / 'not solved: reason' of one CLI run."""
    answer = got.get("answer")
    if answer is None:
        return f"not solved: {got.get('error', 'no answer')}"
    if not answer.get("solved"):
        return f"not solved: {answer.get('reason') or answer.get('failure')}"
    verdict = got["score"]["verdict"]
    if verdict == "ok":
        return "solved" + (f" ({got['score']['why']})" if got["score"].get("why") else "")
    return f"{verdict}: {got['score'].get('why', '')}".rstrip(": ")


def mode_summary(tries: list[dict]) -> tuple[str, str, str]:
    """(verdict word, text, seconds) of a mode: the last try (the first solved, else the last)."""
    last = tries[-1]
    text = outcome(last)
    word = text.split(":")[0].split(" (")[0]
    seconds = sum(t.get("wall_s", 0) for t in tries)
    args = " ".join(last["args"]) or "(file only)"
    return word, f"{text} — `{args}`", f"{seconds:.1f}"


def tables(results: list[dict], modes: list[str]) -> tuple[str, str]:
    rows = table_head(
        "frame", "set", "reference", *[f"({m})" for m in modes], "time (s) " + " / ".join(modes)
    )
    for r in results:
        cells = [mode_summary(r["modes"][m]) for m in modes]
        rows.append(
            table_row(
                f"`{r['name']}`",
                r["set"],
                r["reference"].split(" (")[0],
                *[c[1].replace("|", "/")[:160] for c in cells],
                " / ".join(c[2] for c in cells),
            )
        )
    totals = defaultdict(lambda: defaultdict(lambda: defaultdict(int)))
    for r in results:
        for m in modes:
            word = mode_summary(r["modes"][m])[0]
            for key in (f"project: {r['project']}", f"set: {r['set']}", "all"):
                totals[key][m][word] += 1
                totals[key][m]["frames"] += 1
    head = table_head("group", *[f"({m}) solved / WRONG / unchecked / not solved" for m in modes])
    lines = list(head)
    for key in sorted(totals, key=lambda k: (k == "all", not k.startswith("set"), k)):
        cells = []
        for m in modes:
            t = totals[key][m]
            counts = " / ".join(str(t[w]) for w in ("solved", "WRONG", "unchecked", "not solved"))
            cells.append(f"{counts} of {t['frames']}")
        lines.append(table_row(key, *cells))
    return "\n".join(rows), "\n".join(lines)


def write_docs(which: str, totals_md: str, frames_md: str) -> None:
    """The tables into docs/allsky.md (blocks allsky-totals / allsky-frames, "-heldback" /
    "-heldback_2" / "-heldback_3" / "-all" for the other choices of ``--set``)."""
    suffix = "" if which == "development" else f"-{which}"
    replace_block(DOC, f"allsky-totals{suffix}", totals_md, missing=f"### Totals ({which})")
    replace_block(DOC, f"allsky-frames{suffix}", frames_md, missing=f"### Per frame ({which})")


def rescore(path: Path, args) -> None:
    """The tables of an earlier run's answers (``--json``), scored against the manifest's
    references as they are now."""
    from starnav.catalog import load_catalog

    catalog = load_catalog()
    entries = {e["name"]: e for e in json.loads(MANIFEST.read_text())["files"]}
    results = json.loads(path.read_text())["results"]
    for r in results:
        ref = Reference(entries[r["name"]].get("reference") or {})
        r["reference"] = (entries[r["name"]].get("reference") or {}).get("method", "none")
        for tries in r["modes"].values():
            for got in tries:
                score_try(got, r["name"], ref, catalog)
    modes = [m for m in ("a", "b", "c") if all(m in r["modes"] for r in results)]
    frames_md, totals_md = tables(results, modes)
    measured = json.loads(path.read_text())["machine"]
    head = f"Rescored {path.name} ({len(results)} frames); measured on: {measured}."
    print(head + "\n\n" + totals_md + "\n\n" + frames_md)
    if args.write_docs:
        write_docs(args.set, head + "\n\n" + totals_md, frames_md)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--files", default=os.environ.get(ENV), help=f"folder of the frames (default ${ENV})"
    )
    parser.add_argument("--set", default="development", choices=(*SETS, "all"))
    parser.add_argument("--only", nargs="*", help="these file names only")
    parser.add_argument("--modes", nargs="*", default=["a", "b", "c"], choices=("a", "b", "c"))
    parser.add_argument(
        "--write-docs", action="store_true", help="write the tables into docs/allsky.md"
    )
    parser.add_argument("--json", help="write every run's answer and score here")
    parser.add_argument(
        "--rescore", metavar="JSON", help="score the answers of an earlier --json run again"
    )
    args = parser.parse_args(argv)
    if args.rescore:
        return rescore(Path(args.rescore), args)
    if not args.files or not Path(args.files).is_dir():
        raise SystemExit(f"no frames folder: give --files DIR or set {ENV}")
    from starnav.catalog import load_catalog

    catalog = load_catalog()
    manifest = json.loads(MANIFEST.read_text())
    help_text = cli_options()
    folder = Path(args.files)
    results, skipped = [], []
    for entry in frames(manifest, args.set, args.only):
        problem = file_state(entry, folder)
        if problem:
            skipped.append(f"`{entry['name']}`: {problem}")
            continue
        results.append(run_frame(entry, folder, args.modes, help_text, catalog))
        if args.json:  # as it goes: a long run's frames so far
            Path(args.json).write_text(json.dumps({"machine": machine(), "results": results}))
    frames_md, totals_md = tables(results, args.modes)
    head = f"Machine: {machine(load_at_end=True)}. Set: {args.set}; {len(results)} frames run."
    if skipped:
        head += " Skipped: " + "; ".join(skipped) + "."
    print(head + "\n\n" + totals_md + "\n\n" + frames_md)
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine(), "results": results}, indent=1))
    if args.write_docs:
        write_docs(args.set, head + "\n\n" + totals_md, frames_md)


if __name__ == "__main__":
    main()
