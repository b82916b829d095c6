"""``starnav simulate``: a frame of centroids from the catalog, written as a star list."""

from __future__ import annotations

import argparse

from starnav.api import make_camera
from starnav.catalog import load_catalog
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_attitude,
    add_camera,
    add_catalog,
    add_frame_errors,
    count,
)
from starnav.cli.output import print_json
from starnav.simulate import simulate_frame, write_frame_csv


def add_parser(subparsers: Subparsers) -> None:
    """The ``simulate`` command and its options."""
    p = subparsers.add_parser("simulate", help="simulate a frame of centroids from the catalog")
    add_attitude(p)
    add_camera(p)
    add_catalog(p)
    add_frame_errors(p, noise_px=0.0, false_stars=0, missing_frac=0.0)
    p.add_argument("--seed", type=count, help="random seed (default: random)")
    p.add_argument("-o", "--output", required=True, help="frame CSV to write")
    p.add_argument("--json", action="store_true", help="print the truth as one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Simulate the frame, write it, print the truth."""
    camera = make_camera(width=args.width, height=args.height, fov_deg=args.fov_deg)
    catalog = load_catalog(args.catalog, mag_limit=args.mag_limit, epoch_year=args.epoch)
    frame = simulate_frame(
        catalog,
        camera,
        ra_deg=args.ra_deg,
        dec_deg=args.dec_deg,
        roll_deg=args.roll_deg,
        parity=args.parity,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        mag_noise=args.mag_noise,
        seed=args.seed,
    )
    write_frame_csv(args.output, frame)
    truth = frame.to_dict()
    if args.json:
        print_json({"output": args.output, **truth})
    else:
        print(
            f"wrote {truth['n_points']} points ({truth['n_false']} false) to {args.output}: "
            f"RA {truth['ra_deg']:.4f}° Dec {truth['dec_deg']:+.4f}° roll "
            f"{truth['roll_deg']:.3f}° parity {truth['parity']:+d}"
        )
    return EXIT_OK
