"""Solve every real all-sky image of ../shared/data/allsky and compare it with its independent
reference.

References: the KHO Sony frame has 19 stars identified by hand (tests/data/allsky/
kho_20201211_star_ids.csv); a listed star agrees when the solved star within 5 px of its
position carries the same Hipparcos number (names from starnav.catalog.names), and is wrong
when it carries another. The zenith at the site and UTC (astropy, AltAz -> ICRS) is a
consistency check of the boresight, not an exact reference: the camera is tilted by a degree
or two, and the boresight is the direction at the assumed principal point (the image centre).

Run: python benchmarks/images/real_allsky.py   (prints a markdown table; docs/wide_field.md
holds it)
"""

from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
import starnav
from benchmarks.harness import ROOT, SHARED, table_head
from starnav.catalog.names import star_names
from starnav.geometry import angle_between, radec_to_unit

DATA = ROOT / "tests" / "data" / "allsky"  # our identifications of its stars
PHOTOS = SHARED / "allsky"  # the photographs (their licences beside them)
MATCH_PX = 5.0

# file, solve options (as the CLI takes them), star-id table, its x and y columns, site, UTC
IMAGES = [
    (
        "kho_sony_a7s_20201211_200933.jpg",
        {"lens": "equisolid", "fov_deg": 180.0, "max_stars": 100},
        "kho_20201211_star_ids.csv",
        ("sony_x0", "sony_y0"),
        (78.148, 16.043, 520.0),
        "2020-12-11T20:09:33",
    ),
]


def zenith_radec_deg(lat_deg: float, lon_deg: float, height_m: float, utc: str) -> tuple:
    """ICRS RA/Dec (deg) of the zenith at the site and time (astropy)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    site = EarthLocation(lat=lat_deg * u.deg, lon=lon_deg * u.deg, height=height_m * u.m)
    up = SkyCoord(alt=90 * u.deg, az=0 * u.deg, frame=AltAz(obstime=Time(utc), location=site))
    icrs = up.icrs
    return float(icrs.ra.deg), float(icrs.dec.deg)


def id_agreement(solution, table: Path, columns: tuple[str, str]) -> tuple[int, int, int]:
    """(agreeing, wrong, listed) hand-identified stars: the solved star within MATCH_PX of each
    listed position (0-based px in the table, ours add 0.5) and its Hipparcos number."""
    hip_of = {name: hip for hip, name in star_names().items()}
    solved = [(m.x, m.y, m.catalog_id) for m in solution.stars if m.catalog_id is not None]
    xy = np.array([(x, y) for x, y, _ in solved])
    agree = wrong = listed = 0
    with table.open() as fh:
        for row in csv.DictReader(fh):
            listed += 1
            d = np.hypot(*(xy - [float(row[columns[0]]) + 0.5, float(row[columns[1]]) + 0.5]).T)
            if d.min() > MATCH_PX:
                continue
            same = solved[int(np.argmin(d))][2] == hip_of[row["name"]]
            agree, wrong = agree + same, wrong + (not same)
    return agree, wrong, listed


def main() -> None:
    head = table_head(
        "file",
        "options",
        "solved",
        "matched",
        "rms (px)",
        "boresight − zenith (°)",
        "hand ids agreeing / wrong / listed",
        "time (s)",
    )
    print("\n".join(head))
    for name, options, table, columns, site, utc in IMAGES:
        t0 = time.perf_counter()
        res = starnav.solve_image(PHOTOS / name, **options)
        seconds = time.perf_counter() - t0
        s = res.solution
        opts = " ".join(
            f"--{k.replace('_', '-')} {v:g}"
            if isinstance(v, float)
            else f"--{k.replace('_', '-')} {v}"
            for k, v in options.items()
        )
        if s is None:
            print(f"| {name} | `{opts}` | no: {res.reason} | | | | | {seconds:.1f} |")
            continue
        zra, zdec = zenith_radec_deg(*site, utc)
        boresight = radec_to_unit(np.radians(s.ra_deg), np.radians(s.dec_deg))
        off = np.degrees(angle_between(boresight, radec_to_unit(np.radians(zra), np.radians(zdec))))
        agree, wrong, listed = id_agreement(s, DATA / table, columns)
        print(
            f"| {name} | `{opts}` | yes | {s.n_matched} | {s.rms_px:.2f} | {off:.2f} "
            f"| {agree} / {wrong} / {listed} | {seconds:.1f} |"
        )


if __name__ == "__main__":
    main()
