"""What the commands share: exit codes, the parser that reports a mistake in one line (both from
``starnav.cli.parser``, kept importable from here), the argument types and the option groups
several commands take (output: ``starnav.cli.output``)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from starnav.catalog import DEFAULT_MAG_LIMIT
from starnav.cli.parser import EXIT_BAD_INPUT, EXIT_NOT_SOLVED, EXIT_OK, Parser  # noqa: F401
from starnav.errors import StarnavError
from starnav.identify import ALGORITHMS, DEFAULT_ALGORITHM
from starnav.identify.options import check_algorithm_options
from starnav.pipeline.deep import DEEP_OFF
from starnav.pipeline.options import DEFAULT_MAX_FALSE_MATCH_PROBABILITY
from starnav.runtime.budget import DEFAULTS

# --triangle-selection is short for --algorithm-option selection=...: the algorithms that
# declare a "selection" option (today triangle) get it unless the long form sets it
SHORTHANDS = {"triangle_selection": "selection"}


class Subparsers(Protocol):
    """What a command module's ``add_parser`` needs of ``add_subparsers()``."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser: ...


def finite(text: str) -> float:
    """Argument type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return value


def int_at_least(minimum: int) -> Callable[[str], int]:
    """Argument type: a whole number >= ``minimum``."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        return value

    return convert


positive_int = int_at_least(1)
count = int_at_least(0)


def seconds(text: str) -> float:
    """Argument type: seconds > 0, or "none" (``math.inf``: no limit)."""
    value = math.inf if text.strip().lower() == "none" else finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text}")
    return value


def add_acceptance(p: argparse.ArgumentParser) -> None:
    """--parity and --max-false-match-probability: what a star-list solve may answer."""
    p.add_argument("--parity", type=int, choices=(1, -1), help="force parity (default: find)")
    p.add_argument("--max-false-match-probability", type=finite,
                   default=DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
                   help="refuse less certain answers (default %(default)g)")  # fmt: skip


def add_time_budget(p: argparse.ArgumentParser) -> None:
    """--time-budget (``starnav.runtime.budget``)."""
    p.add_argument(
        "--time-budget",
        type=seconds,
        metavar="SECONDS",
        help=f"give up after this many seconds of searching (default {DEFAULTS}; 'none': no limit)",
    )


def add_dask(p: argparse.ArgumentParser, what: str) -> None:
    """--dask ADDRESS: run ``what`` on a Dask cluster (``starnav.runtime.pools``)."""
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help=f"run {what} on this Dask scheduler (e.g. tcp://host:8786), or 'local' for a "
        "LocalCluster",
    )


def png_path(text: str) -> str:
    """Argument type: the name of a PNG file to write."""
    if not text.lower().endswith(".png"):
        raise argparse.ArgumentTypeError(
            f"the plot is a PNG file: give a name ending in .png, got {text!r}"
        )
    return text


def name_value(text: str) -> tuple[str, int | float | str]:
    """Argument type: NAME=VALUE, the value read as a whole number, else a finite number,
    else text."""
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    for kind in (int, float):
        try:
            number = kind(value)
        except ValueError:
            continue
        if math.isfinite(number):
            return name.strip(), number
    return name.strip(), value


def check_parent_dir(option: str, path: str | None) -> None:
    """Refuse an output file whose directory does not exist, before any work."""
    if path and not Path(path).resolve().parent.is_dir():
        raise StarnavError(f"{option}: the directory of {path!r} does not exist")


def add_camera(p: argparse.ArgumentParser, *, required: bool = True) -> None:
    """--fov-deg, --width, --height."""
    p.add_argument("--fov-deg", type=finite, required=required, help="horizontal FOV (degrees)")
    p.add_argument("--width", type=positive_int, required=required, help="image width (px)")
    p.add_argument("--height", type=positive_int, help="image height (px; default: width)")


def add_attitude(p: argparse.ArgumentParser) -> None:
    """--ra-deg, --dec-deg, --roll-deg (each random when left out) and --parity."""
    p.add_argument("--ra-deg", type=finite, help="boresight RA (degrees; default: random)")
    p.add_argument("--dec-deg", type=finite, help="boresight Dec (degrees; default: random)")
    p.add_argument("--roll-deg", type=finite, help="roll (degrees; default: random)")
    p.add_argument(
        "--parity", type=int, choices=(1, -1), default=1, help="-1: a mirrored image (default 1)"
    )


