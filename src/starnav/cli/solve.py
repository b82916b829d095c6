"""``starnav solve``: an image file (FITS, PNG, JPEG, TIFF) to a verified attitude, with the
field of view unknown, roughly known or calibrated; optionally a WCS header and a picture."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from starnav.cli.common import (
    EXIT_NOT_SOLVED,
    EXIT_OK,
    Subparsers,
    add_fov_search,
    finite,
    int_at_least,
    png_path,
    print_json,
    print_solution,
)
from starnav.errors import StarnavError
from starnav.image import DEFAULT_MAX_STARS, FISHEYE_MAX_STARS, ImageSolveResult

WCS_SUFFIXES = (".fits", ".fit", ".fts", ".wcs")


def add_parser(subparsers: Subparsers) -> None:
    """The ``solve`` command and its options."""
    p = subparsers.add_parser(
        "solve", help="solve an image file (FITS, PNG, JPEG, TIFF): FOV may be unknown"
    )
    p.add_argument("image", help="image file")
    add_fov_search(
        p,
        "horizontal FOV, roughly (searched ±5 %%)",
        camera_help="camera file (any lens model, e.g. from 'starnav calibrate'; its focal "
        "length searched ±1 %%)",
    )
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
        "--sigma-px", type=finite, default=1.0, help="centroid error assumed (default 1 px)"
    )
    p.add_argument("--parity", type=int, choices=(1, -1), help="force parity (default: find)")
    p.add_argument(
        "--catalog", help="CSV catalog id,ra_deg,dec_deg,mag (default: embedded Hipparcos)"
    )
    p.add_argument("--epoch", type=finite, help="year for Hipparcos proper motion")
    p.add_argument(
        "--wcs",
        metavar="FITS",
        help="write a FITS WCS header here (the lens model's projection: pinhole TAN or "
        "TAN-SIP, equidistant ARC, stereographic STG, equisolid ZEA, orthographic SIN, "
        "kannala-brandt ARC-SIP)",
    )
    p.add_argument(
        "--annotate", metavar="PNG", type=png_path, help="draw the solved image into this PNG"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Read, detect, solve; write the WCS and the picture; print the answer."""
    from starnav.detect.read import read_image
    from starnav.image import solve_image

    if args.wcs and not args.wcs.lower().endswith(WCS_SUFFIXES):
        raise StarnavError(
            f"--wcs writes a FITS file: give a name ending in .fits (or .fit, .fts, .wcs), "
            f"got {args.wcs!r}"
        )
    t0 = time.perf_counter()
    pixels = read_image(args.image)
    read_ms = (time.perf_counter() - t0) * 1e3
    res = solve_image(
        pixels,
        fov_deg=args.fov_deg,
        fov_range_deg=tuple(args.fov_range),
        camera=args.camera,
        lens=args.lens,
        fit_distortion=args.fit_distortion,
        max_stars=args.max_stars,
        threshold_sigma=args.threshold_sigma,
        sigma_px=args.sigma_px,
        catalog=args.catalog,
        epoch_year=args.epoch,
        parity=args.parity,
    )
    res = replace(res, read_ms=read_ms)  # read here, so the picture can be annotated
    _write_outputs(args, pixels, res)
    if args.json:
        print_json(res.to_dict(args.image))
    else:
        _print_text(res)
    return EXIT_OK if res.solution else EXIT_NOT_SOLVED


def _write_outputs(args: argparse.Namespace, pixels: np.ndarray, res: ImageSolveResult) -> None:
    """--wcs (in the projection of the fitted camera's lens model) and --annotate of a solved
    image, or a note on stderr that there are none."""
    s = res.solution
    if s is not None and args.wcs:
        from starnav.wcs import choose_sip_order, wcs_from_attitude, write_wcs

        order = choose_sip_order(res.camera)
        write_wcs(args.wcs, wcs_from_attitude(s.R_cam_from_icrs, res.camera, sip_order=order))
    if s is not None and args.annotate:
        from starnav.image import annotate_result

        annotate_result(args.annotate, pixels, res)
    if s is None and (args.wcs or args.annotate):
        print("starnav solve: not solved, no WCS or picture written", file=sys.stderr)


def _print_text(res: ImageSolveResult) -> None:
    s, cam = res.solution, res.camera
    if s is None:
        print(
            f"not solved: {res.reason} ({len(res.detections.xy)} stars detected, "
            f"{res.total_ms:.1f} ms)"
        )
        return
    print_solution(s)
    coefficients = "".join(f" {k} {getattr(cam, k):.5f}" for k in cam.coefficients)
    print(
        f"  camera: {cam.model}, FOV {cam.fov_deg:.4f}°,{coefficients}; "
        f"{len(res.detections.xy)} stars detected; "
        f"read {res.read_ms:.1f} ms, detect {res.detect_ms:.1f} ms, solve {res.solve_ms:.1f} ms"
    )
