"""``starnav calibrate``: lens model, focal length, principal point and the model's
coefficients from star images, with their uncertainties; for a fixed camera with its site and
the frames' UTCs, its orientation relative to the horizon (later frames then track)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from starnav.camera import MODELS
from starnav.cli.common import EXIT_OK, Subparsers, check_parent_dir, finite, int_at_least
from starnav.cli.field import add_fov_search, check_fov
from starnav.cli.output import print_json
from starnav.cli.site import site_of
from starnav.errors import StarnavError


def add_parser(subparsers: Subparsers) -> None:
    """The ``calibrate`` command and its options."""
    p = subparsers.add_parser(
        "calibrate",
        help="fit a camera's lens model, focal length, principal point and distortion (and a "
        "fixed camera's orientation) from star images",
    )
    p.add_argument("images", nargs="+", help="image files of one camera")
    p.add_argument("-o", "--output", required=True, help="camera file (JSON) to write")
    add_fov_search(p, "horizontal FOV, roughly: searched ±5 %%")
    p.add_argument(
        "--camera",
        help="a starting camera file: the images are solved through it (--fov-* unused), the "
        "fit starts from it",
    )
    p.add_argument(
        "--model",
        choices=(*MODELS, "auto"),
        default="pinhole",
        help="lens model fitted (default pinhole: k1, k2; kannala-brandt: k1..k4, starting from "
        "the fixed fisheye model that solves; auto: the fixed fisheyes and kannala-brandt, the "
        "lowest information criterion kept; give a fisheye --fov-deg or e.g. --fov-range 150 200)",
    )
    p.add_argument(
        "--lens",
        choices=tuple(MODELS),
        help="the lens model each image is solved with first (default: --model's; the fixed "
        "fisheyes in turn for kannala-brandt and auto)",
    )
    p.add_argument(
        "--max-stars",
        type=int_at_least(4),
        default=100,
        help="use the brightest this many detections of each image (default %(default)s)",
    )
    fixed = p.add_argument_group("a fixed camera (its orientation for tracking later frames)")
    fixed.add_argument(
        "--utc",
        help="UTC of the image (ISO 8601, one image; default: the file's own DATE-OBS / EXIF UTC)",
    )
    fixed.add_argument("--lat", type=finite, help="site latitude (degrees, north positive)")
    fixed.add_argument("--lon", type=finite, help="site longitude (degrees, east positive)")
    fixed.add_argument(
        "--height-m",
        "--height",
        type=finite,
        default=0.0,
        dest="height_m",
        help="site height (m, default 0; --height-m as in solve and sky)",
    )
    p.add_argument("--plot", help="write the residuals (vs radius and as arrows) to this PNG")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def _times(args: argparse.Namespace) -> list | None:
    """Each image's UTC (``--utc`` or the file's own; None where unknown)."""
    from starnav.detect.header import image_time
    from starnav.navigation.frames import parse_utc

    if args.utc is not None:  # one image (check_fov)
        return [parse_utc(args.utc)]
    times = []
    for path in args.images:
        found = image_time(path)
        times.append(None if found is None or found.local else found.time)
    return times


def run(args: argparse.Namespace) -> int:
    """Calibrate on every image, write the camera file (and the plot), print the fit."""
    from tqdm import tqdm

    from starnav.calibrate import calibrate, plot_residuals
    from starnav.camera import save_camera

    check_fov(args, args.lens or ("equisolid" if args.model == "auto" else args.model))
    check_parent_dir("--output", args.output)
    if args.plot:
        check_parent_dir("--plot", args.plot)
        if not args.plot.lower().endswith(".png"):
            raise StarnavError("--plot writes a PNG file: give a name ending in .png")
    site = site_of(args)
    times = _times(args) if site is not None else None
    with tqdm(total=len(args.images), desc="calibrate", unit="image", file=sys.stderr) as bar:
        cal = calibrate(
            args.images,
            model=args.model,
            lens=args.lens,
            camera=args.camera,
            fov_deg=args.fov_deg,
            fov_range_deg=args.fov_range and tuple(args.fov_range),
            max_stars=args.max_stars,
            times=times,
            site=site,
            progress=bar.update,
        )
    cam = cal.camera
    out = cal.to_dict()
    notes = {k: out[k] for k in ("sigma", "rms_px", "n_stars", "parity", "image_circle_px")}
    if cal.mount is not None:
        notes["mount"] = out["mount"]
    save_camera(args.output, cam, frames=len(cal.frames), **notes)
    if args.plot:
        plot_residuals(cal, args.plot)
    if args.json:
        print_json({**out, "camera_file": args.output, "plot": args.plot})
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
        + (" (mirrored)" if cal.parity < 0 else "")
    )
    if len(cal.models) > 1:
        for m in sorted(cal.models, key=lambda m: m.bic):
            print(f"  {m.model}: rms {m.rms_px:.3f} px over {m.n_stars} stars, BIC {m.bic:.1f}")
    for why in cal.refused:
        print(f"  not fitted: {why}")
    for name, rms, n in zip(cal.frames, cal.frame_rms_px, cal.frame_stars, strict=True):
        print(f"  {Path(name).name}: rms {rms:.3f} px over {n} stars")
    if cal.mount is not None:
        z = cal.mount.to_dict()["zenith_from_axis_deg"]
        print(
            f"  mount: zenith {z:.2f}° from the axis, frames agree within "
            f"{cal.mount.spread_deg:.3f}°: later frames with a UTC track"
        )
    for name, reason in cal.failed:
        print(f"  left out {name}: {reason}")
    return EXIT_OK
