"""Per-frame answers of the solve paths, for comparing a restructuring against what it replaced.

Runs a fixed set of frames through the public API (lost in space with every algorithm, tracking,
the focal length fitted, a distorted camera, the FOV search on star lists, random fields) and,
with ``--images``, the real photographs of ``../shared/data/images`` and ``../shared/data/real``
through ``solve_image`` (no time budget, so the machine's load cannot change an answer);
writes, per frame, whether it was solved, the reason, the catalog id of every point and the
attitude. ``--compare OLD.json`` prints the frames whose answer changed: a
different outcome, ids or reason, or an attitude more than ``--tol-arcsec`` apart.

    python benchmarks/answers.py -o /tmp/before.json
    python benchmarks/answers.py -o /tmp/after.json --compare /tmp/before.json
    python benchmarks/answers.py -o /tmp/after.json --images 14   # and 16 real photographs
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from starnav.api import solve_image, solve_stars
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_difference_deg
from starnav.identify import ALGORITHMS
from starnav.simulate import simulate_frame

ROOT = Path(__file__).resolve().parents[1]
NOISY = {"noise_px": 0.5, "false_stars": 2, "missing_frac": 0.1}


def answer(result) -> dict:
    s = result.solution
    if s is None:
        return {"solved": False, "reason": result.reason}
    return {
        "solved": True,
        "ids": [m.catalog_id for m in s.stars],
        "R": np.asarray(s.R_cam_from_icrs).tolist(),
        "focal_px": s.focal_px,
        "rms_px": s.rms_px,
        "sigma_boresight_arcsec": s.sigma_boresight_arcsec,
        "false_match_probability": s.false_match_probability,
    }


def cases(catalog, frames: int):
    """(name, thunk) for every frame of every case."""
    cam12 = Camera.from_fov(12.0, 512)
    cam20 = Camera.from_fov(20.0, 1024)
    warped = Camera(640, 480, Camera.from_fov(15.0, 640, 480).focal_px, 322.0, 238.0, -0.08, 0.01)

    def frame(camera, seed, **kw):
        return simulate_frame(catalog, camera, seed=seed, **kw)

    def lis(camera, f, **options):
        return lambda: solve_stars(
            f.xy,
            width=camera.width,
            height=camera.height,
            fov_deg=camera.fov_deg,
            brightness=f.brightness,
            catalog=catalog,
            **options,
        )

    for i in range(frames):
        f = frame(cam12, 1000 + i, **NOISY)
        yield f"pyramid-noisy-{i}", lis(cam12, f, sigma_px=0.5)
        f = frame(cam12, 2000 + i, noise_px=0.1, parity=-1 if i % 2 else 1)
        yield f"pyramid-clean-{i}", lis(cam12, f, sigma_px=0.1)
        f = frame(cam20, 3000 + i, noise_px=0.2)
        yield f"pyramid-20deg-{i}", lis(cam20, f, sigma_px=0.2)
        f = frame(cam12, 4000 + i, noise_px=0.5)
        R = f.R_cam_from_icrs
        yield f"tracking-{i}", lis(cam12, f, sigma_px=0.5, prior=R, prior_sigma_deg=0.5)
        f = frame(cam12, 5000 + i, noise_px=0.3)
        yield f"fit-focal-{i}", lis(cam12, f, sigma_px=0.3, fit_focal=True)
        rng = np.random.default_rng(6000 + i)
        n = int(rng.integers(6, 16))
        xy = rng.uniform(0, 512, (n, 2))
        yield (
            f"random-{i}",
            lambda xy=xy: solve_stars(xy, width=512, fov_deg=12.0, catalog=catalog, sigma_px=0.5),
        )
    for i in range(max(frames // 2, 1)):
        f = frame(warped, 7000 + i, noise_px=0.2)
        yield (
            f"distorted-{i}",
            lambda f=f: solve_stars(
                f.xy,
                fov_exact=False,
                width=warped.width,
                height=warped.height,
                brightness=f.brightness,
                camera=warped,
                sigma_px=0.3,
            ),
        )
        f = frame(cam20, 8000 + i, noise_px=0.2)
        yield (
            f"fov-search-{i}",
            lambda f=f: solve_stars(
                f.xy, fov_exact=False, width=1024, brightness=f.brightness, sigma_px=0.3
            ),
        )
    for name in ALGORITHMS:
        if name == "pyramid":
            continue
        options = {"selection": "optimized"} if name == "triangle" else {}
        for i in range(max(frames // 2, 1)):
            f = frame(cam12, 9000 + i, **NOISY)
            yield (
                f"{name}-{i}",
                lis(cam12, f, sigma_px=0.5, algorithm=name, algorithm_options=options),
            )


def image_cases(limit: int):
    """(name, thunk) for the shared folder's real photographs (the first ``limit`` of real/)."""
    shared = ROOT.parent / "shared" / "data"
    suffixes = (".jpg", ".png", ".bmp", ".fits", ".tif")
    real = sorted(p for p in (shared / "real").glob("*") if p.suffix.lower() in suffixes)
    for path in sorted((shared / "images").glob("*.jpg")) + real[:limit]:
        yield (
            f"image-{path.parent.name}-{path.name}",
            lambda path=path: solve_image(path, time_budget_s=math.inf),
        )


def compare(old: dict, new: dict, tol_arcsec: float) -> list[str]:
    out = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a is None or b is None:
            out.append(f"{key}: only in {'new' if a is None else 'old'}")
        elif a["solved"] != b["solved"]:
            out.append(f"{key}: solved {a['solved']} -> {b['solved']} ({b.get('reason', '')})")
        elif not a["solved"]:
            if a["reason"] != b["reason"]:
                out.append(f"{key}: reason {a['reason']!r} -> {b['reason']!r}")
        else:
            if a["ids"] != b["ids"]:
                out.append(f"{key}: ids differ")
            d = max(attitude_difference_deg(np.array(a["R"]), np.array(b["R"]))) * 3600
            if d > tol_arcsec:
                out.append(f"{key}: attitude {d:.3g}″ apart")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", required=True)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--compare")
    parser.add_argument("--tol-arcsec", type=float, default=1e-3)
    parser.add_argument(
        "--images", type=int, default=0, metavar="N", help="also the first N real photographs"
    )
    args = parser.parse_args()
    catalog = load_catalog(None, mag_limit=6.0)
    out, times = {}, {}
    todo = list(cases(catalog, args.frames))
    if args.images:
        todo += list(image_cases(args.images))
    for name, thunk in tqdm(todo, file=sys.stderr):
        t0 = time.perf_counter()
        out[name] = answer(thunk())
        times[name] = time.perf_counter() - t0
    Path(args.out).write_text(json.dumps(out))
    print(f"{len(out)} frames, {sum(a['solved'] for a in out.values())} solved", file=sys.stderr)
    if args.compare:
        diffs = compare(json.loads(Path(args.compare).read_text()), out, args.tol_arcsec)
        print("\n".join(diffs) or "no differences")
        return 1 if diffs else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
