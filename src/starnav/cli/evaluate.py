"""``starnav evaluate``: the lost-in-space evaluation over the whole sky (simulated frames)."""

from __future__ import annotations

import argparse
from dataclasses import asdict

from starnav.api import DEFAULT_MAX_FALSE_MATCH_PROBABILITY
from starnav.catalog import DEFAULT_MAG_LIMIT
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_algorithm,
    add_dask,
    add_frame_errors,
    algorithm_options,
    check_parent_dir,
    count,
    finite,
    png_path,
    positive_int,
)
from starnav.cli.output import print_json
from starnav.errors import StarnavError

DEFAULT_GRID_STEP_DEG = 3.0  # 120 x 60 = 7200 boresights, the published grid
DEFAULT_FRAMES = 1000  # frames of --sampling uniform


def add_parser(subparsers: Subparsers) -> None:
    """The ``evaluate`` command and its options."""
    p = subparsers.add_parser(
        "evaluate", help="lost-in-space evaluation over the whole sky (simulated frames)"
    )
    p.add_argument(
        "--sampling",
        choices=("grid", "uniform"),
        help="the boresights: grid (an RA/Dec grid, --grid-step-deg) or uniform (at random, "
        "uniform on the sphere, --frames); default: uniform when --frames is given, else grid",
    )
    p.add_argument(
        "--grid-step-deg",
        type=finite,
        help=f"RA/Dec grid step of --sampling grid (degrees; default {DEFAULT_GRID_STEP_DEG:g}: "
        "7200 boresights)",
    )
    p.add_argument(
        "--frames",
        type=positive_int,
        help=f"frames of --sampling uniform (default {DEFAULT_FRAMES}); --frames alone means "
        "--sampling uniform",
    )
    p.add_argument(
        "--camera",
        metavar="CAM.json",
        help="camera file (any lens model, e.g. a fisheye) instead of the pinhole of --fov-deg, "
        "--width, --height",
    )
    p.add_argument("--fov-deg", type=finite, help="horizontal FOV (degrees; default 12)")
    p.add_argument("--width", type=positive_int, help="image width (px; default 512)")
    p.add_argument("--height", type=positive_int, help="image height (px; default: width)")
    p.add_argument(
        "--mag-limit",
        type=finite,
        default=DEFAULT_MAG_LIMIT,
        help="Hipparcos Hp limit of the stars simulated and identified (default %(default)g)",
    )
    add_frame_errors(p, noise_px=0.5, false_stars=2, missing_frac=0.1)
    p.add_argument(
        "--sigma-px",
        type=finite,
        help="centroid sigma told to the solver (px; default: the noise)",
    )
    add_algorithm(p)
    p.add_argument(
        "--kind",
        action="append",
        metavar="KIND[,KIND]",
        help="frame kinds, repeatable or a comma list, taken in turn: true (default: the "
        "simulated sky), random, scrambled, mirrored, fov-off, crowded, few "
        "(docs: starnav.evaluate.kinds)",
    )
    p.add_argument(
        "--max-false-match-probability",
        type=finite,
        default=DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
        metavar="P",
        help=f"refuse less certain answers (default {DEFAULT_MAX_FALSE_MATCH_PROBABILITY:g})",
    )
    p.add_argument(
        "--seed",
        type=count,
        default=0,
        help="random seed of the boresights' rolls and of every frame (default %(default)s)",
    )
    p.add_argument(
        "--workers", type=positive_int, help="processes (default: all cores; 1: this process)"
    )
    add_dask(p, "the frames")
    p.add_argument("--frames-csv", metavar="CSV", help="write one row per frame here")
    p.add_argument("--sky-map", metavar="PNG", type=png_path, help="whole-sky outcome map")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the evaluation; print the summary, write the per-frame CSV and the sky map."""
    from starnav.camera import load_camera
    from starnav.evaluate import (
        EvalConfig,
        camera_items,
        evaluate,
        grid_boresights,
        uniform_boresights,
    )
    from starnav.evaluate.kinds import parse_kinds
    from starnav.evaluate.report import describe, markdown, plot_sky_map, write_frames_csv

    drawn, amount = choose_sampling(args.sampling, args.frames, args.grid_step_deg)
    size = {k: getattr(args, k) for k in ("fov_deg", "width", "height")}
    size = {k: v for k, v in size.items() if v is not None}
    if args.camera is not None:
        if size:
            option = "--" + next(iter(size)).replace("_", "-")
            raise StarnavError(f"--camera gives the lens and the image size: drop {option}")
        camera = load_camera(args.camera)
        size = {
            "camera": camera_items(camera),
            "fov_deg": camera.fov_deg,
            "width": camera.width,
            "height": camera.height,
        }
    config = EvalConfig(
        **size,
        mag_limit=args.mag_limit,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        mag_noise=args.mag_noise,
        algorithm=args.algorithm,
        algorithm_options=tuple(algorithm_options(args).items()),
        sigma_px=args.sigma_px,
        max_false_match_probability=args.max_false_match_probability,
        seed=args.seed,
        kinds=parse_kinds(args.kind or ["true"]),
    )
    check_parent_dir("--frames-csv", args.frames_csv)
    check_parent_dir("--sky-map", args.sky_map)
    if drawn == "grid":
        boresights = grid_boresights(amount, seed=args.seed)
        sampling = f"{len(boresights)} boresights on a {amount:g}° RA/Dec grid"
    else:
        boresights = uniform_boresights(amount, seed=args.seed)
        sampling = f"{len(boresights)} boresights uniform on the sphere"
    summary, results = evaluate(config, boresights, workers=args.workers, dask_address=args.dask)
    if args.frames_csv:
        write_frames_csv(results, args.frames_csv)
    if args.sky_map:
        plot_sky_map(results, args.sky_map, title=describe(config, sampling))
    if args.json:
        config_dict = {
            **asdict(config),
            "algorithm_options": dict(config.algorithm_options),
            "camera": config.make_camera().to_dict(),
        }
        print_json({**summary.to_dict(), "config": config_dict, "sampling": sampling})
    else:
        print(markdown(config, sampling, summary))
    return EXIT_OK


def choose_sampling(
    sampling: str | None, frames: int | None, grid_step_deg: float | None
) -> tuple[str, float]:
    """The boresights of --sampling, --frames and --grid-step-deg: ("grid", step in degrees)
    or ("uniform", frames). Without --sampling, --frames means uniform and otherwise the grid
    is run; an option of the other sampling is a one-line error (never silently ignored)."""
    if sampling is None:
        if frames is not None and grid_step_deg is not None:
            raise StarnavError(
                "--frames is for --sampling uniform, --grid-step-deg for --sampling grid: give one"
            )
        sampling = "uniform" if frames is not None else "grid"
    if sampling == "grid":
        if frames is not None:
            raise StarnavError(
                "--frames is for --sampling uniform; the grid's size is --grid-step-deg"
            )
        return "grid", DEFAULT_GRID_STEP_DEG if grid_step_deg is None else grid_step_deg
    if grid_step_deg is not None:
        raise StarnavError(
            "--grid-step-deg is for --sampling grid; uniform sampling takes --frames"
        )
    return "uniform", DEFAULT_FRAMES if frames is None else frames
