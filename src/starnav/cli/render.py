"""``starnav render``: a realistic star image (PSF, noise, hot pixels) of a preset camera or of
a camera file (any lens model: black outside the image circle of a fisheye, vignetting)."""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from starnav.camera import load_camera
from starnav.catalog import load_catalog
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_attitude,
    count,
    finite,
    positive_int,
)
from starnav.cli.output import print_json
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate import draw_radec_roll
from starnav.simulate.render import PRESETS

SENSOR_NUMBERS = (  # RenderSettings fields with an option each (--psf-sigma-px, ...)
    "psf_sigma_px",
    "exposure_s",
    "zero_point_e_per_s",
    "background_e",
    "read_noise_e",
    "gain_e_per_adu",
)
SENSOR_HELP = {  # what each of SENSOR_NUMBERS is, and its unit
    "psf_sigma_px": ("Gaussian PSF sigma", "px"),
    "exposure_s": ("exposure time", "s"),
    "zero_point_e_per_s": ("flux of a magnitude-0 star", "electrons/s"),
    "background_e": ("sky and dark per pixel over the exposure", "electrons"),
    "read_noise_e": ("read noise", "electrons rms"),
    "gain_e_per_adu": ("gain", "electrons/ADU"),
}
DEFAULT_FAINTEST_MAG = 8.0  # stars drawn when the preset sets no magnitude limit
DEFAULT_PRESET = "seed-1024"


def preset_default(name: str) -> str:
    """'default X' of a camera or sensor value the presets set (``name``: a ``RenderSettings``
    field or a camera property such as fov_deg, width, height), naming the preset when the
    presets differ."""
    values = {}
    for key, (camera, settings) in sorted(PRESETS.items()):
        value = getattr(settings, name) if hasattr(settings, name) else getattr(camera, name)
        values[key] = DEFAULT_FAINTEST_MAG if value is None else value
    if len(set(values.values())) == 1:
        return f"default {values[DEFAULT_PRESET]:g}"
    return "default: the preset's, " + ", ".join(f"{v:g} for {k}" for k, v in values.items())


def add_parser(subparsers: Subparsers) -> None:
    """The ``render`` command and its options."""
    p = subparsers.add_parser(
        "render", help="render a realistic star image (PSF, noise, hot pixels)"
    )
    p.add_argument("-o", "--output", required=True, help="image file: .png, .tif, .tiff, .fits")
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=DEFAULT_PRESET,
        help="camera and sensor (default %(default)s); the options below override it",
    )
    p.add_argument(
        "--camera",
        metavar="CAM.json",
        help="camera file (any lens model; size, focal length and coefficients come from it, "
        "instead of the preset's pinhole and the five options below)",
    )
    p.add_argument(
        "--fov-deg", type=finite, help=f"horizontal FOV (degrees; {preset_default('fov_deg')})"
    )
    p.add_argument(
        "--width", type=positive_int, help=f"image width (px; {preset_default('width')})"
    )
    p.add_argument(
        "--height",
        type=positive_int,
        help="image height (px; default: the preset's, or the width given)",
    )
    p.add_argument("--k1", type=finite, help="radial distortion k1 (default 0)")
    p.add_argument("--k2", type=finite, help="radial distortion k2 (default 0)")
    add_attitude(p)
    for name in SENSOR_NUMBERS:
        p.add_argument(
            f"--{name.replace('_', '-')}",
            type=finite,
            help="sensor: {} ({}; {})".format(*SENSOR_HELP[name], preset_default(name)),
        )
    p.add_argument(
        "--vignetting-power",
        type=finite,
        help="p of the relative illumination cos(θ/2)^p (0: none; default 2 for a fisheye, "
        "one stop at 90° from the axis, 0 for a pinhole)",
    )
    p.add_argument(
        "--bit-depth",
        type=int,
        choices=(8, 16),
        help=f"8 or 16 bit output ({preset_default('bit_depth')})",
    )
    p.add_argument(
        "--hot-pixels",
        type=count,
        help=f"hot pixels at random places ({preset_default('hot_pixels')})",
    )
    p.add_argument(
        "--mag-limit",
        type=finite,
        help=f"faintest Hipparcos star drawn (Hp; {preset_default('mag_limit')})",
    )
    p.add_argument("--seed", type=count, help="random seed (default: random)")
    p.add_argument("--truth", metavar="CSV", help="write the drawn stars (x, y, id, mag) here")
    p.add_argument("--json", action="store_true", help="print the truth as one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Render the image (and its truth CSV); print the truth."""
    from starnav.simulate.render import (
        adjust_camera,
        preset,
        render_frame,
        write_image,
        write_truth_csv,
    )

    camera, settings = preset(args.preset)
    if args.camera is not None:
        pinhole = ("fov_deg", "width", "height", "k1", "k2")
        given = [f"--{k.replace('_', '-')}" for k in pinhole if getattr(args, k) is not None]
        if given:
            raise StarnavError(f"--camera gives the lens and the image size: drop {given[0]}")
        camera = load_camera(args.camera)
    else:
        camera = adjust_camera(
            camera,
            fov_deg=args.fov_deg,
            width=args.width,
            height=args.height,
            k1=args.k1 or 0.0,
            k2=args.k2 or 0.0,
        )
    changes = {
        k: getattr(args, k)
        for k in (
            *SENSOR_NUMBERS,
            "bit_depth",
            "hot_pixels",
            "mag_limit",
            "seed",
            "vignetting_power",
        )
        if getattr(args, k) is not None
    }
    settings = replace(settings, **changes)
    rng = np.random.default_rng(args.seed)
    R = attitude_from_radec_roll(
        *draw_radec_roll(rng, args.ra_deg, args.dec_deg, args.roll_deg), args.parity
    )
    faintest = DEFAULT_FAINTEST_MAG if settings.mag_limit is None else settings.mag_limit
    frame = render_frame(load_catalog(None, mag_limit=faintest), camera, R, settings)
    write_image(args.output, frame.image)
    if args.truth:
        write_truth_csv(args.truth, frame)
    truth = frame.to_dict()
    if args.json:
        print_json({"image": args.output, **truth})
    else:
        print(
            f"wrote {args.output}: {camera.model} {camera.width} x {camera.height} px, "
            f"FOV {camera.fov_deg:.3f}°, "
            f"{truth['n_stars']} stars; RA {truth['ra_deg']:.5f}° Dec {truth['dec_deg']:+.5f}° "
            f"roll {truth['roll_deg']:.4f}°"
        )
    return EXIT_OK
