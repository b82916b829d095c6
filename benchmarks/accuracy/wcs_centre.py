"""The WCS starnav writes against astrometry.net's on the real-image corpus: docs/wcs.md.

    nice python benchmarks/accuracy/wcs_centre.py [--rows rows.jsonl] [--from-rows rows.jsonl]
        [--out docs/wcs.md | -] [FILE ...]

Every photograph of ``tests/data/real/reference.json`` that astrometry.net solved (its answer
passing the catalog check) and whose WCS has its reference pixel at the image centre
(``solve-field --crpix-center``: CRVAL is then the sky at the centre, exactly, SIP or not) is
solved as ``starnav-solve-field IMG`` solves it (``starnav.pipeline.plate.solve_plate``, no
hint); the files are read from ``$STARNAV_REAL_CORPUS``, else ``../shared/data/real``.

For each image solved by both, the sky at the image centre (FITS pixel ((W+1)/2, (H+1)/2))
of three WCSs of the same solution is compared with astrometry.net's CRVAL:

* the attitude's own WCS (``starnav.pipeline.image.solution_wcs``: TAN of the fitted pinhole
  camera);
* the fit to the solve's matched stars (``fitted_wcs`` without detections: what starnav wrote
  until the deep fit);
* the WCS written now (``fitted_wcs`` with the image's detections: fitted again on every
  detection the embedded Gaia catalog explains, ``starnav.output.tweak``).

The sky check (``--an-wcs``, a folder of astrometry.net's full .wcs files, SIP included, from
``tests/data/real/make_reference.py solve`` with ``STARNAV_CORPUS_WORK`` pointing there): which
of the two WCSs is nearer the stars in the middle of the image, where their centres disagree.
The 1000 brightest detections (full resolution) are split in two; starnav's WCS is fitted on
one half, and both WCSs are checked on the other half against Gaia (``sky_check``).

Offsets in arcseconds (great-circle) and in pixels (divided by astrometry.net's pixel scale,
sqrt |det CD|), by the reference's horizontal field width. ``--rows`` keeps one JSON line per
image; ``--from-rows`` writes the table from such a file without solving.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import argparse
import json
import os
import time

import numpy as np

from benchmarks.harness import machine, replace_block, table_head, table_row

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "tests" / "data" / "real" / "reference.json"
SOURCES = REFERENCE.with_name("sources.json")
DOC = ROOT / "docs" / "wcs.md"
BANDS_DEG = ((0.0, 3.0), (3.0, 10.0), (10.0, 30.0), (30.0, 180.0))


def corpus_dir() -> Path:
    return Path(os.environ.get("STARNAV_REAL_CORPUS") or ROOT.parent / "shared" / "data" / "real")


def references(names: list[str]) -> dict[str, dict]:
    images = json.loads(REFERENCE.read_text())["images"]
    keep = {}
    for name, ref in images.items():
        an = ref.get("astrometry_net") or {}
        if names and name not in names:
            continue
        if ref.get("solved_by_reference") and an.get("crpix_at_centre"):
            keep[name] = ref
    return keep


def _separation_arcsec(ra1, dec1, ra2, dec2) -> float:
    from starnav.geometry import radec_to_unit

    a = radec_to_unit(np.radians(ra1), np.radians(dec1))
    b = radec_to_unit(np.radians(ra2), np.radians(dec2))
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)) * 3600.0)


CHECK_STARS = 1000  # detections (full resolution) and Gaia stars the sky check pairs
CHECK_RADIUS_PX = 3.0  # pairs within this, unambiguous (``output.tweak.unambiguous_pairs``)
CHECK_MIDDLE = 0.3  # the middle: within this share of the half-diagonal of the centre
CHECK_MIN_PAIRS = 5
CHECKS = ("check_ours_px", "check_an_px")  # the rows' sky checks: starnav's, astrometry.net's


def sky_check(wcs, xy: np.ndarray, vectors: np.ndarray, width: int, height: int):
    """The sky check of a WCS: the Gaia stars (``vectors``) it puts on the image paired with
    the detections ``xy`` (starnav px), and the mean of (catalog through the WCS - detection)
    over the pairs in the middle of the image, in px: how far the WCS's middle is from where
    the stars are (None with fewer than ``CHECK_MIN_PAIRS`` pairs there). starnav's WCS is
    checked on detections it was not fitted on (``measure``: fitted on every other one of the
    ``CHECK_STARS`` brightest, checked on the rest), astrometry.net's on the same."""
    from starnav.geometry import unit_to_radec
    from starnav.output.tweak import in_image, unambiguous_pairs

    ra, dec = np.degrees(unit_to_radec(vectors))
    px = wcs.all_world2pix(np.column_stack([ra, dec]), 0, quiet=True) + 0.5
    px = px[in_image(px, width, height)]
    det, cat = unambiguous_pairs(xy, px, CHECK_RADIUS_PX)
    middle = np.hypot(xy[det, 0] - width / 2, xy[det, 1] - height / 2)
    middle = middle <= CHECK_MIDDLE * np.hypot(width, height) / 2
    if middle.sum() < CHECK_MIN_PAIRS:
        return None
    return float(np.linalg.norm(np.mean(px[cat[middle]] - xy[det[middle]], axis=0)))


