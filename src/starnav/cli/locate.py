"""``starnav locate`` (latitude, longitude and heading from star cameras, gravity and UTC) and
``starnav locate-study`` (the sensitivity of the fix to tilt and star errors)."""

from __future__ import annotations

import argparse
import math
from dataclasses import asdict

from starnav.api import DEFAULT_SIGMA_PX
from starnav.cli.common import (
    EXIT_NOT_SOLVED,
    EXIT_OK,
    Subparsers,
    add_catalog,
    check_parent_dir,
    count,
    finite,
    png_path,
    positive_int,
)
from starnav.cli.output import print_json
from starnav.errors import StarnavError


def add_parser(subparsers: Subparsers) -> None:
    """The ``locate`` and ``locate-study`` commands and their options."""
    p = subparsers.add_parser(
        "locate", help="latitude, longitude and heading from star cameras, gravity and UTC"
    )
    p.add_argument(
        "observation", help="observation JSON: star lists or image files (see docs/locate.md)"
    )
    p.add_argument(
        "--sigma-px",
        type=finite,
        default=DEFAULT_SIGMA_PX,
        help=f"centroid error, 1 sigma (px; default {DEFAULT_SIGMA_PX:g})",
    )
    add_catalog(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)

    p = subparsers.add_parser(
        "locate-study", help="sensitivity of the fix to tilt and star errors (Monte Carlo)"
    )
    p.add_argument("--trials", type=positive_int, default=50, help="per setting (default 50)")
    p.add_argument(
        "--fov-deg",
        type=finite,
        default=20.0,
        help="camera FOV (degrees; default %(default)g)",
    )
    p.add_argument("--seed", type=count, default=0, help="random seed (default %(default)s)")
    p.add_argument(
        "--upward-camera",
        metavar="CAMERA_JSON",
        help="compare with one camera of this camera file looking straight up",
    )
    p.add_argument("--plot", metavar="PNG", type=png_path, help="draw the two curves here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run_study)


def run(args: argparse.Namespace) -> int:
    """The fix of one observation file (exit 1 when there is none)."""
    from starnav.navigation import FixError, locate, read_observation

    if not args.sigma_px > 0:
        raise StarnavError(f"--sigma-px must be positive, got {args.sigma_px:g}")
    if args.epoch is not None:
        raise StarnavError("--epoch is taken from the observation's utc for locate")
    observation = read_observation(args.observation)
    try:
        fix = locate(
            observation, catalog=args.catalog, mag_limit=args.mag_limit, sigma_px=args.sigma_px
        )
    except FixError as exc:
        if args.json:
            print_json({"solved": False, "reason": str(exc), "utc": observation.utc})
        else:
            print(f"no fix: {exc}")
        return EXIT_NOT_SOLVED
    when = {"utc": observation.utc, "utc_source": observation.utc_source}
    if args.json:
        print_json({"solved": True, "reason": None, **when, **fix.to_dict()})
        return EXIT_OK
    print(f"fix: lat {fix.lat_deg:+.6f}°  lon {fix.lon_deg:+.6f}°  heading {fix.azimuth_deg:.4f}°")
    if observation.utc_source != "file":
        print(f"  utc {observation.utc} from the {observation.utc_source}")
    print(
        f"  1σ ellipse {fix.ellipse_major_m:.1f} x {fix.ellipse_minor_m:.1f} m (major axis at "
        f"{fix.ellipse_angle_deg:.0f}° from North), heading 1σ {fix.sigma_azimuth_arcsec:.2f}″, "
        f"{fix.n_stars} stars, rms {fix.rms_arcsec:.2f}″, {fix.time_ms:.0f} ms"
    )
    if fix.gravity_sigma_deg > 0:
        print(
            f"  gravity known to {fix.gravity_sigma_deg:g}° (1σ) adds "
            f"{fix.gravity_north_m / 1e3:.1f} km north, {fix.gravity_east_m / 1e3:.1f} km east (1σ)"
        )
    else:
        print("  (stars only: a tilt error of the gravity vector adds about 31 m per arcsecond)")
    for view, c in zip(observation.cameras, fix.cameras, strict=True):
        status = (
            f"{c.stars_used} of {c.n_points} points identified, boresight RA {c.ra_deg:.3f}° "
            f"Dec {c.dec_deg:+.3f}°"
            if c.stars_used
            else f"not used: {c.reason}"
        )
        if c.stars_used and view.fov_deg is None and c.focal_px:
            status += (
                f", FOV searched: {math.degrees(2 * math.atan(view.width / 2 / c.focal_px)):.3f}°"
            )
        print(f"  {c.name}: {status}")
    return EXIT_OK


def run_study(args: argparse.Namespace) -> int:
    """The Monte Carlo sensitivity study: tables (or JSON) and, with --plot, the curves."""
    from starnav.camera import load_camera
    from starnav.studies.locate import format_tables, plot_study, run_locate_study, upward_camera

    if not 1.0 <= args.fov_deg <= 60.0:
        raise StarnavError(f"--fov-deg must be between 1 and 60, got {args.fov_deg:g}")
    check_parent_dir("--plot", args.plot)
    compare = (upward_camera(load_camera(args.upward_camera)),) if args.upward_camera else ()
    tables = run_locate_study(
        trials=args.trials, fov_deg=args.fov_deg, seed=args.seed, compare=compare
    )
    if args.plot:
        plot_study(tables, args.plot)
    if args.json:
        print_json({name: [asdict(r) for r in rows] for name, rows in tables.items()})
    else:
        print(format_tables(tables))
    return EXIT_OK
