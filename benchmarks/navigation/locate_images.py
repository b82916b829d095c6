"""The celestial fix from rendered images into docs/locate.md.

    python benchmarks/navigation/locate_images.py --cases 10

Each case: the locate simulator's platform (``starnav.navigation.simulate``) at 47.37° N,
8.54° E on 2025-06-01 22:00 UTC, pitched 1°, with a heading of its own, three 20° cameras 120°
apart at 45° elevation; every camera's image rendered with the stars where the simulation put
them (``render_views``: pixel-integrated Gaussian PSF of 1 px sigma, sky, photon and read
noise, 16 bit), written as PNG and read back by ``starnav locate`` from an observation file
(``fov_deg`` 20, no refraction: the simulation has none). The same as
tests/navigation/test_locate_images.py's accuracy test, over more headings and noise draws, at
1024 px (the reference set-up) and 512 px.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from starnav.navigation import locate, read_observation
from starnav.navigation.frames import radii_of_curvature_m
from starnav.navigation.simulate import render_views, simulate_observation
from starnav.simulate.render import RenderSettings, write_image

DOC = DOCS / "locate.md"
SITE = {"lat_deg": 47.37, "lon_deg": 8.54}
UTC = "2025-06-01T22:00:00Z"


def one_case(folder: Path, width: int, heading_deg: float, seed: int) -> tuple[float, float, int]:
    """Position error (m), heading error (arcsec) and stars used of one rendered case."""
    sky = simulate_observation(**SITE, utc=UTC, heading_deg=heading_deg, pitch_deg=1.0, width=width)
    cameras = []
    for k, (view, image) in enumerate(
        zip(sky.observation.cameras, render_views(sky, RenderSettings(), seed=seed), strict=True)
    ):
        write_image(folder / f"cam{k}.png", image)
        cameras.append(
            {
                "R_cam_from_body": view.R_cam_from_body.tolist(),
                "fov_deg": 20.0,
                "image": f"cam{k}.png",
            }
        )
    obs = {
        "utc": UTC,
        "gravity_body": sky.observation.gravity_body.tolist(),
        "pressure_hpa": 0,
        "cameras": cameras,
    }
    (folder / "obs.json").write_text(json.dumps(obs))
    fix = locate(read_observation(folder / "obs.json"), sigma_px=0.1)
    m_north, m_east = radii_of_curvature_m(SITE["lat_deg"])
    north = np.radians(fix.lat_deg - SITE["lat_deg"]) * m_north
    east = np.radians(fix.lon_deg - SITE["lon_deg"]) * m_east * np.cos(np.radians(SITE["lat_deg"]))
    heading = ((fix.azimuth_deg - heading_deg + 180.0) % 360.0 - 180.0) * 3600.0
    return float(np.hypot(north, east)), float(heading), fix.n_stars


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    t0 = time.time()
    rng = np.random.default_rng(args.seed)
    draws = [(float(rng.uniform(0, 360)), int(rng.integers(2**31))) for _ in range(args.cases)]
    lines = table_head(
        "images",
        "cases",
        "median error (m)",
        "max (m)",
        "median abs heading (″)",
        "max (″)",
        "median stars used",
    )
    with tempfile.TemporaryDirectory() as tmp:
        for width in (1024, 512):
            runs = np.array([one_case(Path(tmp), width, h, s) for h, s in draws])
            position, heading = runs[:, 0], np.abs(runs[:, 1])
            lines.append(
                table_row(
                    f"three 20° cameras, {width} px",
                    len(runs),
                    f"{np.median(position):.1f}",
                    f"{position.max():.1f}",
                    f"{np.median(heading):.2f}",
                    f"{heading.max():.2f}",
                    f"{np.median(runs[:, 2]):.0f}",
                )
            )
    text = "\n".join(
        [
            *lines,
            "",
            f"Headings uniform in 0-360°, seed {args.seed}; `python "
            f"benchmarks/navigation/locate_images.py --cases {args.cases}`: "
            f"{time.time() - t0:.0f} s on {machine()}.",
        ]
    )
    replace_block(DOC, "images", text)
    print(text)


if __name__ == "__main__":
    main()
