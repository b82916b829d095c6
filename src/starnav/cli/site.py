"""Where an image was taken, and a fisheye's scale, on the command line: ``--lat --lon
--height-m`` (with the time, ``cli.field``'s ``--utc``: the sky above the horizon and the
planets) and ``--circle-fov-deg`` / ``--focal-mm --pixel-um`` (``add_sky_options``), turned
into solve options (``sky_options``)."""

from __future__ import annotations

import argparse

from starnav.cli.common import finite
from starnav.errors import StarnavError


def add_sky_options(p: argparse.ArgumentParser) -> None:
    """A fisheye's scale (the image circle's field, or the focal length) and the site and time
    (the sky above the horizon, and the planets)."""
    sky = p.add_argument_group("fisheye and all-sky cameras")
    sky.add_argument(
        "--circle-fov-deg",
        type=finite,
        help="a fisheye's field across its image circle (degrees, e.g. 180; searched ±5 %%; "
        "default: 140-230 scanned from 180): the circle is found in the image",
    )
    sky.add_argument(
        "--focal-mm",
        type=finite,
        help="a fisheye's focal length (mm; with --pixel-um; searched ±5 %%; default: not "
        "known, scanned)",
    )
    sky.add_argument(
        "--pixel-um",
        type=finite,
        help="the sensor's pixel pitch (µm, as binned; default: not known)",
    )
    sky.add_argument(
        "--lat",
        type=finite,
        help="the site's latitude (degrees, north positive; default: FITS SITELAT / OBSGEO-B)",
    )
    sky.add_argument(
        "--lon",
        type=finite,
        help="the site's longitude (degrees, east positive; default: FITS SITELONG)",
    )
    sky.add_argument(
        "--height-m", type=finite, default=0.0, help="the site's height (m; default %(default)g)"
    )


def sky_options(args: argparse.Namespace) -> dict:
    """The ``SolveOptions`` fields of ``add_sky_options``'s arguments; a one-line error for a
    site without both coordinates or a focal length without the pixel pitch."""
    return {
        "circle_fov_deg": args.circle_fov_deg,
        "focal_px": _focal_px(args),
        "site": site_of(args),
        "utc": getattr(args, "utc", None),
    }


def site_of(args: argparse.Namespace) -> tuple[float, float, float] | None:
    """(latitude, longitude, height) of ``--lat``, ``--lon``, ``--height-m`` (degrees, m), or
    None without them; a one-line error for half a site or one that cannot be."""
    if (args.lat is None) != (args.lon is None):
        raise StarnavError("give both --lat and --lon (the site), or neither")
    if args.lat is None:
        return None
    from starnav.catalog.sky import Site

    Site(args.lat, args.lon, args.height_m)  # checks it
    return (args.lat, args.lon, args.height_m)


def _focal_px(args: argparse.Namespace) -> float | None:
    """--focal-mm over --pixel-um (px); a one-line error when one comes without the other."""
    if (args.focal_mm is None) != (args.pixel_um is None):
        raise StarnavError("--focal-mm and --pixel-um go together (the focal length in px)")
    if args.focal_mm is None:
        return None
    if not (args.focal_mm > 0 and args.pixel_um > 0):
        raise StarnavError("--focal-mm and --pixel-um must be positive")
    return 1e3 * args.focal_mm / args.pixel_um
