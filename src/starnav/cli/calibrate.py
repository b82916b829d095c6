"""``starnav calibrate``: focal length, principal point and the lens model's coefficients
from star images."""

from __future__ import annotations

import argparse
import sys

from starnav.camera import MODELS
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    int_at_least,
)
from starnav.cli.field import add_fov_search, check_fov
from starnav.cli.output import print_json


def add_parser(subparsers: Subparsers) -> None:
    """The ``calibrate`` command and its options."""
    p = subparsers.add_parser(
        "calibrate", help="fit focal length, principal point and distortion from star images"
    )
    p.add_argument("images", nargs="+", help="image files of one camera")
    p.add_argument("-o", "--output", required=True, help="camera file (JSON) to write")
    add_fov_search(p, "horizontal FOV, roughly: searched ±5 %%")
    p.add_argument(
        "--model",
        choices=tuple(MODELS),
        default="pinhole",
        help="lens model fitted (default pinhole: k1, k2; kannala-brandt: k1..k4; the other "
        "fisheyes have no coefficients; give a fisheye --fov-deg or e.g. --fov-range 150 200)",
    )
    p.add_argument(
        "--max-stars",
        type=int_at_least(4),
        default=100,
        help="use the brightest this many detections of each image (default %(default)s)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Calibrate on every image, write the camera file, print the fit."""
    from tqdm import tqdm

    from starnav.calibrate import calibrate
    from starnav.camera import save_camera

    check_fov(args, args.model)
    with tqdm(total=len(args.images), desc="calibrate", unit="image", file=sys.stderr) as bar:
        cal = calibrate(
            args.images,
            model=args.model,
            fov_deg=args.fov_deg,
            fov_range_deg=args.fov_range and tuple(args.fov_range),
            max_stars=args.max_stars,
            progress=bar.update,
        )
    cam = cal.camera
    save_camera(args.output, cam, rms_px=cal.rms_px, stars=cal.n_stars, frames=len(cal.frames))
    if args.json:
        print_json(
            {
                **cam.to_dict(),
                "sigma": cal.sigma,
                "rms_px": cal.rms_px,
                "n_stars": cal.n_stars,
                "frames": list(cal.frames),
                "failed": [{"image": n, "reason": r} for n, r in cal.failed],
                "camera_file": args.output,
            }
        )
        return EXIT_OK
    sg = cal.sigma
    coefficients = "".join(
        f", {k} {getattr(cam, k):.5f} ± {sg[k]:.5f}" for k in type(cam).coefficients
    )
    print(
        f"wrote {args.output}: {cam.model}, focal {cam.focal_px:.2f} ± {sg['focal_px']:.2f} px "
        f"(FOV {cam.fov_deg:.4f}°), principal point ({cam.cx:.2f} ± {sg['cx']:.2f}, "
        f"{cam.cy:.2f} ± {sg['cy']:.2f}) px{coefficients}; rms {cal.rms_px:.3f} px over "
        f"{cal.n_stars} stars in {len(cal.frames)} images"
    )
    for name, reason in cal.failed:
        print(f"  left out {name}: {reason}")
    return EXIT_OK
