"""Command line: parse, call the API, print. Exit 0 solved / done, 1 not solved, 2 bad input."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from starnav.api import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    DEFAULT_SIGMA_PX,
    Solution,
    get_database,
    make_camera,
    solve_verbose,
)
from starnav.catalog import DEFAULT_MAG_LIMIT, load_catalog
from starnav.errors import PointingError, StarnavError
from starnav.fov import DEFAULT_FOV_RANGE_DEG
from starnav.geometry import (
    attitude_from_radec_roll,
    radec_roll_from_attitude,
)
from starnav.identify import ALGORITHMS, DEFAULT_ALGORITHM, cli_options
from starnav.image import DEFAULT_MAX_STARS
from starnav.render import PRESETS as RENDER_PRESETS
from starnav.results import solve_dict
from starnav.simulate import draw_radec_roll, simulate_frame, write_frame_csv
from starnav.starlist import read_star_csv

EXIT_OK, EXIT_NOT_SOLVED, EXIT_BAD_INPUT = 0, 1, 2
_RENDER_NUMBERS = (
    "psf_sigma_px",
    "exposure_s",
    "zero_point_e_per_s",
    "background_e",
    "read_noise_e",
    "gain_e_per_adu",
)


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage mistake in one line (exit 2), without the usage dump."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return value


def _int_at_least(minimum: int):
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        return value

    return convert


_positive_int = _int_at_least(1)
_count = _int_at_least(0)


def _png_path(text: str) -> str:
    if not text.lower().endswith(".png"):
        raise argparse.ArgumentTypeError(
            f"the plot is a PNG file: give a name ending in .png, got {text!r}"
        )
    return text


def _add_camera(p: argparse.ArgumentParser, *, required: bool = True) -> None:
    p.add_argument("--fov-deg", type=_finite, required=required, help="horizontal field of view")
    p.add_argument("--width", type=_positive_int, required=required, help="image width (px)")
    p.add_argument("--height", type=_positive_int, help="image height (px; default: width)")


def _add_fov_search(p: argparse.ArgumentParser, fov_help: str):
    """--fov-deg or --fov-range (the FOV search); returns the group for more choices."""
    fov = p.add_mutually_exclusive_group()
    fov.add_argument("--fov-deg", type=_finite, help=fov_help)
    fov.add_argument(
        "--fov-range",
        nargs=2,
        type=_finite,
        metavar=("LO", "HI"),
        default=DEFAULT_FOV_RANGE_DEG,
        help="horizontal FOV range searched when the FOV is unknown (degrees; default 5 40)",
    )
    return fov


def _add_catalog(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--catalog",
        help="CSV catalog id,ra_deg,dec_deg,mag (default: embedded Hipparcos)",
    )
    p.add_argument(
        "--mag-limit",
        type=_finite,
        help=f"faintest catalog magnitude used (default {DEFAULT_MAG_LIMIT:g} for Hipparcos, "
        "all stars for a CSV)",
    )
    p.add_argument(
        "--epoch",
        type=_finite,
        help="year to apply Hipparcos proper motion to (default: this year)",
    )


def _add_algorithm(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--algorithm",
        choices=list(ALGORITHMS),
        default=DEFAULT_ALGORITHM,
        help="identification algorithm (default %(default)s)",
    )
    p.add_argument(
        "--triangle-selection",
        choices=("brightest", "optimized"),
        default="optimized",
        help="how --algorithm triangle picks its triangles (default %(default)s)",
    )


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="starnav",
        description="Star identification and attitude from star-camera centroids and images. "
        "Exit status: 0 done/solved, 1 not solved, 2 bad input.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("identify", help="identify a star list (CSV) and solve the attitude")
    p.add_argument(
        "stars",
        help="CSV with header: x,y and optionally label, flux or mag; or a directory of them",
    )
    _add_fov_search(p, "horizontal field of view (without it the FOV is searched)")
    p.add_argument("--width", type=_positive_int, required=True, help="image width (px)")
    p.add_argument("--height", type=_positive_int, help="image height (px; default: width)")
    _add_catalog(p)
    p.add_argument(
        "--sigma-px",
        type=_finite,
        default=DEFAULT_SIGMA_PX,
        help=f"centroid error, 1 sigma (px; default {DEFAULT_SIGMA_PX:g}): sets the tolerances",
    )
    p.add_argument("--parity", type=int, choices=(1, -1), help="force parity (default: find)")
    p.add_argument("--fit-focal", action="store_true", help="fit the focal length too")
    p.add_argument(
        "--max-false-match-probability",
        type=_finite,
        default=DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
        help="refuse less certain answers (default %(default)g)",
    )
    _add_algorithm(p)
    p.add_argument(
        "--workers", type=_positive_int, help="a directory: processes (default: all cores)"
    )
    p.add_argument("--prior-ra-deg", type=_finite, help="tracking: previous boresight RA")
    p.add_argument("--prior-dec-deg", type=_finite, help="tracking: previous boresight Dec")
    p.add_argument("--prior-roll-deg", type=_finite, help="tracking: previous roll")
    p.add_argument(
        "--prior-sigma-deg",
        type=_finite,
        default=1.0,
        help="tracking: 1-sigma error of the previous attitude (default 1)",
    )
    p.add_argument(
        "--plot", metavar="PNG", type=_png_path, help="draw the identified map into this PNG file"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser("simulate", help="simulate a frame of centroids from the catalog")
    p.add_argument("--ra-deg", type=_finite, help="boresight RA (default: random)")
    p.add_argument("--dec-deg", type=_finite, help="boresight Dec (default: random)")
    p.add_argument("--roll-deg", type=_finite, help="roll (default: random)")
    p.add_argument("--parity", type=int, choices=(1, -1), default=1)
    _add_camera(p)
    _add_catalog(p)
    p.add_argument("--noise-px", type=_finite, default=0.0, help="centroid noise, 1 sigma")
    p.add_argument("--false-stars", type=_count, default=0, help="false stars added")
    p.add_argument("--missing-frac", type=_finite, default=0.0, help="fraction of stars dropped")
    p.add_argument("--mag-noise", type=_finite, default=0.0, help="magnitude noise, 1 sigma")
    p.add_argument("--seed", type=_count, help="random seed")
    p.add_argument("-o", "--output", required=True, help="frame CSV to write")
    p.add_argument("--json", action="store_true", help="print the truth as one JSON object")

    p = sub.add_parser("demo", help="simulate a random frame, identify it, compare with truth")
    p.add_argument("--seed", type=_count, help="random seed (default: random)")
    p.add_argument("--fov-deg", type=_finite, default=12.0)
    p.add_argument("--width", type=_positive_int, default=512)
    p.add_argument("--noise-px", type=_finite, default=0.5)
    p.add_argument("--false-stars", type=_count, default=2)
    p.add_argument("--missing-frac", type=_finite, default=0.1)
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("pointing", help="boresight from three known stars (or the best three)")
    p.add_argument("stars", help="CSV: ra_deg,dec_deg and x,y or r_px (optionally label)")
    p.add_argument("--focal-px", type=_finite, help="focal length (px); default: solve for it")
    p.add_argument("--width", type=_positive_int, help="image width (px), needed with x,y")
    p.add_argument("--height", type=_positive_int, help="image height (px; default: width)")
    p.add_argument("--sigma-px", type=_finite, help="centroid noise per axis, for the 1σ error")
    p.add_argument("--parity", type=int, choices=(1, -1), help="default: found from x,y")
    p.add_argument(
        "--select-best",
        action="store_true",
        help="from N > 3 stars pick the three with the smallest predicted error",
    )
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("pointing-study", help="boresight error of classic star arrangements")
    p.add_argument("--fov-deg", type=_finite, default=12.0)
    p.add_argument("--width", type=_positive_int, default=512)
    p.add_argument("--sigma-px", type=_finite, default=0.5)
    p.add_argument("--trials", type=_positive_int, default=20000, help="Monte Carlo draws")
    p.add_argument("--seed", type=_count, default=0)
    p.add_argument("--out-dir", default=".", help="where the PNG figures go")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser(
        "evaluate", help="lost-in-space evaluation over the whole sky (simulated frames)"
    )
    p.add_argument("--sampling", choices=("grid", "uniform"), default="grid")
    p.add_argument(
        "--grid-step-deg",
        type=_finite,
        default=3.0,
        help="RA/Dec grid step (default 3: 7200 boresights)",
    )
    p.add_argument(
        "--frames", type=_positive_int, default=1000, help="frames of --sampling uniform"
    )
    p.add_argument("--fov-deg", type=_finite, default=12.0, help="horizontal FOV (default 12)")
    p.add_argument("--width", type=_positive_int, default=512, help="image width (default 512)")
    p.add_argument("--height", type=_positive_int, help="image height (px; default: width)")
    p.add_argument(
        "--mag-limit", type=_finite, default=DEFAULT_MAG_LIMIT, help="Hipparcos Hp limit"
    )
    p.add_argument(
        "--noise-px", type=_finite, default=0.5, help="centroid noise, 1 sigma (default 0.5)"
    )
    p.add_argument("--false-stars", type=_count, default=2, help="per frame (default 2)")
    p.add_argument("--missing-frac", type=_finite, default=0.1, help="stars dropped (default 0.1)")
    p.add_argument(
        "--mag-noise", type=_finite, default=0.0, help="magnitude noise, 1 sigma (default 0)"
    )
    p.add_argument(
        "--sigma-px", type=_finite, help="centroid sigma told to the solver (default: the noise)"
    )
    _add_algorithm(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--workers", type=_positive_int, help="processes (default: all cores; 1: this process)"
    )
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run on this Dask scheduler (e.g. tcp://host:8786), or 'local' for a LocalCluster",
    )
    p.add_argument("--frames-csv", metavar="CSV", help="write one row per frame here")
    p.add_argument("--sky-map", metavar="PNG", type=_png_path, help="whole-sky outcome map")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser(
        "locate", help="latitude, longitude and heading from star cameras, gravity and UTC"
    )
    p.add_argument("observation", help="observation JSON (see docs/locate.md)")
    p.add_argument(
        "--sigma-px",
        type=_finite,
        default=DEFAULT_SIGMA_PX,
        help=f"centroid error, 1 sigma (px; default {DEFAULT_SIGMA_PX:g})",
    )
    _add_catalog(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser(
        "locate-study", help="sensitivity of the fix to tilt and star errors (Monte Carlo)"
    )
    p.add_argument("--trials", type=_positive_int, default=50, help="per setting (default 50)")
    p.add_argument("--fov-deg", type=_finite, default=20.0, help="camera FOV (default 20)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--plot", metavar="PNG", type=_png_path, help="draw the two curves here")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser("database", help="build (or load) the pair database and report it")
    _add_camera(p)
    _add_catalog(p)
    p.add_argument("--json", action="store_true")

    p = sub.add_parser(
        "solve", help="solve an image file (FITS, PNG, JPEG, TIFF): FOV may be unknown"
    )
    p.add_argument("image", help="image file")
    fov = _add_fov_search(p, "horizontal FOV, roughly (searched ±5 %%)")
    fov.add_argument("--camera", help="camera file from 'starnav calibrate' (searched ±1 %%)")
    p.add_argument(
        "--fit-distortion", action="store_true", help="fit radial distortion k1, k2 as well"
    )
    p.add_argument(
        "--max-stars",
        type=_int_at_least(4),
        default=DEFAULT_MAX_STARS,
        help="use the brightest this many detections (default %(default)s)",
    )
    p.add_argument(
        "--threshold-sigma",
        type=_finite,
        default=5.0,
        help="detection threshold over the background noise (default %(default)g)",
    )
    p.add_argument(
        "--sigma-px", type=_finite, default=1.0, help="centroid error assumed (default 1 px)"
    )
    p.add_argument("--parity", type=int, choices=(1, -1), help="force parity (default: find)")
    p.add_argument(
        "--catalog", help="CSV catalog id,ra_deg,dec_deg,mag (default: embedded Hipparcos)"
    )
    p.add_argument("--epoch", type=_finite, help="year for Hipparcos proper motion")
    p.add_argument("--wcs", metavar="FITS", help="write a FITS WCS header (TAN or TAN-SIP) here")
    p.add_argument(
        "--annotate", metavar="PNG", type=_png_path, help="draw the solved image into this PNG"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser("render", help="render a realistic star image (PSF, noise, hot pixels)")
    p.add_argument("-o", "--output", required=True, help="image file: .png, .tif, .tiff, .fits")
    p.add_argument(
        "--preset",
        choices=sorted(RENDER_PRESETS),
        default="seed-1024",
        help="camera and sensor (default %(default)s); the options below override it",
    )
    p.add_argument("--fov-deg", type=_finite, help="horizontal FOV")
    p.add_argument("--width", type=_positive_int, help="image width (px)")
    p.add_argument("--height", type=_positive_int, help="image height (px; default: width)")
    p.add_argument("--k1", type=_finite, default=0.0, help="radial distortion k1")
    p.add_argument("--k2", type=_finite, default=0.0, help="radial distortion k2")
    p.add_argument("--ra-deg", type=_finite, help="boresight RA (default: random)")
    p.add_argument("--dec-deg", type=_finite, help="boresight Dec (default: random)")
    p.add_argument("--roll-deg", type=_finite, help="roll (default: random)")
    p.add_argument("--parity", type=int, choices=(1, -1), default=1)
    for name in _RENDER_NUMBERS:
        p.add_argument(f"--{name.replace('_', '-')}", type=_finite, help=f"sensor: {name}")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), help="8 or 16 bit output")
    p.add_argument("--hot-pixels", type=_count, help="hot pixels at random places")
    p.add_argument("--mag-limit", type=_finite, help="faintest Hipparcos star drawn")
    p.add_argument("--seed", type=_count, help="random seed")
    p.add_argument("--truth", metavar="CSV", help="write the drawn stars (x, y, id, mag) here")
    p.add_argument("--json", action="store_true", help="print the truth as one JSON object")

    p = sub.add_parser(
        "calibrate", help="fit focal length, principal point and distortion from star images"
    )
    p.add_argument("images", nargs="+", help="image files of one camera")
    p.add_argument("-o", "--output", required=True, help="camera file (JSON) to write")
    _add_fov_search(p, "horizontal FOV, roughly (searched ±5 %%)")
    p.add_argument("--max-stars", type=_int_at_least(4), default=100)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def _json(obj: dict) -> str:
    """One line of JSON; NaN and infinities (e.g. an undetermined sigma) become null."""

    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    return json.dumps(clean(obj), allow_nan=False)


def _print_solution(s: Solution, *, file=None) -> None:
    print(
        f"solved: RA {s.ra_deg:.5f}°  Dec {s.dec_deg:+.5f}°  roll {s.roll_deg:.4f}°  "
        f"parity {s.parity:+d}",
        file=file,
    )
    print(
        f"  {s.n_matched}/{len(s.stars)} stars matched, rms {s.rms_px:.3f} px, "
        f"1σ boresight {s.sigma_boresight_arcsec:.2f}″ roll {s.sigma_roll_arcsec:.2f}″, "
        f"focal {s.focal_px:.2f} px (FOV {s.fov_deg:.4f}°)",
        file=file,
    )
    print(
        f"  false-match probability {s.false_match_probability:.1e}, {s.time_ms:.1f} ms, "
        f"catalog: {s.catalog}",
        file=file,
    )
    print(f"{'label':>8} {'x':>9} {'y':>9} {'catalog_id':>10} {'residual_px':>11}", file=file)
    for m in s.stars:
        cid = "-" if m.catalog_id is None else str(m.catalog_id)
        res = "-" if m.residual_px is None else f"{m.residual_px:.3f}"
        print(f"{m.label:>8} {m.x:9.2f} {m.y:9.2f} {cid:>10} {res:>11}", file=file)


def _prior(args) -> np.ndarray | None:
    given = [args.prior_ra_deg, args.prior_dec_deg, args.prior_roll_deg]
    if all(v is None for v in given):
        return None
    if any(v is None for v in given):
        raise StarnavError(
            "tracking needs all of --prior-ra-deg, --prior-dec-deg, --prior-roll-deg"
        )
    if not -90.0 <= args.prior_dec_deg <= 90.0:
        raise StarnavError(f"--prior-dec-deg must be within ±90, got {args.prior_dec_deg:g}")
    return attitude_from_radec_roll(*given, args.parity or 1)


def _solve_options(args) -> dict:
    """The options of ``solve_verbose`` that ``identify`` takes from its command line."""
    return dict(
        width=args.width,
        height=args.height,
        fov_deg=args.fov_deg,
        catalog=args.catalog,
        mag_limit=args.mag_limit,
        epoch_year=args.epoch,
        parity=args.parity,
        sigma_px=args.sigma_px,
        fit_focal=args.fit_focal,
        max_false_match_probability=args.max_false_match_probability,
        algorithm=args.algorithm,
        algorithm_options=cli_options(args.algorithm, args.triangle_selection),
    )


def _identify_many(args, paths: list[Path]) -> int:
    """Every star list of a directory on all cores: one line (or JSON line) per file."""
    from tqdm import tqdm

    from starnav.api import solve_batch

    if args.plot or _prior(args) is not None:
        raise StarnavError("--plot and --prior-* take one star list, not a directory")
    if args.fov_deg is None:
        raise StarnavError("a directory of star lists needs --fov-deg")
    lists, problems = [], {}
    for path in paths:
        try:
            lists.append(read_star_csv(path))
        except StarnavError as exc:
            problems[path] = str(exc)
            lists.append(None)
    good = [(p, s) for p, s in zip(paths, lists, strict=True) if s is not None]
    t0 = time.perf_counter()
    with tqdm(total=len(good), desc="identify", unit="file", file=sys.stderr) as bar:
        results = solve_batch(
            [s.xy for _, s in good],
            brightness=[s.brightness for _, s in good],
            workers=args.workers,
            progress=bar.update,
            **_solve_options(args),
        )
    wall = time.perf_counter() - t0
    by_path = dict(zip([p for p, _ in good], results, strict=True))
    worst = EXIT_OK
    for path in paths:
        if path in problems:
            worst = EXIT_BAD_INPUT
            line = {"file": str(path), "solved": False, "reason": f"error: {problems[path]}"}
        else:
            s, reason, ms = by_path[path]
            if s is None:
                worst = max(worst, EXIT_BAD_INPUT if reason.startswith("error:") else 1)
            line = {"file": str(path), **(solve_dict(s) if s else {"solved": False})}
            line.update(reason=None if s else reason, time_ms=ms)
        if args.json:
            print(_json(line))
        elif line["solved"]:
            print(
                f"{path}: RA {line['ra_deg']:.5f}° Dec {line['dec_deg']:+.5f}° roll "
                f"{line['roll_deg']:.4f}° parity {line['parity']:+d}, {line['n_matched']} stars, "
                f"{line['time_ms']:.1f} ms"
            )
        else:
            print(f"{path}: not solved: {line['reason']}")
    print(
        f"{len(paths)} files in {wall:.2f} s ({len(good) / max(wall, 1e-9):.0f} frames/s)",
        file=sys.stderr,
    )
    return worst


def _cmd_identify(args) -> int:
    source = Path(args.stars)
    if source.is_dir():
        paths = sorted(source.glob("*.csv"))
        if not paths:
            raise StarnavError(f"{args.stars!r} holds no .csv star lists")
        return _identify_many(args, paths)
    stars = read_star_csv(args.stars)
    prior = _prior(args)
    if args.fov_deg is None:  # FOV unknown: searched with scale-free patterns
        from starnav.fov import solve_fov

        if prior is not None or args.algorithm != DEFAULT_ALGORITHM or args.mag_limit is not None:
            raise StarnavError(
                "--prior-*, --algorithm and --mag-limit need --fov-deg (without it the FOV "
                "search picks the catalog depth of each FOV band and fits the focal length)"
            )
        result = solve_fov(
            stars.xy,
            width=args.width,
            height=args.height,
            brightness=stars.brightness,
            labels=stars.labels,
            fov_range_deg=tuple(args.fov_range),
            catalog=args.catalog,
            epoch_year=args.epoch,
            parity=args.parity,
            sigma_px=args.sigma_px,
            max_false_match_probability=args.max_false_match_probability,
        )
    else:
        result = solve_verbose(
            stars.xy,
            brightness=stars.brightness,
            labels=stars.labels,
            **_solve_options(args),
            prior=prior,
            prior_sigma_deg=args.prior_sigma_deg,
        )
    s = result.solution
    if s is None and args.plot:
        print(f"starnav identify: not solved, no plot written to {args.plot}", file=sys.stderr)
    if s is not None and args.plot:
        from starnav.plot import plot_solution

        plot_solution(
            s,
            make_camera(width=args.width, height=args.height, fov_deg=s.fov_deg),
            result.database.catalog,
            args.plot,
        )
    if args.json:
        print(_json(result.to_dict(stars.labels, stars.xy)))
    elif s:
        _print_solution(s)
    else:
        print(f"not solved: {result.reason} ({result.time_ms:.1f} ms)")
    return EXIT_OK if s else EXIT_NOT_SOLVED


def _cmd_simulate(args) -> int:
    camera = make_camera(width=args.width, height=args.height, fov_deg=args.fov_deg)
    catalog = load_catalog(args.catalog, mag_limit=args.mag_limit, epoch_year=args.epoch)
    frame = simulate_frame(
        catalog,
        camera,
        ra_deg=args.ra_deg,
        dec_deg=args.dec_deg,
        roll_deg=args.roll_deg,
        parity=args.parity,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        mag_noise=args.mag_noise,
        seed=args.seed,
    )
    write_frame_csv(args.output, frame)
    truth = frame.to_dict()
    if args.json:
        print(_json({"output": args.output, **truth}))
    else:
        print(
            f"wrote {truth['n_points']} points ({truth['n_false']} false) to {args.output}: "
            f"RA {truth['ra_deg']:.4f}° Dec {truth['dec_deg']:+.4f}° roll "
            f"{truth['roll_deg']:.3f}° parity {truth['parity']:+d}"
        )
    return EXIT_OK


def _cmd_demo(args) -> int:
    rng = np.random.default_rng(args.seed)
    camera = make_camera(width=args.width, height=None, fov_deg=args.fov_deg)
    t0 = time.perf_counter()
    catalog = load_catalog(None)
    database = get_database(catalog, camera)
    setup_s = time.perf_counter() - t0
    frame = simulate_frame(
        catalog,
        camera,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        seed=rng,
    )
    if len(frame.xy) < 3:
        raise StarnavError(
            f"the simulated {args.fov_deg:g}° field holds only {len(frame.xy)} stars: "
            "choose a wider field of view"
        )
    result = solve_verbose(
        frame.xy,
        width=camera.width,
        fov_deg=args.fov_deg,
        brightness=frame.brightness,
        catalog=catalog,
        sigma_px=max(args.noise_px, 0.1),
    )
    s = result.solution
    truth = frame.to_dict()
    right = frame.compare(s)
    if args.json:
        solution = result.to_dict(None, frame.xy)
        print(
            _json(
                {
                    "truth": truth,
                    "solution": solution,
                    "comparison": right,
                    "database_bytes": database.nbytes,
                    "setup_s": setup_s,
                }
            )
        )
        return EXIT_OK if s else EXIT_NOT_SOLVED
    print(
        f"catalog: {catalog.name} ({len(catalog)} stars); pair database "
        f"{database.nbytes / 1e6:.1f} MB, built in {database.build_s:.2f} s"
        f"{' (loaded from cache)' if database.from_cache else ''}; setup {setup_s:.2f} s"
    )
    print(
        f"simulated {camera.fov_deg:g}° / {camera.width} px frame: {truth['n_points']} points "
        f"({truth['n_false']} false), noise {args.noise_px:g} px, "
        f"{args.missing_frac:.0%} of {truth['n_in_view']} stars dropped"
    )
    print(f"{'':10}{'RA (°)':>12}{'Dec (°)':>12}{'roll (°)':>12}{'parity':>8}")
    print(
        f"{'truth':10}{truth['ra_deg']:12.5f}{truth['dec_deg']:12.5f}"
        f"{truth['roll_deg']:12.4f}{truth['parity']:8d}"
    )
    if s is None:
        print(f"{'solved':10} not solved: {result.reason}")
        return EXIT_NOT_SOLVED
    print(f"{'solved':10}{s.ra_deg:12.5f}{s.dec_deg:12.5f}{s.roll_deg:12.4f}{s.parity:8d}")
    print(
        f"error: boresight {right['boresight_error_arcsec']:.1f}″ "
        f"(1σ estimate {s.sigma_boresight_arcsec:.1f}″), roll {right['roll_error_arcsec']:.1f}″ "
        f"(1σ {s.sigma_roll_arcsec:.1f}″); ids {right['ids_correct']} right, "
        f"{right['ids_wrong']} wrong, {right['false_stars_refused']} false stars refused; "
        f"{s.time_ms:.1f} ms"
    )
    return EXIT_OK


def _cmd_database(args) -> int:
    camera = make_camera(width=args.width, height=args.height, fov_deg=args.fov_deg)
    catalog = load_catalog(args.catalog, mag_limit=args.mag_limit, epoch_year=args.epoch)
    db = get_database(catalog, camera)
    info = {
        "catalog": catalog.name,
        "stars": len(catalog),
        "max_angle_deg": float(np.degrees(db.max_angle_rad)),
        "pairs": len(db.pair_a),
        "bytes": db.nbytes,
        "build_s": db.build_s,
        "from_cache": db.from_cache,
        "path": str(db.path) if db.path else None,
    }
    if args.json:
        print(_json(info))
    else:
        print(
            f"{info['catalog']}: {info['stars']} stars, {info['pairs']} pairs up to "
            f"{info['max_angle_deg']:g}°, {info['bytes'] / 1e6:.2f} MB, built in "
            f"{info['build_s']:.2f} s{' (loaded from cache)' if db.from_cache else ''}"
            f"{'; ' + info['path'] if info['path'] else ''}"
        )
    return EXIT_OK


def _print_pointing(p, used_labels) -> None:
    roll = "-" if p.roll_deg is None else f"{p.roll_deg:.4f}°"
    sigma = "" if p.sigma_boresight_arcsec is None else f", 1σ {p.sigma_boresight_arcsec:.2f}″"
    if p.sigma_focal_px is not None:
        sigma += f", focal 1σ {p.sigma_focal_px:.2f} px"
    print(f"stars used: {', '.join(used_labels)}")
    if p.fit_rms_px is not None:
        sigma += f", parity {p.parity:+d}, angle misfit {p.fit_rms_px:.2f} px"
    print(
        f"boresight: RA {p.ra_deg:.6f}°  Dec {p.dec_deg:+.6f}°  roll {roll}  focal "
        f"{p.focal_px:.3f} px  consistency |d|-1 = {p.consistency:.2e}{sigma}"
    )
    for k, alt in enumerate(p.alternatives, 1):
        print(
            f"  alternative {k}: RA {alt.ra_deg:.6f}°  Dec {alt.dec_deg:+.6f}°  focal "
            f"{alt.focal_px:.3f} px"
        )
    if p.note:
        print(f"note: {p.note}")


def _cmd_pointing(args) -> int:
    from starnav.pointing import best_triple, three_star
    from starnav.starlist import read_known_stars_csv

    if args.height is not None and args.width is None:
        raise PointingError("--height needs --width too")
    stars = read_known_stars_csv(args.stars)
    height = args.height if args.height is not None else args.width
    rows = np.arange(len(stars.ra_deg))
    if args.select_best:
        if stars.xy is None or args.focal_px is None or args.width is None:
            raise PointingError("--select-best needs x,y columns, --focal-px and --width")
        rows = np.array(
            best_triple(
                stars.ra_deg,
                stars.dec_deg,
                stars.xy,
                focal_px=args.focal_px,
                width=args.width,
                height=height,
            )
        )
    result = three_star(
        stars.ra_deg[rows],
        stars.dec_deg[rows],
        xy=None if stars.xy is None else stars.xy[rows],
        r_px=None if stars.r_px is None else stars.r_px[rows],
        focal_px=args.focal_px,
        width=args.width,
        height=height,
        sigma_px=args.sigma_px,
        parity=args.parity,
    )
    used = [stars.labels[k] for k in rows]
    if args.json:
        print(_json({**result.to_dict(), "stars_used": used}))
    else:
        _print_pointing(result, used)
    return EXIT_OK


def _cmd_pointing_study(args) -> int:
    from starnav.studies.pointing import format_table, run_study

    if args.sigma_px <= 0:
        raise StarnavError(f"--sigma-px must be positive, got {args.sigma_px:g}")
    if not 1.0 <= args.fov_deg <= 120.0:
        raise StarnavError(
            f"--fov-deg must be between 1 and 120 for the study, got {args.fov_deg:g}"
        )
    if args.width < 64:
        raise StarnavError(f"--width must be at least 64 px for the study, got {args.width}")
    out_dir = Path(args.out_dir)
    if not out_dir.is_dir():
        raise StarnavError(f"--out-dir {args.out_dir!r} is not a directory")
    result = run_study(
        fov_deg=args.fov_deg,
        width=args.width,
        sigma_px=args.sigma_px,
        trials=args.trials,
        seed=args.seed,
        out_dir=out_dir,
    )
    if args.json:
        print(_json(result.to_dict()))
    else:
        print(format_table(result))
    return EXIT_OK


def _cmd_evaluate(args) -> int:
    from starnav.evaluate import EvalConfig, evaluate, grid_boresights, uniform_boresights
    from starnav.evaluate.report import describe, markdown, plot_sky_map, write_frames_csv

    config = EvalConfig(
        fov_deg=args.fov_deg,
        width=args.width,
        height=args.height,
        mag_limit=args.mag_limit,
        noise_px=args.noise_px,
        false_stars=args.false_stars,
        missing_frac=args.missing_frac,
        mag_noise=args.mag_noise,
        algorithm=args.algorithm,
        algorithm_options=cli_options(args.algorithm, args.triangle_selection),
        sigma_px=args.sigma_px,
        seed=args.seed,
    )
    for option, path in (("--frames-csv", args.frames_csv), ("--sky-map", args.sky_map)):
        if path and not Path(path).resolve().parent.is_dir():
            raise StarnavError(f"{option}: the directory of {path!r} does not exist")
    if args.sampling == "grid":
        boresights = grid_boresights(args.grid_step_deg, seed=args.seed)
        sampling = f"{len(boresights)} boresights on a {args.grid_step_deg:g}° RA/Dec grid"
    else:
        boresights = uniform_boresights(args.frames, seed=args.seed)
        sampling = f"{len(boresights)} boresights uniform on the sphere"
    summary, results = evaluate(config, boresights, workers=args.workers, dask_address=args.dask)
    if args.frames_csv:
        write_frames_csv(results, args.frames_csv)
    if args.sky_map:
        plot_sky_map(results, args.sky_map, title=describe(config, sampling))
    if args.json:
        print(_json({**summary.to_dict(), "config": asdict(config), "sampling": sampling}))
    else:
        print(markdown(config, sampling, summary))
    return EXIT_OK


def _cmd_locate(args) -> int:
    from starnav.navigation import FixError, locate, read_observation

    if not args.sigma_px > 0:
        raise StarnavError(f"--sigma-px must be positive, got {args.sigma_px:g}")
    if args.epoch is not None:
        raise StarnavError("--epoch is taken from the observation's utc for locate")
    observation = read_observation(args.observation)
    try:
        fix = locate(
            observation, catalog=args.catalog, mag_limit=args.mag_limit, sigma_px=args.sigma_px
        )
    except FixError as exc:
        if args.json:
            print(_json({"solved": False, "reason": str(exc)}))
        else:
            print(f"no fix: {exc}")
        return EXIT_NOT_SOLVED
    if args.json:
        print(_json({"solved": True, "reason": None, **fix.to_dict()}))
        return EXIT_OK
    print(f"fix: lat {fix.lat_deg:+.6f}°  lon {fix.lon_deg:+.6f}°  heading {fix.azimuth_deg:.4f}°")
    print(
        f"  1σ ellipse {fix.ellipse_major_m:.1f} x {fix.ellipse_minor_m:.1f} m (major axis at "
        f"{fix.ellipse_angle_deg:.0f}° from North), heading 1σ {fix.sigma_azimuth_arcsec:.2f}″, "
        f"{fix.n_stars} stars, rms {fix.rms_arcsec:.2f}″, {fix.time_ms:.0f} ms"
    )
    print("  (stars only: a tilt error of the gravity vector adds about 31 m per arcsecond)")
    for c in fix.cameras:
        status = (
            f"{c.stars_used} of {c.n_points} points identified, boresight RA {c.ra_deg:.3f}° "
            f"Dec {c.dec_deg:+.3f}°"
            if c.stars_used
            else f"not used: {c.reason}"
        )
        print(f"  {c.name}: {status}")
    return EXIT_OK


def _cmd_locate_study(args) -> int:
    from starnav.studies.locate import format_tables, plot_study, run_locate_study

    if not 1.0 <= args.fov_deg <= 60.0:
        raise StarnavError(f"--fov-deg must be between 1 and 60, got {args.fov_deg:g}")
    if args.plot and not Path(args.plot).resolve().parent.is_dir():
        raise StarnavError(f"--plot: the directory of {args.plot!r} does not exist")
    tables = run_locate_study(trials=args.trials, fov_deg=args.fov_deg, seed=args.seed)
    if args.plot:
        plot_study(tables, args.plot)
    if args.json:
        print(_json({name: [asdict(r) for r in rows] for name, rows in tables.items()}))
    else:
        print(format_tables(tables))
    return EXIT_OK


def _cmd_solve(args) -> int:
    from starnav.detect.read import read_image
    from starnav.image import solve_image

    if args.wcs and not args.wcs.lower().endswith((".fits", ".fit", ".fts", ".wcs")):
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
        fit_distortion=args.fit_distortion,
        max_stars=args.max_stars,
        threshold_sigma=args.threshold_sigma,
        sigma_px=args.sigma_px,
        catalog=args.catalog,
        epoch_year=args.epoch,
        parity=args.parity,
    )
    res = replace(res, read_ms=read_ms)  # read here, so the picture can be annotated
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
    if args.json:
        print(_json(res.to_dict(args.image)))
    elif s:
        _print_solution(s)
        cam = res.camera
        print(
            f"  camera: FOV {cam.fov_deg:.4f}°, "
            f"k1 {cam.k1:.5f} k2 {cam.k2:.5f}; {len(res.detections.xy)} stars detected; "
            f"read {res.read_ms:.1f} ms, detect {res.detect_ms:.1f} ms, solve {res.solve_ms:.1f} ms"
        )
    else:
        print(
            f"not solved: {res.reason} ({len(res.detections.xy)} stars detected, "
            f"{res.total_ms:.1f} ms)"
        )
    return EXIT_OK if s else EXIT_NOT_SOLVED


def _cmd_render(args) -> int:
    from starnav.render import adjust_camera, preset, render_frame, write_image, write_truth_csv

    camera, settings = preset(args.preset)
    camera = adjust_camera(
        camera,
        fov_deg=args.fov_deg,
        width=args.width,
        height=args.height,
        k1=args.k1,
        k2=args.k2,
    )
    changes = {
        k: getattr(args, k)
        for k in (*_RENDER_NUMBERS, "bit_depth", "hot_pixels", "mag_limit", "seed")
        if getattr(args, k) is not None
    }
    settings = replace(settings, **changes)
    rng = np.random.default_rng(args.seed)
    R = attitude_from_radec_roll(
        *draw_radec_roll(rng, args.ra_deg, args.dec_deg, args.roll_deg), args.parity
    )
    faintest = 8.0 if settings.mag_limit is None else settings.mag_limit
    frame = render_frame(load_catalog(None, mag_limit=faintest), camera, R, settings)
    write_image(args.output, frame.image)
    if args.truth:
        write_truth_csv(args.truth, frame)
    ra, dec, roll, _ = radec_roll_from_attitude(R)
    truth = {"image": args.output, **frame.to_dict()}
    if args.json:
        print(_json(truth))
    else:
        print(
            f"wrote {args.output}: {camera.width} x {camera.height} px, FOV {camera.fov_deg:.3f}°, "
            f"{len(frame.xy)} stars; RA {ra:.5f}° Dec {dec:+.5f}° roll {roll:.4f}°"
        )
    return EXIT_OK


def _cmd_calibrate(args) -> int:
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
    out = {
        **{k: getattr(cam, k) for k in ("width", "height", "focal_px", "cx", "cy", "k1", "k2")},
        "fov_deg": cam.fov_deg,
        "sigma": cal.sigma,
        "rms_px": cal.rms_px,
        "n_stars": cal.n_stars,
        "frames": list(cal.frames),
        "failed": [{"image": n, "reason": r} for n, r in cal.failed],
        "camera_file": args.output,
    }
    if args.json:
        print(_json(out))
    else:
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


_COMMANDS = {
    "identify": _cmd_identify,
    "simulate": _cmd_simulate,
    "demo": _cmd_demo,
    "database": _cmd_database,
    "evaluate": _cmd_evaluate,
    "locate": _cmd_locate,
    "locate-study": _cmd_locate_study,
    "pointing": _cmd_pointing,
    "pointing-study": _cmd_pointing_study,
    "solve": _cmd_solve,
    "render": _cmd_render,
    "calibrate": _cmd_calibrate,
}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``starnav`` command."""
    args = _build_parser().parse_args(argv)
    try:
        return _COMMANDS[args.command](args)
    except StarnavError as exc:
        print(f"starnav {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print(f"starnav {args.command}: error: out of memory (input too large)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # output piped into head & co: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
