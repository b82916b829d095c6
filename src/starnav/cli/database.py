"""``starnav database``: build (or load) the pair database of a camera and report it."""

from __future__ import annotations

import argparse

import numpy as np

from starnav.api import get_database, make_camera
from starnav.catalog import load_catalog
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_camera,
    add_catalog,
)
from starnav.cli.output import print_json


def add_parser(subparsers: Subparsers) -> None:
    """The ``database`` command and its options."""
    p = subparsers.add_parser("database", help="build (or load) the pair database and report it")
    add_camera(p)
    add_catalog(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Build or load the database; print its size, build time and place."""
    camera = make_camera(width=args.width, height=args.height, fov_deg=args.fov_deg)
    catalog = load_catalog(args.catalog, mag_limit=args.mag_limit, epoch_year=args.epoch)
    db = get_database(catalog, camera)
    info = {
        "catalog": catalog.name,
        "stars": len(catalog),
        "max_angle_deg": float(np.degrees(db.max_angle_rad)),
        "pairs": len(db.pair_a),
        "bytes": db.nbytes,
        "build_s": db.build_s,
        "from_cache": db.from_cache,
        "path": str(db.path) if db.path else None,
    }
    if args.json:
        print_json(info)
    else:
        print(
            f"{info['catalog']}: {info['stars']} stars, {info['pairs']} pairs up to "
            f"{info['max_angle_deg']:g}°, {info['bytes'] / 1e6:.2f} MB, built in "
            f"{info['build_s']:.2f} s{' (loaded from cache)' if db.from_cache else ''}"
            f"{'; ' + info['path'] if info['path'] else ''}"
        )
    return EXIT_OK
