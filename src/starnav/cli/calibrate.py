"""``starnav calibrate``: focal length, principal point and distortion from star images."""

from __future__ import annotations

import argparse
import sys

from starnav.camera import CAMERA_FILE_KEYS
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_fov_search,
    int_at_least,
    print_json,
)


def add_parser(subparsers: Subparsers) -> None:
    """The ``calibrate`` command and its options."""
    p = subparsers.add_parser(
        "calibrate", help="fit focal length, principal point and distortion from star images"
    )
    p.add_argument("images", nargs="+", help="image files of one camera")
    p.add_argument("-o", "--output", required=True, help="camera file (JSON) to write")
    add_fov_search(p, "horizontal FOV, roughly (searched ±5 %%)")
    p.add_argument("--max-stars", type=int_at_least(4), default=100)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Calibrate on every image, write the camera file, print the fit."""
    from tqdm import tqdm

    from starnav.calibrate import calibrate
    from starnav.camera import save_camera

    with tqdm(total=len(args.images), desc="calibrate", unit="image", file=sys.stderr) as bar:
        cal = calibrate(
            args.images,
            fov_deg=args.fov_deg,
            fov_range_deg=tuple(args.fov_range),
            max_stars=args.max_stars,
            progress=bar.update,
        )
    cam = cal.camera
    save_camera(args.output, cam, rms_px=cal.rms_px, stars=cal.n_stars, frames=len(cal.frames))
    if args.json:
        print_json(
            {
                **{k: getattr(cam, k) for k in CAMERA_FILE_KEYS},
                "fov_deg": cam.fov_deg,
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
    print(
        f"wrote {args.output}: focal {cam.focal_px:.2f} ± {sg['focal_px']:.2f} px "
        f"(FOV {cam.fov_deg:.4f}°), principal point ({cam.cx:.1f} ± {sg['cx']:.1f}, "
        f"{cam.cy:.1f} ± {sg['cy']:.1f}) px, k1 {cam.k1:.5f} ± {sg['k1']:.5f}, "
        f"k2 {cam.k2:.5f} ± {sg['k2']:.5f}; rms {cal.rms_px:.3f} px over {cal.n_stars} "
        f"stars in {len(cal.frames)} images"
    )
    for name, reason in cal.failed:
        print(f"  left out {name}: {reason}")
    return EXIT_OK
