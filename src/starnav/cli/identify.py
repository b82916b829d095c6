"""``starnav identify``: a star list (CSV), or a directory of them, to a verified attitude."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from starnav.api import (
    DEFAULT_SIGMA_PX,
    SolveOptions,
    solve_stars,
)
from starnav.camera import model_class
from starnav.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_SOLVED,
    EXIT_OK,
    Subparsers,
    add_acceptance,
    add_algorithm,
    add_catalog,
    add_deep_mag_limit,
    add_time_budget,
    algorithm_options,
    finite,
    png_path,
    positive_int,
)
from starnav.cli.field import add_fov_search, check_fov
from starnav.cli.output import print_json, print_solution
from starnav.cli.plain import plain_python, solve_plain
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll
from starnav.identify import DEFAULT_ALGORITHM
from starnav.pipeline.options import facts_model
from starnav.pipeline.star_files import FileResult, read_star_files, solve_star_files
from starnav.results import SolveResult
from starnav.starlist import read_star_csv


def add_parser(subparsers: Subparsers) -> None:
    """The ``identify`` command and its options."""
    p = subparsers.add_parser("identify", help="identify a star list (CSV) and solve the attitude")
    p.add_argument(
        "stars",
        help="CSV with header: x,y and optionally label, flux or mag; or a directory of them",
    )
    add_fov_search(
        p,
        "horizontal field of view",
        camera_help="camera file (any lens model; width and height come from it)",
    )
    p.add_argument("--width", type=positive_int, help="image width (px; or give --camera)")
    p.add_argument("--height", type=positive_int, help="image height (px; default: width)")
    add_catalog(p)
    add_deep_mag_limit(p)
    p.add_argument(
        "--sigma-px",
        type=finite,
        help=f"centroid error, 1 sigma (px): sets the tolerances (default: not known; the "
        f"tolerances allow {DEFAULT_SIGMA_PX:g} px, the false-match probability takes the sigma "
        "the stars fit best)",
    )
    add_acceptance(p)
    p.add_argument("--fit-focal", action="store_true", help="fit the focal length too")
    add_algorithm(p)
    p.add_argument(
        "--workers", type=positive_int, help="a directory: processes (default: all cores)"
    )
    p.add_argument(
        "--prior-ra-deg",
        type=finite,
        help="tracking: previous boresight RA (degrees; default: none, lost in space)",
    )
    p.add_argument(
        "--prior-dec-deg",
        type=finite,
        help="tracking: previous boresight Dec (degrees; default: none)",
    )
    p.add_argument(
        "--prior-roll-deg", type=finite, help="tracking: previous roll (degrees; default: none)"
    )
    p.add_argument(
        "--prior-sigma-deg",
        type=finite,
        default=1.0,
        help="tracking: 1-sigma error of the previous attitude (degrees; default %(default)g)",
    )
    p.add_argument(
        "--plot", metavar="PNG", type=png_path, help="draw the identified map into this PNG file"
    )
    add_time_budget(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def prior_attitude(args: argparse.Namespace) -> np.ndarray | None:
    """The tracking prior of --prior-ra-deg/--prior-dec-deg/--prior-roll-deg (all or none)."""
    given = [args.prior_ra_deg, args.prior_dec_deg, args.prior_roll_deg]
    if all(v is None for v in given):
        return None
    if any(v is None for v in given):
        raise StarnavError(
            "tracking needs all of --prior-ra-deg, --prior-dec-deg, --prior-roll-deg"
        )
    if not -90.0 <= args.prior_dec_deg <= 90.0:
        raise StarnavError(f"--prior-dec-deg must be within ±90, got {args.prior_dec_deg:g}")
    return attitude_from_radec_roll(*given, args.parity or 1)


def solve_options(args: argparse.Namespace) -> SolveOptions:
    """The solve options ``identify`` takes from its command line (one list or many)."""
    if args.camera is None and args.width is None:
        raise StarnavError("give --width (and --fov-deg or --fov-range), or a --camera file")
    return SolveOptions(
        fov_deg=args.fov_deg,
        fov_range_deg=args.fov_range and tuple(args.fov_range),
        camera=args.camera,
        lens=args.lens,
        catalog=args.catalog,
        mag_limit=args.mag_limit,
        epoch_year=args.epoch,
        parity=args.parity,
        sigma_px=args.sigma_px,
        fit_focal=args.fit_focal,
        max_false_match_probability=args.max_false_match_probability,
        algorithm=args.algorithm,
        algorithm_options=algorithm_options(args),
        time_budget_s=args.time_budget,
        deep_mag_limit=args.deep_mag_limit,
    )


def _check_fov_search(args: argparse.Namespace, prior: np.ndarray | None) -> None:
    """The options the FOV search (no --fov-deg) cannot take."""
    why = (
        "without it the FOV search picks the catalog depth of each FOV band and fits the "
        "focal length"
    )
    # the focal scan takes a catalog depth
    scanned = model_class(facts_model(args.lens)).scans_focal
    if prior is not None or args.algorithm != DEFAULT_ALGORITHM or (args.mag_limit and not scanned):
        raise StarnavError(f"--prior-*, --algorithm and --mag-limit need --fov-deg ({why})")
    if args.algorithm_option:
        raise StarnavError(f"--algorithm-option needs --fov-deg ({why})")


def run(args: argparse.Namespace) -> int:
    """Identify one star list, or every ``*.csv`` of a directory."""
    check_fov(args, args.lens, exact=True)
    source = Path(args.stars)
    if source.is_dir():
        return run_directory(args, source)
    stars = read_star_csv(args.stars)
    prior = prior_attitude(args)
    if args.fov_deg is None and args.camera is None:
        _check_fov_search(args, prior)
    options = replace(solve_options(args), prior_sigma_deg=args.prior_sigma_deg)
    if plain_python(args, len(stars.xy)):
        result = solve_plain(stars, options, width=args.width, height=args.height, prior=prior)
    else:
        result = solve_stars(stars, options, width=args.width, height=args.height, prior=prior)
    _plot(args, result)
    s = result.solution
    if args.json:
        print_json(result.to_dict(stars.labels, stars.xy))
    elif s:
        print_solution(s)
    else:
        print(f"not solved: {result.reason} ({result.time_ms:.1f} ms)")
    return EXIT_OK if s else EXIT_NOT_SOLVED


def _plot(args: argparse.Namespace, result: SolveResult) -> None:
    """--plot: the identified map, or a note on stderr that there is none."""
    if not args.plot:
        return
    s = result.solution
    if s is None:
        print(f"starnav identify: not solved, no plot written to {args.plot}", file=sys.stderr)
        return
    from starnav.output.plot import plot_solution

    plot_solution(s, s.camera, result.catalog, args.plot)


def run_directory(args: argparse.Namespace, source: Path) -> int:
    """Every star list of a directory on all cores: one line (or JSON line) per file."""
    from tqdm import tqdm

    paths = sorted(source.glob("*.csv"))
    if not paths:
        raise StarnavError(f"{args.stars!r} holds no .csv star lists")
    if args.plot or prior_attitude(args) is not None:
        raise StarnavError("--plot and --prior-* take one star list, not a directory")
    if args.fov_deg is None and args.camera is None:
        raise StarnavError("a directory of star lists needs --fov-deg or --camera")
    files = read_star_files(paths)
    options = solve_options(args)
    t0 = time.perf_counter()
    with tqdm(total=len(files.lists), desc="identify", unit="file", file=sys.stderr) as bar:
        results = solve_star_files(
            files,
            options,
            width=args.width,
            height=args.height,
            workers=args.workers,
            progress=bar.update,
        )
    wall = time.perf_counter() - t0
    for r in results:
        if args.json:
            print_json(r.to_dict())
        else:
            print(_file_line(r))
    print(
        f"{len(paths)} files in {wall:.2f} s ({len(files.lists) / max(wall, 1e-9):.0f} frames/s)",
        file=sys.stderr,
    )
    return max((_exit_status(r) for r in results), default=EXIT_OK)


def _file_line(r: FileResult) -> str:
    s = r.solution
    if s is None:
        return f"{r.path}: not solved: {r.reason}"
    return (
        f"{r.path}: RA {s.ra_deg:.5f}° Dec {s.dec_deg:+.5f}° roll {s.roll_deg:.4f}° parity "
        f"{s.parity:+d}, {s.n_matched} stars, {r.time_ms:.1f} ms"
    )


def _exit_status(r: FileResult) -> int:
    if r.bad_input:
        return EXIT_BAD_INPUT
    return EXIT_OK if r.solution is not None else EXIT_NOT_SOLVED
