"""``starnav sky``: one frame of an all-sky camera solved, then the sky's state over it: which
catalog stars should be seen and are, clear / cloudy per region and per altitude-azimuth cell,
the limiting magnitude reached (``starnav.sky``), as text or JSON and as a picture."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from starnav.cli.common import EXIT_NOT_SOLVED, EXIT_OK, Subparsers, check_parent_dir, finite
from starnav.cli.field import add_image_solve_options, check_fov, image_solve_options
from starnav.cli.output import print_json
from starnav.cli.site import site_of
from starnav.errors import StarnavError

SKY_CATALOG_MAG = 7.5  # the stars tested: deeper than any all-sky camera's clear-sky limit


def add_parser(subparsers: Subparsers) -> None:
    """The ``sky`` command and its options."""
    p = subparsers.add_parser(
        "sky",
        help="clear / cloudy sky of an all-sky frame: the stars expected and seen, a cloud map, "
        "alt-az cells and the limiting magnitude",
    )
    p.add_argument("image", metavar="IMAGE", help="the frame (FITS, PNG, JPEG, TIFF)")
    add_image_solve_options(p)
    sky = p.add_argument_group("the sky's state")
    sky.add_argument(
        "--mag-limit",
        type=finite,
        help="the camera's clear-sky limiting magnitude: the stars to it are expected "
        "(default: from the frame's photometric zero point)",
    )
    sky.add_argument(
        "--snr-seen",
        type=finite,
        default=3.0,
        help="a star is seen above this signal-to-noise at its predicted pixel (default "
        "%(default)g)",
    )
    sky.add_argument(
        "--min-alt-deg",
        type=finite,
        default=10.0,
        help="lowest altitude judged, with a site (degrees; default %(default)g)",
    )
    sky.add_argument(
        "--mount",
        metavar="JSON",
        help="a fixed camera's mount (R_cam_from_enu): the JSON 'starnav sky --json' printed "
        "for a solved frame of this camera with a site (a clear night's: its limiting "
        "magnitude becomes --mag-limit); with --camera, --lat/--lon and the time, the "
        "attitude comes from it and the frame is not solved (an overcast frame gets its map "
        "too)",
    )
    p.add_argument("--png", metavar="PNG", help="draw the frame, the stars and the cloud map here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def _site(args: argparse.Namespace, path: Path):
    """The ``Site`` of the options (and the file's time), or None with neither latitude nor
    longitude; one-line errors for half a site or a site without a time."""
    from starnav.sky import Site

    where = site_of(args)
    if where is None:
        if args.utc is not None:
            raise StarnavError("--utc needs the site: give --lat and --lon too")
        return None
    utc = args.utc
    if utc is None:
        from starnav.detect.header import image_time

        found = image_time(path)
        if found is None:
            raise StarnavError(f"{str(path)!r} records no time: give --utc")
        if found.local:
            raise StarnavError(
                f"{str(path)!r} records the camera clock's local time ({found.text}, "
                f"{found.source}) with no zone: give --utc"
            )
        utc = found.time.utc.isot
    from starnav.navigation.frames import parse_utc

    parse_utc(utc)  # a bad time fails here, before the solve
    return Site(*where, utc)


def run(args: argparse.Namespace) -> int:
    """Read, solve, judge the sky, write the picture, print."""
    check_fov(args, args.lens)
    path = Path(args.image)
    if args.png:
        if not args.png.lower().endswith(".png"):
            raise StarnavError(
                f"--png writes a PNG file: give a name ending in .png, got {args.png!r}"
            )
        check_parent_dir("--png", args.png)
    if not args.snr_seen > 0:
        raise StarnavError(f"--snr-seen must be positive, got {args.snr_seen:g}")
    site = _site(args, path)
    from starnav.catalog import is_embedded, load_catalog
    from starnav.detect.circle import find_image_circle
    from starnav.detect.header import fits_hints
    from starnav.detect.read import read_image
    from starnav.navigation.frames import parse_utc
    from starnav.pipeline.image import solve_image
    from starnav.sky import sky_state
    from starnav.sky.state import mount_of

    t0 = time.perf_counter()
    pixels = read_image(path)
    if args.mount:
        R, camera, detections, summary = _mounted(args, pixels, site)
    else:
        options = image_solve_options(args)
        options.setdefault("hints", fits_hints(path))
        if site is not None and args.epoch is None:
            options["epoch_year"] = float(parse_utc(site.utc).decimalyear)
        res = solve_image(pixels, **options)
        summary = {k: v for k, v in res.to_dict(str(path)).items() if k != "stars"}
        if res.solution is None:
            if args.json:
                print_json({"file": str(path), "solve": summary, "sky": None})
            else:
                print(f"not solved: {res.reason}; the sky's state needs a solved frame")
            return EXIT_NOT_SOLVED
        R, camera, detections = res.solution.R_cam_from_icrs, res.camera, res.detections
    solve_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    own = is_embedded(args.catalog)
    epoch = args.epoch
    if epoch is None and site is not None:
        epoch = float(parse_utc(site.utc).decimalyear)
    catalog = load_catalog(
        args.catalog,
        mag_limit=SKY_CATALOG_MAG if own else None,
        epoch_year=epoch if own else None,
    )
    state = sky_state(
        pixels,
        R_cam_from_icrs=R,
        camera=camera,
        catalog=catalog,
        psf_sigma_px=_psf(detections.psf_sigma_px),
        circle=find_image_circle(pixels),
        detected_xy=detections.xy,
        site=site,
        mag_limit=args.mag_limit,
        snr_seen=args.snr_seen,
        min_alt_deg=args.min_alt_deg,
    )
    sky_s = time.perf_counter() - t1
    if args.png:
        from starnav.sky.plot import plot_sky_state

        plot_sky_state(
            args.png, pixels, state, R_cam_from_icrs=R, camera=camera, title=path.name,
        )  # fmt: skip
    if args.json:
        out = {"file": str(path), "solve": summary, "sky": state.to_dict()}
        out["sky"]["sky_ms"] = round(sky_s * 1e3, 1)
        if site is not None:
            out["sky"]["R_cam_from_enu"] = mount_of(R, site).tolist()
        print_json(out)
    else:
        _print_text(state, solve_s, sky_s)
    return EXIT_OK


def _psf(sigma_px: float) -> float:
    """The PSF sigma measured, or 1.5 px for a frame with too few stars to measure it."""
    return sigma_px if sigma_px == sigma_px and sigma_px > 0 else 1.5


def _mounted(args: argparse.Namespace, pixels, site):
    """A fixed camera's frame with no solve: (R_cam_from_icrs from --mount and the site and
    time, the --camera, the detections, a summary for the JSON)."""
    from starnav.camera import load_camera
    from starnav.detect.stars import detect_stars
    from starnav.sky.state import attitude_of, read_mount

    if args.camera is None or site is None:
        raise StarnavError("--mount needs --camera and the site and time (--lat, --lon, a time)")
    camera = load_camera(args.camera)
    if pixels.shape != (camera.height, camera.width):
        raise StarnavError(
            f"the image is {pixels.shape[1]} x {pixels.shape[0]} px, the camera file "
            f"{camera.width} x {camera.height}"
        )
    mount, clear_limit = read_mount(args.mount)
    if args.mag_limit is None:
        args.mag_limit = clear_limit
    detections = detect_stars(pixels, threshold_sigma=args.threshold_sigma)
    summary = {"solved": None, "attitude": "from the mount", "mount": args.mount}
    return attitude_of(mount, site), camera, detections, summary


def _print_text(state, solve_s: float, sky_s: float) -> None:
    frac = "n/a" if state.clear_fraction is None else f"{state.clear_fraction:.2f}"
    lim = "n/a" if state.limiting_mag is None else f"{state.limiting_mag:.1f}"
    n_exp = int(state.expected.sum())
    print(
        f"sky {state.state}: clear fraction {frac}, limiting magnitude {lim}; "
        f"{int((state.expected & state.seen).sum())} of {n_exp} expected stars seen "
        f"({len(state.ids)} tested, expected by {state.expected_by})"
    )
    counts = state.cell_counts()
    frame = "alt-az" if state.altaz else "camera frame (no site)"
    print(f"  cells ({frame}): " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    for c in state.cells:
        lim = "-" if c.limiting_mag is None else f"{c.limiting_mag:.1f}"
        print(
            f"  alt {c.alt_min_deg:4.0f}-{c.alt_max_deg:<4.0f} az {c.az_min_deg:5.0f}-"
            f"{c.az_max_deg:<5.0f} {c.state:8s} {c.n_seen:4d}/{c.n_expected:<4d} lim {lim}"
        )
    print(f"  solve {solve_s:.1f} s, sky {sky_s:.2f} s", file=sys.stderr)
