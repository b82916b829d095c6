"""``starnav pointing`` (the boresight from three known stars) and ``starnav pointing-study``
(the boresight error of classic star arrangements)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    count,
    finite,
    positive_int,
)
from starnav.cli.output import print_json
from starnav.errors import PointingError, StarnavError

if TYPE_CHECKING:
    from starnav.pointing import Pointing


def add_parser(subparsers: Subparsers) -> None:
    """The ``pointing`` and ``pointing-study`` commands and their options."""
    p = subparsers.add_parser(
        "pointing", help="boresight from three known stars (or the best three)"
    )
    p.add_argument("stars", help="CSV: ra_deg,dec_deg and x,y or r_px (optionally label)")
    p.add_argument("--focal-px", type=finite, help="focal length (px); default: solve for it")
    p.add_argument("--width", type=positive_int, help="image width (px), needed with x,y")
    p.add_argument("--height", type=positive_int, help="image height (px; default: width)")
    p.add_argument(
        "--sigma-px",
        type=finite,
        help="centroid noise per axis (px), for the 1σ error (default: none, no 1σ error)",
    )
    p.add_argument(
        "--parity",
        type=int,
        choices=(1, -1),
        help="1, or -1 for a mirrored image (default: found from x,y)",
    )
    p.add_argument(
        "--select-best",
        action="store_true",
        help="from N > 3 stars pick the three with the smallest predicted error",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)

    p = subparsers.add_parser("pointing-study", help="boresight error of classic star arrangements")
    p.add_argument(
        "--fov-deg",
        type=finite,
        default=12.0,
        help="horizontal field of view (degrees, 1-120; default %(default)g)",
    )
    p.add_argument(
        "--width", type=positive_int, default=512, help="image width (px; default %(default)s)"
    )
    p.add_argument(
        "--sigma-px",
        type=finite,
        default=0.5,
        help="centroid noise per axis (px; default %(default)g)",
    )
    p.add_argument(
        "--trials",
        type=positive_int,
        default=20000,
        help="Monte Carlo draws (default %(default)s)",
    )
    p.add_argument("--seed", type=count, default=0, help="random seed (default %(default)s)")
    p.add_argument(
        "--out-dir", default=".", help="where the PNG figures go (default: this directory)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run_study)


def run(args: argparse.Namespace) -> int:
    """The boresight from the three stars given (or the best three of them)."""
    from starnav.pointing import best_triple, three_star
    from starnav.starlist import read_known_stars_csv

    if args.height is not None and args.width is None:
        raise PointingError("--height needs --width too")
    stars = read_known_stars_csv(args.stars)
    height = args.height if args.height is not None else args.width
    rows = np.arange(len(stars.ra_deg))
    if args.select_best:
        if stars.xy is None or args.focal_px is None or args.width is None:
            raise PointingError("--select-best needs x,y columns, --focal-px and --width")
        rows = np.array(
            best_triple(
                stars.ra_deg,
                stars.dec_deg,
                stars.xy,
                focal_px=args.focal_px,
                width=args.width,
                height=height,
            )
        )
    result = three_star(
        stars.ra_deg[rows],
        stars.dec_deg[rows],
        xy=None if stars.xy is None else stars.xy[rows],
        r_px=None if stars.r_px is None else stars.r_px[rows],
        focal_px=args.focal_px,
        width=args.width,
        height=height,
        sigma_px=args.sigma_px,
        parity=args.parity,
    )
    used = [stars.labels[k] for k in rows]
    if args.json:
        print_json({**result.to_dict(), "stars_used": used})
    else:
        _print_pointing(result, used)
    return EXIT_OK


def _print_pointing(p: Pointing, used_labels: list[str]) -> None:
    roll = "-" if p.roll_deg is None else f"{p.roll_deg:.4f}°"
    sigma = "" if p.sigma_boresight_arcsec is None else f", 1σ {p.sigma_boresight_arcsec:.2f}″"
    if p.sigma_focal_px is not None:
        sigma += f", focal 1σ {p.sigma_focal_px:.2f} px"
    print(f"stars used: {', '.join(used_labels)}")
    if p.fit_rms_px is not None:
        sigma += f", parity {p.parity:+d}, angle misfit {p.fit_rms_px:.2f} px"
    print(
        f"boresight: RA {p.ra_deg:.6f}°  Dec {p.dec_deg:+.6f}°  roll {roll}  focal "
        f"{p.focal_px:.3f} px  consistency |d|-1 = {p.consistency:.2e}{sigma}"
    )
    for k, alt in enumerate(p.alternatives, 1):
        print(
            f"  alternative {k}: RA {alt.ra_deg:.6f}°  Dec {alt.dec_deg:+.6f}°  focal "
            f"{alt.focal_px:.3f} px"
        )
    if p.note:
        print(f"note: {p.note}")


def run_study(args: argparse.Namespace) -> int:
    """The arrangement study: a table (or JSON) and PNG figures in --out-dir."""
    from starnav.studies import pointing as study

    if args.sigma_px <= 0:
        raise StarnavError(f"--sigma-px must be positive, got {args.sigma_px:g}")
    if not 1.0 <= args.fov_deg <= 120.0:
        raise StarnavError(
            f"--fov-deg must be between 1 and 120 for the study, got {args.fov_deg:g}"
        )
    if args.width < 64:
        raise StarnavError(f"--width must be at least 64 px for the study, got {args.width}")
    out_dir = Path(args.out_dir)
    if not out_dir.is_dir():
        raise StarnavError(f"--out-dir {args.out_dir!r} is not a directory")
    result = study.run_study(
        fov_deg=args.fov_deg,
        width=args.width,
        sigma_px=args.sigma_px,
        trials=args.trials,
        seed=args.seed,
        out_dir=out_dir,
    )
    if args.json:
        print_json(result.to_dict())
    else:
        print(study.format_table(result))
    return EXIT_OK
