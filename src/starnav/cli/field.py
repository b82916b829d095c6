"""The field of view on the command line: ``--fov-deg`` / ``--fov-range`` / ``--camera`` /
``--lens`` (``add_fov_search``), checked against the lens model before any work
(``check_fov``); with them, the other options of an image's solve (``add_image_solve_options``,
read by ``image_solve_options``), which ``starnav solve`` and ``starnav sky`` take; and
``--utc``, with which a camera file holding a fixed camera's mount predicts the attitude to
track from (``solve_mounted``)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from starnav.camera import MODELS
from starnav.cli.common import add_deep_mag_limit, add_time_budget, finite, int_at_least
from starnav.cli.site import add_sky_options, sky_options
from starnav.errors import StarnavError
from starnav.pipeline.fov import FOV_LIMITS_DEG, LENS_FOV_LIMITS_DEG, UNREAD_SHAPE, search_range
from starnav.pipeline.options import (
    DEFAULT_FOV_RANGE_DEG,
    DEFAULT_LENS_FOV_RANGE_DEG,
    DEFAULT_MAX_STARS,
    FISHEYE,
    FISHEYE_MAX_STARS,
    default_fov_range_deg,
    facts_model,
)

FOV_LIMITS_HELP = "{:g}-{:g} for the pinhole lens, {:g}-{:g} for a fisheye".format(
    *FOV_LIMITS_DEG, *LENS_FOV_LIMITS_DEG
)  # the fields --fov-deg and --fov-range take; a portrait image's pinhole limit is its height's

if TYPE_CHECKING:
    from starnav.navigation.mount import MountPrior
    from starnav.pipeline.image import ImageSolveResult


def add_fov_search(
    p: argparse.ArgumentParser, fov_help: str, *, camera_help: str | None = None, utc=False
) -> None:
    """--fov-deg or --fov-range (the FOV search), or --camera (a camera file) when
    ``camera_help`` is given, and with ``utc`` --utc (a camera file's mount predicts the
    attitude at that time); ``check_fov`` checks them against the lens model."""
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
    if utc:
        p.add_argument(
            "--utc",
            help="UTC of the image (ISO 8601; default: the file's DATE-OBS / EXIF UTC): a "
            "--camera file with a fixed camera's mount ('starnav calibrate --lat --lon') "
            "then predicts the attitude, and the solve tracks from it; with the site (--lat "
            "--lon, or FITS SITELAT/SITELONG) a fisheye is solved on the stars and planets "
            "above the horizon",
        )


def check_fov(args: argparse.Namespace, lens: str, *, exact: bool = False) -> None:
    """--fov-deg, else --fov-range, against ``pipeline.fov.fov_limits_deg(lens)`` before any
    work (the same error from each command); a --camera file brings its own field. ``exact``:
    the command takes --fov-deg as exact (``identify``: through the camera model, whose own
    limits apply, 0-179° for the pinhole), so only a searched --fov-range is checked here.
    --utc (solve's, calibrate's) is for one image."""
    images = getattr(args, "images", None) or [getattr(args, "image", None)]
    if getattr(args, "utc", None) and (len(images) != 1 or Path(images[0]).is_dir()):
        raise StarnavError("--utc is for one image; several take their files' own times")
    if getattr(args, "camera", None) is not None:
        return
    fov_deg = None if exact else args.fov_deg
    if exact and args.fov_deg is not None:
        return
    searched = tuple(args.fov_range) if args.fov_range else default_fov_range_deg(lens)
    search_range(fov_deg, searched, None, facts_model(lens), UNREAD_SHAPE)


def solve_mounted(
    args: argparse.Namespace, path: Path, pixels: np.ndarray, options: dict, read_ms: float
) -> tuple[ImageSolveResult, MountPrior | None]:
    """Solve one image (``solve_image`` with ``options``), from the attitude the ``--camera``
    file's mount predicts at the image's UTC (``--utc``, else the file's) when it has one."""
    from starnav.pipeline.image import solve_image

    mounted = None
    if args.camera:
        from starnav.navigation.mount import mount_prior

        mounted = mount_prior(args.camera, path, args.utc)
    prior = None if mounted is None else mounted.R_cam_from_icrs
    return replace(solve_image(pixels, prior=prior, **options), read_ms=read_ms), mounted


def mounted_dict(res: ImageSolveResult, mounted: MountPrior | None, name: str) -> dict:
    """The answer's JSON, with ``mount_prior`` (the prediction, how far off) when used."""
    out = res.to_dict(name)
    if mounted is not None:
        solved = None if res.solution is None else res.solution.R_cam_from_icrs
        out["mount_prior"] = mounted.to_dict(solved)
    return out


def add_image_solve_options(p: argparse.ArgumentParser) -> None:
    """The options of an image's solve (``_options`` reads them): the field and lens, the
    detection, the catalog, the hints and the time budget; ``solve`` and ``sky`` take them."""
    add_fov_search(
        p,
        "horizontal FOV, roughly: searched ±5 %%",
        camera_help="camera file (any lens model, e.g. from 'starnav calibrate'; its focal "
        "length searched ±1 %%)",
        utc=True,
    )
    add_sky_options(p)
    p.add_argument(
        "--fit-distortion",
        action="store_true",
        help="fit the lens model's coefficients as well (pinhole k1, k2; kannala-brandt k1..k4)",
    )
    p.add_argument(
        "--max-stars",
        type=int_at_least(4),
        help=f"use the brightest this many detections (default {DEFAULT_MAX_STARS}, "
        f"{FISHEYE_MAX_STARS} for a fisheye lens)",
    )
    p.add_argument(
        "--threshold-sigma",
        type=finite,
        default=5.0,
        help="detection threshold over the background noise (default %(default)g)",
    )
    p.add_argument(
        "--sigma-px",
        type=finite,
        help="centroid error, 1 sigma (px; default: not known, estimated as by identify)",
    )
    p.add_argument("--parity", type=int, choices=(1, -1), help="force parity (default: find)")
    p.add_argument(
        "--catalog", help="CSV catalog id,ra_deg,dec_deg,mag (default: embedded Hipparcos)"
    )
    p.add_argument(
        "--epoch", type=finite, help="year of Hipparcos proper motion (default: DATE-OBS, else now)"
    )
    add_deep_mag_limit(p)
    p.add_argument(
        "--no-hints",
        action="store_true",
        help="ignore a FITS header's RA/DEC, pixel scale and DATE-OBS (used by default when "
        "the options do not say otherwise)",
    )
    add_time_budget(p)


def image_solve_options(args: argparse.Namespace) -> dict:
    """The ``solve_image`` options of the command line."""
    from starnav.detect.header import ImageHints

    return dict(
        fov_deg=args.fov_deg,
        fov_range_deg=args.fov_range and tuple(args.fov_range),
        camera=args.camera,
        lens=args.lens,
        fit_distortion=args.fit_distortion,
        max_stars=args.max_stars,
        threshold_sigma=args.threshold_sigma,
        sigma_px=args.sigma_px,
        catalog=args.catalog,
        epoch_year=args.epoch,
        parity=args.parity,
        time_budget_s=args.time_budget,
        deep_mag_limit=args.deep_mag_limit,
        **sky_options(args),
        **({"hints": ImageHints()} if args.no_hints else {}),
    )
