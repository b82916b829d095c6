"""The field of view on the command line: ``--fov-deg`` / ``--fov-range`` / ``--camera`` /
``--lens`` (``add_fov_search``), checked against the lens model before any work
(``check_fov``)."""

from __future__ import annotations

import argparse

from starnav.camera import MODELS
from starnav.cli.common import finite
from starnav.pipeline.fov import fov_limits_deg, search_range
from starnav.pipeline.options import (
    DEFAULT_FOV_RANGE_DEG,
    DEFAULT_LENS_FOV_RANGE_DEG,
    FISHEYE,
    default_fov_range_deg,
    facts_model,
)

FOV_LIMITS_HELP = "{:g}-{:g} for the pinhole lens, {:g}-{:g} for a fisheye".format(
    *fov_limits_deg("pinhole"), *fov_limits_deg("equidistant")
)  # the fields --fov-deg and --fov-range take


def add_fov_search(
    p: argparse.ArgumentParser, fov_help: str, *, camera_help: str | None = None
) -> None:
    """--fov-deg or --fov-range (the FOV search), or --camera (a camera file) when
    ``camera_help`` is given; ``check_fov`` checks them against the lens model."""
    fov = p.add_mutually_exclusive_group()
    fov.add_argument(
        "--fov-deg",
        type=finite,
        help=f"{fov_help} (degrees, {FOV_LIMITS_HELP}; default: not known, --fov-range searched)",
    )
    fov.add_argument(
        "--fov-range",
        nargs=2,
        type=finite,
        metavar=("LO", "HI"),
        help=f"horizontal FOV range searched when the FOV is unknown (degrees, within "
        f"{FOV_LIMITS_HELP}; default {DEFAULT_FOV_RANGE_DEG[0]:g} {DEFAULT_FOV_RANGE_DEG[1]:g}, "
        f"{DEFAULT_LENS_FOV_RANGE_DEG[0]:g} {DEFAULT_LENS_FOV_RANGE_DEG[1]:g} for a fisheye)",
    )
    if camera_help:
        fov.add_argument("--camera", help=camera_help)
        p.add_argument(
            "--lens",
            choices=(*MODELS, FISHEYE),
            default="pinhole",
            help="the lens model when no camera file is given (default %(default)s; fisheye: "
            "each of the common fisheye models, equidistant, equisolid, stereographic and "
            "orthographic); without --fov-deg a fisheye model's focal length is scanned over "
            "--fov-range, or from the image circle found in the image",
        )


def check_fov(args: argparse.Namespace, lens: str, *, exact: bool = False) -> None:
    """--fov-deg, else --fov-range, against ``pipeline.fov.fov_limits_deg(lens)`` before any
    work (the same error from each command); a --camera file brings its own field. ``exact``:
    the command takes --fov-deg as exact (``identify``: through the camera model, whose own
    limits apply, 0-179° for the pinhole), so only a searched --fov-range is checked here."""
    if getattr(args, "camera", None) is not None:
        return
    fov_deg = None if exact else args.fov_deg
    if exact and args.fov_deg is not None:
        return
    searched = tuple(args.fov_range) if args.fov_range else default_fov_range_deg(lens)
    search_range(fov_deg, searched, None, facts_model(lens))
