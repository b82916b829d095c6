"""``starnav demo``: simulate a random frame, identify it and compare with the truth."""

from __future__ import annotations

import argparse
import time

import numpy as np

from starnav.api import get_database, make_camera, solve_stars
from starnav.catalog import load_catalog
from starnav.cli.common import (
    EXIT_NOT_SOLVED,
    EXIT_OK,
    Subparsers,
    add_frame_errors,
    count,
    finite,
    positive_int,
)
from starnav.cli.output import print_json
from starnav.errors import StarnavError
from starnav.results import SolveResult
from starnav.simulate import SimulatedFrame, simulate_frame


def add_parser(subparsers: Subparsers) -> None:
    """The ``demo`` command and its options."""
    p = subparsers.add_parser(
        "demo", help="simulate a random frame, identify it, compare with truth"
    )
    p.add_argument("--seed", type=count, help="random seed (default: random)")
    p.add_argument(
        "--fov-deg",
        type=finite,
        default=12.0,
        help="horizontal field of view (degrees; default %(default)g)",
    )
    p.add_argument(
        "--width", type=positive_int, default=512, help="image width (px; default %(default)s)"
    )
    add_frame_errors(p, noise_px=0.5, false_stars=2, missing_frac=0.1, mag_noise=False)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Set up (catalog, database), simulate, solve, compare."""
    rng = np.random.default_rng(args.seed)
    camera = make_camera(width=args.width, height=None, fov_deg=args.fov_deg)
    t0 = time.perf_counter()
    catalog = load_catalog(None)
    database = get_database(catalog, camera)
    setup_s = time.perf_counter() - t0
    frame = simulate_frame(
        catalog,
        camera,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        seed=rng,
    )
    if len(frame.xy) < 3:
        raise StarnavError(
            f"the simulated {args.fov_deg:g}° field holds only {len(frame.xy)} stars: "
            "choose a wider field of view"
        )
    result = solve_stars(
        frame.xy,
        width=camera.width,
        fov_deg=args.fov_deg,
        brightness=frame.brightness,
        catalog=catalog,
        sigma_px=max(args.noise_px, 0.1),
    )
    s = result.solution
    if args.json:
        print_json(
            {
                "truth": frame.to_dict(),
                "solution": result.to_dict(None, frame.xy),
                "comparison": frame.compare(s),
                "database_bytes": database.nbytes,
                "setup_s": setup_s,
            }
        )
    else:
        print(
            f"catalog: {catalog.name} ({len(catalog)} stars); pair database "
            f"{database.nbytes / 1e6:.1f} MB, built in {database.build_s:.2f} s"
            f"{' (loaded from cache)' if database.from_cache else ''}; setup {setup_s:.2f} s"
        )
        _print_comparison(args, frame, result)
    return EXIT_OK if s else EXIT_NOT_SOLVED


def _print_comparison(args: argparse.Namespace, frame: SimulatedFrame, result: SolveResult) -> None:
    """The frame, truth and answer side by side, and the errors."""
    truth, camera, s = frame.to_dict(), frame.camera, result.solution
    print(
        f"simulated {camera.fov_deg:g}° / {camera.width} px frame: {truth['n_points']} points "
        f"({truth['n_false']} false), noise {args.noise_px:g} px, "
        f"{args.missing_frac:.0%} of {truth['n_in_view']} stars dropped"
    )
    print(f"{'':10}{'RA (°)':>12}{'Dec (°)':>12}{'roll (°)':>12}{'parity':>8}")
    print(
        f"{'truth':10}{truth['ra_deg']:12.5f}{truth['dec_deg']:12.5f}"
        f"{truth['roll_deg']:12.4f}{truth['parity']:8d}"
    )
    if s is None:
        print(f"{'solved':10} not solved: {result.reason}")
        return
    right = frame.compare(s)
    print(f"{'solved':10}{s.ra_deg:12.5f}{s.dec_deg:12.5f}{s.roll_deg:12.4f}{s.parity:8d}")
    print(
        f"error: boresight {right['boresight_error_arcsec']:.1f}″ "
        f"(1σ estimate {s.sigma_boresight_arcsec:.1f}″), roll {right['roll_error_arcsec']:.1f}″ "
        f"(1σ {s.sigma_roll_arcsec:.1f}″); ids {right['ids_correct']} right, "
        f"{right['ids_wrong']} wrong, {right['false_stars_refused']} false stars refused; "
        f"{s.time_ms:.1f} ms"
    )
