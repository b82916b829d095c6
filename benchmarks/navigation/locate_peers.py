"""starnav locate and zenith-fixer on the same simulated observations, into docs/locate.md.

    python benchmarks/navigation/locate_peers.py --cases 50

zenith-fixer (PyPI, a Rust extension) runs in its own virtual environment, created once under
``$STARNAV_CACHE_DIR/venvs/zenith-fixer`` (or ``--venv``), through
``benchmarks/navigation/zenith_fixer_adapter.py`` in a subprocess that times each fix itself.
Cases: random
site (|lat| < 60°), random UTC at night in 2025, random heading, tilt up to 3°; three cameras
120° apart at 45° elevation, 20° FOV, 1024 px, Hipparcos Hp <= 7, 0.5 px centroid noise, no
refraction in the data (the adapter undoes zenith-fixer's fixed refraction correction).
Position error: distance from the truth; heading only from starnav (zenith-fixer reports none).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, machine, replace_block, table_head, table_row
from starnav.identify import cache_dir
from starnav.navigation import FixError, locate
from starnav.navigation.frames import radii_of_curvature_m
from starnav.navigation.simulate import simulate_observation

DOC = DOCS / "locate.md"
ADAPTER = Path(__file__).resolve().parent / "zenith_fixer_adapter.py"
ZENITH_VERSION = "0.22.0"


def zenith_python(venv: Path) -> Path:
    """The interpreter of the zenith-fixer environment (made on first use)."""
    python = venv / "bin" / "python"
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run(
            [str(python), "-m", "pip", "install", "-q", f"zenith-fixer=={ZENITH_VERSION}"],
            check=True,
        )
    return python


def distance_m(lat, lon, lat_true, lon_true) -> float:
    m_north, m_east = radii_of_curvature_m(lat_true)
    north = np.radians(lat - lat_true) * m_north
    east = np.radians((lon - lon_true + 180) % 360 - 180) * m_east * np.cos(np.radians(lat_true))
    return float(np.hypot(north, east))


def observation_json(obs) -> dict:
    return {
        "utc": obs.utc,
        "gravity_body": obs.gravity_body.tolist(),
        "pressure_hpa": obs.pressure_hpa,
        "cameras": [
            {
                "fov_deg": c.fov_deg,
                "width": c.width,
                "height": c.height,
                "R_cam_from_body": c.R_cam_from_body.tolist(),
                "stars": c.xy.tolist(),
            }
            for c in obs.cameras
        ],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--venv", type=Path, default=cache_dir() / "venvs" / "zenith-fixer")
    args = parser.parse_args()
    t0 = time.time()
    python = zenith_python(args.venv)
    rng = np.random.default_rng(args.seed)
    cases, ours = [], []
    for _ in tqdm(range(args.cases), desc="starnav locate", file=sys.stderr):
        lat = float(np.degrees(np.arcsin(rng.uniform(-0.85, 0.85))))
        lon = float(rng.uniform(-180, 180))
        # local midnight +- 3 h on a random day of 2025 (IERS final values)
        day = int(rng.integers(0, 300))
        hours = (24.0 - lon / 15.0 + rng.uniform(-3, 3)) % 24.0
        utc = (
            np.datetime64("2025-01-01T00:00:00")
            + np.timedelta64(day, "D")
            + np.timedelta64(int(hours * 3600), "s")
        )
        truth = {"lat": lat, "lon": lon, "heading": float(rng.uniform(0, 360))}
        sky = simulate_observation(
            lat_deg=lat,
            lon_deg=lon,
            utc=f"{utc}Z",
            heading_deg=truth["heading"],
            pitch_deg=float(rng.uniform(-3, 3)),
            roll_deg=float(rng.uniform(-3, 3)),
            noise_px=0.5,
            seed=rng,
        )
        cases.append((truth, sky.observation))
        try:
            fix = locate(sky.observation, sigma_px=0.5)
        except FixError:
            ours.append(None)
            continue
        heading_error = ((fix.azimuth_deg - truth["heading"] + 180) % 360 - 180) * 3600
        ours.append(
            (distance_m(fix.lat_deg, fix.lon_deg, lat, lon), abs(heading_error), fix.time_ms)
        )
    lines = "\n".join(json.dumps(observation_json(obs)) for _, obs in cases)
    theirs = []
    for mode in ("best", "merge"):
        run = subprocess.run(
            [str(python), str(ADAPTER), "--mode", mode],
            input=lines,
            capture_output=True,
            text=True,
            check=True,
        )
        rows = []
        for (truth, _), line in zip(cases, run.stdout.splitlines(), strict=True):
            out = json.loads(line)
            if out.get("error"):
                rows.append(None)
            else:
                d = distance_m(out["lat_deg"], out["lon_deg"], truth["lat"], truth["lon"])
                rows.append((d, None, out["time_ms"]))
        theirs.append((mode, rows))

    def row(name, results):
        ok = [r for r in results if r is not None]
        d = np.array([r[0] for r in ok])
        ms = np.array([r[2] for r in ok])
        heading = [r[1] for r in ok if r[1] is not None]
        h = f"{np.median(heading):.3f}" if heading else "not reported"
        return table_row(
            name,
            f"{len(ok)} / {len(results)}",
            f"{np.median(d):.1f}",
            f"{np.percentile(d, 95):.1f}",
            f"{d.max():.1f}",
            h,
            f"{np.median(ms):.1f}",
        )

    text = "\n".join(
        [
            f"{args.cases} simulated observations (see `benchmarks/navigation/locate_peers.py`): "
            "three cameras 120° apart at 45° elevation, 20° FOV, 1024 px, Hp <= 7, 0.5 px noise, "
            f"tilt up to 3°, random sites and nights of 2025; zenith-fixer {ZENITH_VERSION} "
            "in its own environment, through `benchmarks/navigation/zenith_fixer_adapter.py` (it "
            "takes one camera: `best` = the camera with most stars, `merge` = all cameras' stars "
            "reprojected into one virtual camera looking up, the adapter's construction).",
            "",
            *table_head(
                "solver",
                "fixes",
                "median error (m)",
                "p95 (m)",
                "max (m)",
                "median heading error (″)",
                "median ms",
            ),
            row("starnav locate", ours),
            *[row(f"zenith-fixer ({mode})", rows) for mode, rows in theirs],
            "",
            f"Times: starnav's identification of three cameras and the fix (`Fix.time_ms`); "
            f"zenith-fixer's own call, timed in its process. {machine()}; "
            f"`python benchmarks/navigation/locate_peers.py --cases {args.cases}`, "
            f"{time.time() - t0:.0f} s.",
        ]
    )
    replace_block(DOC, "peers", text)
    print(text)


if __name__ == "__main__":
    main()