def check_stars(pixels: np.ndarray, wcs, width: int, height: int):
    """The brightest ``CHECK_STARS`` detections (full resolution) and Gaia stars about the
    field of ``wcs``."""
    from starnav.catalog import GAIA, load_catalog
    from starnav.detect.stars import detect_stars
    from starnav.geometry import radec_to_unit

    xy = detect_stars(pixels, max_stars=CHECK_STARS).xy
    corners = np.array([[0, 0], [width, 0], [0, height], [width, height], [width / 2, height / 2]])
    ra, dec = np.radians(wcs.all_pix2world(corners - 0.5, 0)).T
    v = radec_to_unit(ra, dec)
    radius = float(np.max(np.arccos(np.clip(v[:4] @ v[4], -1.0, 1.0))))
    near = load_catalog(GAIA).within(v[4], radius, "field")
    return xy, near.vectors[np.argsort(near.mag, kind="stable")[: 2 * CHECK_STARS]]


def measure(name: str, ref: dict, folder: Path, an_wcs: Path | None = None) -> dict:
    from starnav.pipeline.image import fitted_wcs, solution_wcs
    from starnav.pipeline.plate import PlateHints, solve_plate

    an = ref["astrometry_net"]["wcs"]
    cd = np.array([[an["CD1_1"], an["CD1_2"]], [an["CD2_1"], an["CD2_2"]]])
    scale_arcsec = float(np.sqrt(abs(np.linalg.det(cd))) * 3600.0)
    row = {"image": name, "fov_deg": ref["fov_deg"], "scale_arcsec": scale_arcsec}
    path = folder / name
    if not path.is_file():
        return {**row, "status": "absent"}
    t0 = time.perf_counter()
    res = solve_plate(path, PlateHints())
    row["seconds"] = time.perf_counter() - t0
    if res.plate is None:
        return {**row, "status": "not solved", "reason": res.reason}
    s = res.solution
    centre = [[(res.width + 1) / 2.0, (res.height + 1) / 2.0]]
    wcss = {"before": solution_wcs(s.R_cam_from_icrs, s.camera),
            "matched": fitted_wcs(s, res.catalog), "after": res.plate.wcs}  # fmt: skip
    for label, wcs in wcss.items():
        ra, dec = wcs.all_pix2world(centre, 1)[0]
        off = _separation_arcsec(ra, dec, an["CRVAL1"], an["CRVAL2"])
        row[f"{label}_arcsec"] = off
        row[f"{label}_px"] = off / scale_arcsec
    header = res.plate.wcs.to_header(relax=True)
    row.update(status="solved", n_matched=s.n_matched, rms_px=s.rms_px,
               sip_order=int(header.get("A_ORDER", 1)))  # fmt: skip
    full = None if an_wcs is None else an_wcs / f"{Path(name).stem}.wcs"
    if full is not None and full.is_file():
        import warnings

        from astropy.io import fits
        from astropy.wcs import WCS, FITSFixedWarning

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FITSFixedWarning)
            theirs = WCS(fits.getheader(full))
        xy, vectors = check_stars(res.pixels, res.plate.wcs, res.width, res.height)
        # held out: starnav's WCS fitted on every other detection, checked on the others
        fitted, checked = xy[0::2], xy[1::2]
        half = fitted_wcs(s, res.catalog, detections_xy=fitted)
        row["check_ours_px"] = sky_check(half, checked, vectors, res.width, res.height)
        row["check_an_px"] = sky_check(theirs, checked, vectors, res.width, res.height)
    return row


def _stats(values: list[float]) -> str:
    if not values:
        return "-"
    v = np.asarray(values)
    return f"{np.median(v):.3g} / {np.percentile(v, 90):.3g} / {v.max():.3g}"


