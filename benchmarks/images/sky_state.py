"""The sky's state (``starnav sky``) of real all-sky frames: the KHO Sony frame of
../shared/data/allsky (solved from the file), and, when STARNAV_TUDO_FRAMES names their folder,
the tudo-astroparticlephysics/all_sky_cloud_detection test frames (MAGIC, IceAct): their
attitude and clear-sky limit come from each camera's mount (tests/data/allsky/
tudo_cameras.json, made by sky_cameras.py on one clear frame; today's solver does not solve
them). Each row runs the command line as an operator does and prints: the stars expected and
seen, the clear fraction, the clear cells' limiting magnitude, the cells clear / partly /
cloudy / no data, what the eye sees in the frame, and the time per frame.

Run: python benchmarks/images/sky_state.py   (prints a markdown table and the machine line;
writes docs/images/sky_state_kho.png; docs/allsky.md holds the table)
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import ROOT, SHARED, machine, table_head, table_row
from starnav.cli import main as starnav

KHO = SHARED / "allsky" / "kho_sony_a7s_20201211_200933.jpg"
KHO_OPTIONS = ["--lens", "equisolid", "--fov-deg", "180", "--max-stars", "100",
               "--lat", "78.148", "--lon", "16.043", "--height-m", "520",
               "--utc", "2020-12-11T20:09:33"]  # fmt: skip
KHO_EYE = "clear; aurora low in the S, glow along the N horizon"
CAMERAS = ROOT / "tests" / "data" / "allsky" / "tudo_cameras.json"
# file, camera, mid-exposure UTC, what the eye sees (our reading of each frame)
TUDO = [
    (
        "magic_20180817_0055.fits",
        "magic",
        "2018-08-17T00:52:51",
        "clear, Milky Way; telescope and domes at the E, W and S edges",
    ),
    (
        "magic_20180817_0341.fits",
        "magic",
        "2018-08-17T03:38:58",
        "clear, Milky Way low; same obstructions",
    ),
    (
        "magic_20180816_2101.fits",
        "magic",
        "2018-08-16T20:59:05",
        "clear, Moon low in the W (masked), its glare over the W half",
    ),
    ("iceact_starry.fits", "iceact", "2017-05-03T03:13:04", "clear, Milky Way across"),
    (
        "iceact_cloudy.fits",
        "iceact",
        "2017-06-11T04:10:03",
        "overcast, lit cloud all round; a thinner hole S of the zenith shows stars",
    ),
]


def run_sky(image: Path, options: list[str], png: Path | None) -> tuple[dict, float]:
    """``starnav sky IMAGE OPTIONS --json`` in this process: its JSON and the wall time (s)."""
    args = ["sky", str(image), *options, "--json", *(["--png", str(png)] if png else [])]
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out):
        status = starnav(args)
    seconds = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"starnav sky {image.name}: exit {status}")
    return json.loads(out.getvalue()), seconds


def shrink(png: Path) -> None:
    """The docs' copy of a picture: 1000 px, 256 colours (a photograph's noise makes the full
    picture a few MB)."""
    from PIL import Image

    with Image.open(png) as im:
        small = im.convert("RGB")
        small.thumbnail((1000, 1000))
        small.quantize(256).save(png, optimize=True)


def row(name: str, how: str, result: dict, seconds: float, eye: str) -> str:
    sky = result["sky"]
    counts = sky["cell_counts"]
    lim = "—" if sky["limiting_mag"] is None else f"{sky['limiting_mag']:.1f}"
    clear = "—" if sky["clear_fraction"] is None else f"{sky['clear_fraction']:.2f}"
    cells = " / ".join(str(counts[k]) for k in ("clear", "partly", "cloudy", "no data"))
    return table_row(
        name, how, f"{sky['n_expected']} (to {sky['mag_limit']:.2f}, {sky['expected_by']})",
        sky["n_expected_seen"], clear, sky["state"], lim, cells, eye, f"{seconds:.1f}",
    )  # fmt: skip


def main() -> None:
    load = os.getloadavg()[0]
    lines = table_head(
        "frame", "attitude", "expected (to mag)", "seen", "clear fraction", "sky",
        "limiting mag", "cells C / P / X / none", "what the eye sees", "time (s)",
    )  # fmt: skip
    png = ROOT / "docs" / "images" / "sky_state_kho.png"
    result, seconds = run_sky(KHO, KHO_OPTIONS, png)
    lines.append(row(KHO.name, "solved", result, seconds, KHO_EYE))
    shrink(png)
    folder = Path(os.environ.get("STARNAV_TUDO_FRAMES", ""))
    if folder.is_dir():
        cameras = json.loads(CAMERAS.read_text())
        with tempfile.TemporaryDirectory() as tmp:
            for name, cam, utc, eye in TUDO:
                spec = cameras[cam]
                camera_file, mount_file = Path(tmp) / f"{cam}.json", Path(tmp) / f"{cam}_m.json"
                camera_file.write_text(json.dumps(spec["camera"]))
                mount = {k: spec[k] for k in ("R_cam_from_enu", "mag_limit")}
                mount_file.write_text(json.dumps(mount))
                site = spec["site"]
                options = ["--camera", str(camera_file), "--mount", str(mount_file),
                           "--lat", str(site["lat_deg"]), "--lon", str(site["lon_deg"]),
                           "--height-m", str(site["height_m"]), "--utc", utc]  # fmt: skip
                result, seconds = run_sky(folder / name, options, None)
                lines.append(row(name, f"mount ({cam})", result, seconds, eye))
    print("\n".join(lines))
    print(f"\n{machine(load, load_at_end=True)}")


if __name__ == "__main__":
    main()
