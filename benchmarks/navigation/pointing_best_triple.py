"""Three-star pointing on simulated frames: which triple of identified stars to use.

Frames: boresights uniform on the sphere, random roll, 12° / 512 px pinhole camera, Hipparcos
Hp <= 6 at epoch J1991.25 (the catalog the frames are made from, so catalog positions are
exact), Gaussian centroid noise 0.5 px per axis; frames with fewer than 5 stars are skipped
and redrawn. The stars are the true ones (identification assumed correct; false stars are
left out). Methods: ``best_triple`` (smallest predicted error), the three brightest, three at
random, and the triple of largest tetrahedron volume |det U| (the textbook rule). Each triple
is solved with ``three_star`` (focal length known, x,y given) and scored by the angle between
its boresight and the true one.

    python benchmarks/navigation/pointing_best_triple.py --frames 1000

prints the markdown table that docs/pointing.md quotes (``--out FILE`` also writes it).
"""

from __future__ import annotations

import argparse
import sys
import time
from itertools import combinations
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import machine, table_head, table_row
from starnav import Camera, load_catalog, simulate_frame
from starnav.geometry import ARCSEC_PER_RAD, angle_between
from starnav.pointing import PointingError, best_triple, three_star
from starnav.simulate import FALSE_STAR_ID

FOV_DEG = 12.0
WIDTH = 512
MIN_STARS = 5
METHODS = ("best_triple", "brightest three", "random three", "largest volume")


def largest_volume(ra_deg: np.ndarray, dec_deg: np.ndarray) -> tuple[int, int, int]:
    """Indices of the triple with the largest |det[u1, u2, u3]|."""
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    U = np.column_stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)])
    triples = list(combinations(range(len(U)), 3))
    dets = [abs(np.linalg.det(U[list(t)])) for t in triples]
    return triples[int(np.argmax(dets))]


def run(frames: int, seed: int, noise_px: float) -> dict:
    camera = Camera.from_fov(FOV_DEG, WIDTH)
    catalog = load_catalog(None, mag_limit=6.0, epoch_year=1991.25)
    rng = np.random.default_rng(seed)
    errors = {m: [] for m in METHODS}
    predicted = {m: [] for m in METHODS}
    rejected = dict.fromkeys(METHODS, 0)
    reasons = []
    n_stars, drawn, same_as_volume = [], 0, 0
    with tqdm(total=frames, desc="frames", file=sys.stderr) as bar:
        while len(n_stars) < frames:
            frame = simulate_frame(catalog, camera, noise_px=noise_px, seed=rng)
            drawn += 1
            true = frame.true_id != FALSE_STAR_ID
            if true.sum() < MIN_STARS:
                continue
            rows = catalog.rows(frame.true_id[true])
            ra, dec, xy = catalog.ra_deg[rows], catalog.dec_deg[rows], frame.xy[true]
            triples = {
                "best_triple": best_triple(
                    ra,
                    dec,
                    xy,
                    focal_px=camera.focal_px,
                    width=WIDTH,
                    height=WIDTH,
                ),
                "brightest three": (0, 1, 2),  # frame order is brightest first
                "random three": tuple(rng.choice(len(rows), 3, replace=False)),
                "largest volume": largest_volume(ra, dec),
            }
            same_as_volume += set(triples["best_triple"]) == set(triples["largest volume"])
            truth = frame.R_cam_from_icrs[2]
            for method, t in triples.items():
                t = list(t)
                try:
                    p = three_star(
                        ra[t],
                        dec[t],
                        xy=xy[t],
                        width=WIDTH,
                        height=WIDTH,
                        focal_px=camera.focal_px,
                        sigma_px=noise_px,
                    )
                except PointingError as exc:
                    rejected[method] += 1
                    gap = min(np.hypot(*(xy[i] - xy[j])) for i, j in combinations(t, 2))
                    reasons.append(f"{method}, closest pair {gap:.1f} px apart: {exc}")
                    errors[method].append(np.nan)
                    predicted[method].append(np.nan)
                    continue
                predicted[method].append(p.sigma_boresight_arcsec)
                errors[method].append(float(angle_between(p.boresight, truth)) * ARCSEC_PER_RAD)
            n_stars.append(int(true.sum()))
            bar.update()
    return {
        "errors": {m: np.array(e) for m, e in errors.items()},
        "predicted": {m: np.array(e) for m, e in predicted.items()},
        "rejected": rejected,
        "n_stars": np.array(n_stars),
        "drawn": drawn,
        "same_as_volume": same_as_volume,
        "reasons": reasons,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--noise", type=float, default=0.5, help="centroid noise, px per axis")
    parser.add_argument("--out", help="also write the markdown table to this file")
    parser.add_argument("--append", action="store_true", help="append to --out, do not replace")
    args = parser.parse_args()
    t0 = time.time()
    r = run(args.frames, args.seed, args.noise)
    err = r["errors"]
    n = r["n_stars"]
    lines = [
        f"Three-star pointing, {FOV_DEG:g}° / {WIDTH} px, Hipparcos Hp <= 6 (J1991.25), "
        f"centroid noise {args.noise:g} px, {args.frames} frames with >= {MIN_STARS} stars "
        f"({r['drawn']} drawn uniformly on the sky), seed {args.seed}; stars per frame: median "
        f"{np.median(n):.0f}, range {n.min()}-{n.max()}. Machine: {machine()}.",
        "",
        "Boresight error against the truth; RMS next to the RMS of the analytic 1σ that "
        "`three_star` predicted for the same triples (the two agree when the error model holds).",
        "",
        *table_head(
            "triple",
            "median (″)",
            "mean (″)",
            "p95 (″)",
            "RMS (″)",
            "predicted 1σ, RMS (″)",
            "rejected",
        ),
    ]
    for m in METHODS:
        ok = np.isfinite(err[m])
        e, s = err[m][ok], r["predicted"][m][ok]
        lines.append(
            table_row(
                m,
                f"{np.median(e):.1f}",
                f"{np.mean(e):.1f}",
                f"{np.percentile(e, 95):.1f}",
                f"{np.sqrt(np.mean(e**2)):.1f}",
                f"{np.sqrt(np.mean(s**2)):.1f}",
                r["rejected"][m],
            )
        )
    both = np.isfinite(err["best_triple"]) & np.isfinite(err["brightest three"])
    wins = int(np.sum(err["best_triple"][both] < err["brightest three"][both]))
    # nan compares False: a frame where either triple was rejected counts as no win
    wins_random = int(np.sum(err["best_triple"] < err["random three"]))
    wins_volume = int(np.sum(err["best_triple"] < err["largest volume"]))
    lines += [
        "",
        f"best_triple beats the brightest three in {wins} of {both.sum()} frames "
        f"({100 * wins / both.sum():.0f} %), three random stars in {wins_random} of "
        f"{len(n)} ({100 * wins_random / len(n):.0f} %), the largest-volume triple in "
        f"{wins_volume} of {len(n)} ({100 * wins_volume / len(n):.0f} %; the two chose the "
        f"same triple in {r['same_as_volume']} frames).",
    ]
    if r["reasons"]:
        lines += ["", "Triples `three_star` refused:", ""]
        lines += [f"- {why}" for why in r["reasons"]]
    lines += [
        "",
        f"Command: `python benchmarks/navigation/pointing_best_triple.py --frames {args.frames} "
        f"--seed {args.seed} --noise {args.noise:g}`, {time.time() - t0:.0f} s.",
    ]
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "a" if args.append else "w") as fh:
            fh.write(text + "\n")


if __name__ == "__main__":
    main()