def table(rows: list[dict]) -> str:
    solved = [r for r in rows if r["status"] == "solved"]
    lines = table_head(
        "field width",
        "images",
        "solved by both",
        "SIP order 1/2/3/4",
        "attitude's TAN: px (median / 90 % / max)",
        "fit to the matched stars: px",
        "written (deep fit): px",
        "written: arcsec",
        "written within 0.2 px",
    )
    for lo, hi in (*BANDS_DEG, (0.0, 180.0)):
        band = [r for r in rows if lo <= r["fov_deg"] < hi]
        got = [r for r in solved if lo <= r["fov_deg"] < hi]
        orders = "/".join(str(sum(r["sip_order"] == k for r in got)) for k in (1, 2, 3, 4))
        label = "all" if (lo, hi) == (0.0, 180.0) else f"{lo:g}-{hi:g}°"
        within = sum(r["after_px"] <= 0.2 for r in got)
        lines.append(
            table_row(
                label,
                len(band),
                len(got),
                orders,
                _stats([r["before_px"] for r in got]),
                _stats([r["matched_px"] for r in got if "matched_px" in r]),
                _stats([r["after_px"] for r in got]),
                _stats([r["after_arcsec"] for r in got]),
                f"{within} of {len(got)}",
            )
        )
    sets = json.loads(SOURCES.read_text())["files"]
    set_of = {f["name"]: f["set"] for f in sets}
    lines += ["", "By set of the corpus (held-back sets: not looked at while this was built):", ""]
    lines += table_head("set", "solved by both", "within 0.2 px: attitude's TAN / matched-star fit "
                        "/ written", "written: px (median / 90 % / max)", "sky check: starnav "
                        "nearer", "sky check: starnav / astrometry.net px (median)")  # fmt: skip
    for name in sorted({set_of.get(r["image"], "?") for r in solved}):
        got = [r for r in solved if set_of.get(r["image"], "?") == name]
        within = " / ".join(str(sum(r[f"{k}_px"] <= 0.2 for r in got if f"{k}_px" in r))
                            for k in ("before", "matched", "after"))  # fmt: skip
        seen = [r for r in got if r.get("check_ours_px") is not None
                and r.get("check_an_px") is not None]  # fmt: skip
        nearer = sum(r["check_ours_px"] <= r["check_an_px"] for r in seen)
        medians = "-"
        if seen:
            ours, theirs = (np.median([r[k] for r in seen]) for k in CHECKS)
            medians = f"{ours:.3f} / {theirs:.3f}"
        lines.append(table_row(name, len(got), within, _stats([r["after_px"] for r in got]),
                               f"{nearer} of {len(seen)}", medians))  # fmt: skip
    checked = [r for r in solved if r.get("check_ours_px") is not None
               and r.get("check_an_px") is not None]  # fmt: skip
    if checked:
        lines += ["", "Sky check (each WCS's middle against the Gaia stars there):", ""]
        lines += table_head("images checked", "starnav written: px (median / 90 % / max)",
                            "astrometry.net: px", "starnav nearer the stars")  # fmt: skip
        nearer = sum(r["check_ours_px"] <= r["check_an_px"] for r in checked)
        lines.append(table_row(len(checked), _stats([r["check_ours_px"] for r in checked]),
                               _stats([r["check_an_px"] for r in checked]),
                               f"{nearer} of {len(checked)}"))  # fmt: skip
    worst = sorted(solved, key=lambda r: -r["after_px"])[:8]
    lines += ["", "Largest offsets of the written WCS:", ""]
    lines += table_head("image", "width °", "matched", "solution rms px", "SIP order",
                        "attitude px", "written px", "sky check: starnav px",
                        "sky check: astrometry.net px")  # fmt: skip
    for r in worst:
        cells = (r["image"], f"{r['fov_deg']:.2f}", r["n_matched"], f"{r['rms_px']:.2f}",
                 r["sip_order"], f"{r['before_px']:.3f}", f"{r['after_px']:.3f}",
                 _maybe(r.get("check_ours_px")), _maybe(r.get("check_an_px")))  # fmt: skip
        lines.append(table_row(*cells))
    absent = sum(r["status"] == "absent" for r in rows)
    unsolved = sum(r["status"] == "not solved" for r in rows)
    lines += ["", f"{len(rows)} reference images: {len(solved)} solved by starnav, {unsolved} "
              f"not solved, {absent} files absent from the corpus folder."]  # fmt: skip
    return "\n".join(lines)


def _maybe(value) -> str:
    return "-" if value is None else f"{value:.3f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="*", help="image names of reference.json (default: all)")
    p.add_argument("--rows", help="write one JSON line per image here")
    p.add_argument("--from-rows", help="the table from these rows, nothing solved")
    p.add_argument("--out", default=str(DOC), help="markdown file (its block wcs-centre) or -")
    p.add_argument("--an-wcs", help="folder of astrometry.net's full .wcs files: the sky check")
    args = p.parse_args(argv)
    if args.from_rows:
        rows = [json.loads(line) for line in Path(args.from_rows).read_text().splitlines()]
        header = f"From {args.from_rows}."
    else:
        folder = corpus_dir()
        refs = references(args.files)
        rows = []
        sink = open(args.rows, "w") if args.rows else None
        for i, (name, ref) in enumerate(refs.items(), start=1):
            row = measure(name, ref, folder, Path(args.an_wcs) if args.an_wcs else None)
            rows.append(row)
            print(f"{i}/{len(refs)} {name}: {row['status']} "
                  f"{row.get('before_px', float('nan')):.3f} -> "
                  f"{row.get('after_px', float('nan')):.3f} px", file=sys.stderr)  # fmt: skip
            if sink:
                sink.write(json.dumps(row) + "\n")
                sink.flush()
        if sink:
            sink.close()
        header = f"Corpus folder {folder}; {machine()}."
    text = header + "\n\n" + table(rows)
    if args.out == "-":
        print(text)
    else:
        replace_block(args.out, "wcs-centre", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