def add_catalog(p: argparse.ArgumentParser) -> None:
    """--catalog, --mag-limit, --epoch."""
    p.add_argument(
        "--catalog",
        help='"gaia" (the embedded Gaia DR3, G <= 10), or a CSV or FITS table of RA, Dec '
        "(degrees) and a magnitude, id optional (id,ra_deg,dec_deg,mag or Gaia / VizieR "
        "names); default: the embedded Hipparcos, and Gaia DR3 for fields under ~3°",
    )
    p.add_argument(
        "--mag-limit",
        type=finite,
        help=f"faintest catalog magnitude used (Hipparcos: default {DEFAULT_MAG_LIMIT:g}, deeper "
        "when a known field's identification needs it; a CSV: all its stars)",
    )
    p.add_argument("--epoch", type=finite, help="year of Hipparcos proper motion (default: now)")


def add_deep_mag_limit(p: argparse.ArgumentParser) -> None:
    """--deep-mag-limit (the deep stage, ``starnav.pipeline.deep``)."""
    p.add_argument(
        "--deep-mag-limit",
        type=_deep_mag,
        metavar="MAG",
        help="after the fit, match every star to the catalog down to this magnitude: ids of "
        "faint stars, each with its match probability and a flag for unresolved doubles; "
        "'off': never (default: Hp 12 for a known field of the embedded Hipparcos with pixels "
        "fine enough, as a 6° star tracker's; else off)",
    )


def _deep_mag(text: str) -> float | str:
    """Argument type of --deep-mag-limit: a finite number or ``DEEP_OFF``."""
    return DEEP_OFF if text.strip().lower() == DEEP_OFF else finite(text)


def add_algorithm(p: argparse.ArgumentParser) -> None:
    """--algorithm, its options by name (--algorithm-option) and --triangle-selection."""
    p.add_argument(
        "--algorithm",
        choices=list(ALGORITHMS),
        default=DEFAULT_ALGORITHM,
        help="identification algorithm (default %(default)s)",
    )
    p.add_argument(
        "--algorithm-option",
        action="append",
        type=name_value,
        metavar="NAME=VALUE",
        help="an option of the algorithm by name, e.g. selection=brightest for triangle "
        "(repeatable; VALUE is read as a number when it is one)",
    )
    p.add_argument(
        "--triangle-selection",
        choices=("brightest", "optimized"),
        default="optimized",
        help="how --algorithm triangle picks its triangles (default %(default)s); short for "
        "--algorithm-option selection=...",
    )


def algorithm_options(args: argparse.Namespace) -> dict[str, object]:
    """The options of ``args.algorithm``: those of --algorithm-option, checked against what
    the algorithm declares, plus the shorthands' values for the options it declares."""
    defaults = {option: getattr(args, dest) for dest, option in SHORTHANDS.items()}
    return check_algorithm_options(args.algorithm, dict(args.algorithm_option or []), defaults)


def add_frame_errors(
    p: argparse.ArgumentParser,
    *,
    noise_px: float,
    false_stars: int,
    missing_frac: float,
    mag_noise: bool = True,
) -> None:
    """--noise-px, --false-stars, --missing-frac (and --mag-noise): the errors of a simulated
    frame, with this command's defaults."""
    p.add_argument(
        "--noise-px",
        type=finite,
        default=noise_px,
        help="centroid noise, 1 sigma (px; default %(default)g)",
    )
    p.add_argument(
        "--false-stars",
        type=count,
        default=false_stars,
        help="false stars added (default %(default)s)",
    )
    p.add_argument(
        "--missing-frac",
        type=finite,
        default=missing_frac,
        help="fraction of the stars dropped (default %(default)g)",
    )
    if mag_noise:
        p.add_argument(
            "--mag-noise",
            type=finite,
            default=0.0,
            help="magnitude noise, 1 sigma (mag; default %(default)g)",
        )
