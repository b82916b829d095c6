"""All-sky (185°) fisheye images rendered and solved from the pixels: markdown table on stdout.

    python benchmarks/images/wide_images.py --frames 100 [--seed 2026] [--max-stars 50 100]

Cameras: 1024 x 1024 px whose 185° image circle just fits the sensor (black outside it),
``equidistant`` (r = f θ) and ``equisolid`` (r = 2 f sin(θ/2)), f from ``from_fov(185°)``.
Frames: ``--frames`` attitudes uniform on SO(3) (parity +1), frame i's attitude and noise from
(``--seed``, i), the same attitudes for both lenses, rendered by ``simulate.render`` from the
Hipparcos stars with Hp <= 6.5 (about 4000 in the circle): Gaussian PSF sigma 1.2 px (the same
over the image), sky 100 e/px, read noise 5 e, 20 hot pixels, 16 bits, vignetting cos²(θ/2)
(one stop at 90° from the axis, the render's fisheye default). An Hp 6 star on the axis has
SNR ~ 15.

Each image is solved with ``starnav.solve_image(pixels, ...)`` twice: camera known
(``camera=`` the rendering camera) and focal length unknown (``lens=`` the model,
``fov_range_deg=(150, 200)``: the fisheye focal scan), using the brightest ``--max-stars``
detections (one row per value). A first solve, not counted, loads the catalog and tables.

Scores: solved = an answer; wrong = not correct by ``starnav evaluate``'s rule
(``harness.CORRECT_RULE``: the right parity, within 0.05° in boresight and 0.5° in roll, or
within 5 of its own sigmas); the boresight errors (arcsec) are over the correct answers; time
= detection + identification + fit per image (``ImageSolveResult.total_ms``), median over the
images.
"""

from __future__ import annotations

import os

# one core: thread pools of 1, set before numpy loads
os.environ.update(
    dict.fromkeys(("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"), "1")
)

import argparse
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import CORRECT_RULE, score_solution, table_head, table_row
from starnav.camera import Equidistant, Equisolid
from starnav.catalog import load_catalog
from starnav.pipeline.image import solve_image
from starnav.simulate.render import RenderSettings, render_frame

CIRCLE_DEG = 185.0
SIZE_PX = 1024
MAG_LIMIT = 6.5
FOV_RANGE_DEG = (150.0, 200.0)
SETTINGS = RenderSettings(
    psf_sigma_px=1.2, background_e=100.0, read_noise_e=5.0, hot_pixels=20, mag_limit=MAG_LIMIT
)
LENSES = (Equidistant, Equisolid)
MODES = ("camera known", "focal unknown")


@dataclass(frozen=True)
class Outcome:
    """One image solved one way: ``error_arcsec`` (boresight; None when unsolved), whether
    the answer is correct (``harness.score_solution``) and ``total_ms``."""

    error_arcsec: float | None
    correct: bool
    total_ms: float


def allsky_camera(lens: type):
    """The 1024 px camera whose 185° image circle fits the sensor."""
    return lens.from_fov(CIRCLE_DEG, SIZE_PX, SIZE_PX).with_circle(CIRCLE_DEG)


def attitude(seed: int, index: int) -> tuple[np.ndarray, int]:
    """Frame ``index``'s attitude (uniform on SO(3)) and its render seed."""
    seq = np.random.SeedSequence([seed, index])
    R = Rotation.random(random_state=np.random.default_rng(seq)).as_matrix()
    return R, int(seq.generate_state(1)[0])


def solve_one(image: np.ndarray, camera, mode: str, max_stars: int):
    """``solve_image`` of ``image`` in ``mode``."""
    if mode == "camera known":
        return solve_image(image, camera=camera, max_stars=max_stars)
    return solve_image(image, lens=camera.model, fov_range_deg=FOV_RANGE_DEG, max_stars=max_stars)


def run(frames: int, seed: int, max_stars: list[int]) -> dict[tuple, list[Outcome]]:
    """Every image of every lens solved every way: outcomes by (lens, mode, max_stars)."""
    catalog = load_catalog(None, mag_limit=MAG_LIMIT)
    out: dict[tuple, list[Outcome]] = {}
    for lens in LENSES:
        camera = allsky_camera(lens)
        for i in tqdm(range(frames), desc=camera.model, file=sys.stderr, leave=False):
            R, frame_seed = attitude(seed, i)
            frame = render_frame(catalog, camera, R, dataclasses.replace(SETTINGS, seed=frame_seed))
            for mode in MODES:
                for m in max_stars:
                    if i == 0:  # loads the catalog and the tables: not counted
                        solve_one(frame.image, camera, mode, m)
                    result = solve_one(frame.image, camera, mode, m)
                    s = result.solution
                    score = None if s is None else score_solution(s, R)
                    out.setdefault((camera.model, mode, m), []).append(
                        Outcome(
                            None if score is None else score.boresight_arcsec,
                            score is not None and score.correct,
                            result.total_ms,
                        )
                    )
    return out


def table(outcomes: dict[tuple, list[Outcome]]) -> str:
    """The markdown table of the outcomes."""
    lines = table_head(
        "lens",
        "mode",
        "max stars",
        "images",
        "solved %",
        "wrong",
        "median error ″",
        "max error ″",
        "median ms",
    )
    for (model, mode, m), rows in outcomes.items():
        solved = [r for r in rows if r.error_arcsec is not None]
        wrong = sum(not r.correct for r in solved)
        good = [r.error_arcsec for r in solved if r.correct]
        median = f"{np.median(good):.1f}" if len(good) else "-"
        worst = f"{np.max(good):.1f}" if len(good) else "-"
        ms = np.median([r.total_ms for r in rows])
        lines.append(
            table_row(
                model,
                mode,
                m,
                len(rows),
                f"{100 * len(solved) / len(rows):.1f}",
                wrong,
                median,
                worst,
                f"{ms:.0f}",
            )
        )
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=100, help="images per lens (default 100)")
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument(
        "--max-stars",
        type=int,
        nargs="+",
        default=[50],
        help="brightest detections used (default 50, solve_image's default); one row each",
    )
    args = p.parse_args()
    outcomes = run(args.frames, args.seed, args.max_stars)
    print(
        f"{args.frames} all-sky images per lens ({SIZE_PX} x {SIZE_PX} px, image circle "
        f"{CIRCLE_DEG:g}°, Hp <= {MAG_LIMIT:g}, PSF sigma {SETTINGS.psf_sigma_px:g} px, sky "
        f"{SETTINGS.background_e:g} e, read noise {SETTINGS.read_noise_e:g} e, "
        f"{SETTINGS.hot_pixels} hot pixels, vignetting cos^p(θ/2) with p = "
        f"{SETTINGS.vignetting_power_for(allsky_camera(Equidistant)):g}), seed {args.seed}; "
        f"focal unknown: scanned over {FOV_RANGE_DEG[0]:g}-{FOV_RANGE_DEG[1]:g}°. Scores: "
        f"{CORRECT_RULE}.\n"
    )
    print(table(outcomes))


if __name__ == "__main__":
    main()
