"""``starnav-astap``: ASTAP's command line, solved by starnav.

For the programs that run ASTAP and read the files it writes (N.I.N.A., CCDciel,
StellarSolver, astapy). The options, files and exit codes follow ASTAP's source (Han Kleijn,
github.com/han-k59/astap: ``command-line_version/astap_command_line.lpr``, ``astap_main.pas``
``write_ini``): ``BASE.ini`` always (``PLTSOLVD=T`` and the solution, or ``PLTSOLVD=F``),
``BASE.wcs`` when solved (its header as text lines, or with ``-wcs`` a FITS header like
astrometry.net's), BASE being ``-o`` or the input path, its extension replaced.

The solution is ASTAP's: a TAN projection whose reference pixel is the image centre, FITS
pixel ((W+1)/2, (H+1)/2) (the plate's WCS: ``pipeline.image.solution_wcs``), with CDELT and CROTA
from its CD matrix by inverting the relation ASTAP makes its CD matrix with
(``command-line_version/unit_command_line_solving.pas``: CD1_1 = CDELT1 cos CROTA1, CD1_2 =
-CDELT1 sin CROTA1 f, CD2_1 = CDELT2 sin CROTA2 f, CD2_2 = CDELT2 cos CROTA2, CDELT2 > 0,
f = +-1 the sign of det CD: -1 for the sky as seen with FITS y up, +1 for an image whose first
row is its top, as starnav reads them): CDELT1 = f hypot(CD1_1, CD1_2), CDELT2 =
hypot(CD2_1, CD2_2), CROTA1 = atan2(-CD1_2, f CD1_1), CROTA2 = atan2(f CD2_1, CD2_2). For an
image as starnav reads it (no flip, row 0 = FITS y = 1), CROTA2 = 180° - roll, in (-180, 180].

Exit codes are the documented ones that ASTAP's GUI program returns: 0 solved, 1 no solution,
2 not enough stars, 16 error reading the image, 33 error reading the star database (starnav's
catalog), 34 error updating the input file. (32, no star database found, cannot happen: the
catalog ships with starnav. ``astap_cli`` itself returns 1 for every failure.)
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from starnav.cli.parser import EXIT_BAD_INPUT, Parser, run_console
from starnav.errors import CatalogError, ImageError, StarnavError

if TYPE_CHECKING:  # numpy, astropy and the solver are imported when a file is solved: -h needs none
    import numpy as np
    from astropy.io import fits
    from astropy.wcs import WCS

    from starnav.pipeline.plate import Plate, PlateHints, PlateResult

PROG = "starnav-astap"
EXIT_SOLVED, EXIT_NO_SOLUTION, EXIT_NOT_ENOUGH_STARS = 0, 1, 2
EXIT_IMAGE_ERROR, EXIT_NO_DATABASE, EXIT_DATABASE_ERROR, EXIT_UPDATE_ERROR = 16, 32, 33, 34
# write_ini's ERROR= lines (astap_main.pas); a plain "no solution" writes none
ERRORS = {
    EXIT_NOT_ENOUGH_STARS: "Not enough stars.",
    EXIT_IMAGE_ERROR: "Error reading image file.",
    EXIT_NO_DATABASE: "No star database found.",
    EXIT_DATABASE_ERROR: "Error reading star database.",
}
FOV_TOLERANCE = 0.10  # -fov searched within ±10 % (ASTAP needs it within about that)
SCALE_WARNING = 0.05  # ASTAP warns when the solved height is off the given one by 5 %
BLIND_RADIUS_DEG = 180.0  # -r 180: the whole sky (N.I.N.A. sends it when it knows no position)
# accepted and ignored: they tune ASTAP's own detector, quad matcher or database
IGNORED = ("-s", "-t", "-m", "-d", "-D", "-speed", "-sqm", "-tofits")
IGNORED_FLAGS = ("-progress", "-annotate", "-debug")
REFUSED = ("-extract", "-extract2", "-stack", "-focus1", "-focus2")
ANALYSE_SNR_DEFAULT = 30.0  # -analyse 0: ASTAP's default signal-to-noise floor
HFD_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))  # a Gaussian's half-flux diameter


@dataclass(frozen=True)
class AstapSolution:
    """ASTAP's numbers of a solution: ``crpix`` (FITS px), ``crval`` (RA, Dec, degrees),
    ``cdelt`` (degrees/px), ``crota`` (degrees), ``cd`` (2 x 2, degrees/px), and its TAN ``wcs``."""

    crpix: tuple[float, float]
    crval: tuple[float, float]
    cdelt: tuple[float, float]
    crota: tuple[float, float]
    cd: np.ndarray
    wcs: WCS

    @classmethod
    def from_plate(cls, plate: Plate) -> AstapSolution:
        """The centred TAN solution of a plate (module docstring)."""
        import numpy as np

        tan = plate.wcs  # TAN, CRPIX at the centre (``pipeline.image.solution_wcs``)
        cd = np.array(tan.wcs.cd, dtype=float)
        f = -1.0 if np.linalg.det(cd) < 0 else 1.0
        cdelt = (f * math.hypot(cd[0, 0], cd[0, 1]), math.hypot(cd[1, 0], cd[1, 1]))
        crota = (math.degrees(math.atan2(-cd[0, 1], f * cd[0, 0])),
                 math.degrees(math.atan2(f * cd[1, 0], cd[1, 1])))  # fmt: skip
        crpix = (float(tan.wcs.crpix[0]), float(tan.wcs.crpix[1]))
        crval = (float(tan.wcs.crval[0]), float(tan.wcs.crval[1]))
        return cls(crpix, crval, cdelt, crota, cd, tan)

    def cards(self) -> list[tuple[str, object, str]]:
        """The solution's header cards in ASTAP's order and words."""
        (c11, c12), (c21, c22) = self.cd
        return [
            ("CTYPE1", "RA---TAN", "first parameter RA,    projection TANgential"),
            ("CTYPE2", "DEC--TAN", "second parameter DEC,  projection TANgential"),
            ("CUNIT1", "deg", "Unit of coordinates"),
            ("EQUINOX", 2000.0, "Equinox of coordinates"),
            ("CRPIX1", self.crpix[0], "X of reference pixel"),
            ("CRPIX2", self.crpix[1], "Y of reference pixel"),
            ("CRVAL1", self.crval[0], "RA of reference pixel (deg)"),
            ("CRVAL2", self.crval[1], "DEC of reference pixel (deg)"),
            ("CDELT1", self.cdelt[0], "X pixel size (deg)"),
            ("CDELT2", self.cdelt[1], "Y pixel size (deg)"),
            ("CROTA1", self.crota[0], "Image twist of X axis        (deg)"),
            ("CROTA2", self.crota[1], "Image twist of Y axis        (deg)"),
            ("CD1_1", float(c11), "CD matrix to convert (x,y) to (Ra, Dec)"),
            ("CD1_2", float(c12), "CD matrix to convert (x,y) to (Ra, Dec)"),
            ("CD2_1", float(c21), "CD matrix to convert (x,y) to (Ra, Dec)"),
            ("CD2_2", float(c22), "CD matrix to convert (x,y) to (Ra, Dec)"),
            ("PLTSOLVD", True, "Astrometric solved by starnav"),
        ]


def float_e(value: float) -> str:
    """A number as ASTAP's ``floattostrE`` (Free Pascal's ``str(x)``) writes it to the .ini:
    17 significant digits, a three-digit exponent, a space for the sign of a positive value
    ("CRPIX1= 8.0050000000000000E+002")."""
    mantissa, exponent = f"{value:.16E}".split("E")
    sign = " " if not mantissa.startswith("-") else ""
    return f"{sign}{mantissa}E{exponent[0]}{int(exponent[1:]):03d}"


def build_parser() -> Parser:
    """ASTAP's options (``astap_command_line.lpr``; single dash)."""
    p = Parser(prog=PROG, description=__doc__.split("\n\n")[0], allow_abbrev=False,
               add_help=False)  # fmt: skip
    p.add_argument("-h", "-help", action="store_true", dest="help", help="this help")
    p.add_argument("-f", metavar="FILE", help="image to solve: FITS, TIFF, PNG, JPEG")
    p.add_argument("-r", type=float, metavar="DEG", help="search radius (180: whole sky)")
    p.add_argument("-fov", type=float, metavar="DEG", help="image height (0: unknown)")
    p.add_argument("-ra", type=float, metavar="HOURS", help="RA of the search centre")
    p.add_argument("-spd", type=float, metavar="DEG", help="Dec + 90 of the search centre")
    p.add_argument("-z", type=int, metavar="N", help="downsample by N (0: auto, to 4.2 MP)")
    p.add_argument("-o", metavar="BASE", help="base path of the .ini, .wcs, .log files")
    p.add_argument("-wcs", action="store_true", help="write .wcs as a FITS header")
    p.add_argument("-update", action="store_true", help="put the solution in the input file")
    p.add_argument("-log", action="store_true", help="write BASE.log")
    p.add_argument("-check", nargs="?", const="y", metavar="y/n", help="accepted and ignored")
    p.add_argument("-sip", nargs="?", const="y", metavar="y/n", help="accepted and ignored")
    for flag in IGNORED:
        p.add_argument(flag, metavar="X", help="accepted and ignored (docs/dropin.md)")
    for flag in IGNORED_FLAGS:
        p.add_argument(flag, action="store_true", help="accepted and ignored (docs/dropin.md)")
    p.add_argument("-analyse", type=float, metavar="SNR_MIN",
                   help="only report the median HFD and the stars of at least SNR_MIN")  # fmt: skip
    for flag in REFUSED:
        p.add_argument(flag, metavar="X", help="not done by starnav (exit 2)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ASTAP's command line (``starnav.cli.parser.run_console``: no
    garbage collections; the console script's process ends at once); its exit code."""
    return run_console(_main, argv)


def _main(argv: Sequence[str] | None) -> int:
    program = sys.argv[0] if argv is None else PROG  # ASTAP's CMDLINE starts with its path
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if args.help or not argv:
        parser.print_help()
        return EXIT_SOLVED
    for option in unknown:  # ASTAP ignores options it does not know
        print(f"{PROG}: ignored {option!r}", file=sys.stderr)
    refused = [flag for flag in REFUSED if getattr(args, flag.lstrip("-")) is not None]
    if refused:
        print(f"{PROG}: {refused[0]} is not done by starnav", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.f is None:
        print(f"{PROG}: -f FILE is needed", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.analyse is not None:
        return _analyse(Path(args.f), args.analyse)
    cmdline = " ".join([program, *argv])
    base = Path(args.o) if args.o else Path(args.f)
    log: list[str] = [cmdline]
    try:
        code = _run(args, base, cmdline, log)
    except (StarnavError, OSError) as exc:  # a bad number or an unwritable output folder
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.log:
        _with_suffix(base, ".log").write_text("\n".join(log) + "\n")
    return code


def analyse(image: Path, snr_min: float) -> tuple[float, int]:
    """ASTAP's -analyse: the median half-flux diameter (px) of the image's stars and how many
    have a signal-to-noise of at least ``snr_min`` (0: ``ANALYSE_SNR_DEFAULT``). starnav's
    detection (``starnav.detect.stars.detect_stars``, every star) and its measures: the
    HFD of the PSF it fits (a Gaussian's, 2 sqrt(2 ln 2) sigma: one PSF for the image), the
    signal-to-noise of ``Detections.snr`` (ASTAP measures both per star, its own way)."""
    import numpy as np

    from starnav.detect.read import read_image
    from starnav.detect.stars import detect_stars

    if not (math.isfinite(snr_min) and snr_min >= 0):
        raise StarnavError(f"-analyse takes a signal-to-noise floor >= 0, got {snr_min}")
    found = detect_stars(read_image(image))
    floor = snr_min or ANALYSE_SNR_DEFAULT
    return HFD_PER_SIGMA * found.psf_sigma_px, int(np.sum(found.snr >= floor))


def _analyse(image: Path, snr_min: float) -> int:
    """Print -analyse's two lines as ASTAP's command line does; 0, or 16 when the image
    cannot be read (ASTAP's exit codes on Linux)."""
    try:
        hfd, stars = analyse(image, snr_min)
    except ImageError as exc:
        print(f"Error reading image file: {exc}", flush=True)
        return EXIT_IMAGE_ERROR
    except StarnavError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"HFD_MEDIAN={hfd:.1f}")
    print(f"STARS={stars}")
    return EXIT_SOLVED


def _say(log: list[str], line: str) -> None:
    print(line, flush=True)
    log.append(line)


def _with_suffix(base: Path, suffix: str) -> Path:
    """Free Pascal's ChangeFileExt: the extension of the last name replaced (or added)."""
    return base.with_suffix(suffix) if base.suffix else base.with_name(base.name + suffix)


def _run(args, base: Path, cmdline: str, log: list[str]) -> int:
    from starnav.pipeline.image import MIN_DETECTIONS
    from starnav.pipeline.plate import solve_plate

    image = Path(args.f)
    ini, wcs_path = _with_suffix(base, ".ini"), _with_suffix(base, ".wcs")
    if wcs_path.exists():
        wcs_path.unlink()  # written only when solved: a stale one must not read as this run's
    try:
        _say(log, f"Solving {image}...")
        result = solve_plate(image, functools.partial(_hints, args))
        width, height = result.width, result.height
    except ImageError as exc:
        _say(log, f"Error reading image file: {exc}")
        write_ini(ini, None, cmdline, EXIT_IMAGE_ERROR, None, str(exc))
        return EXIT_IMAGE_ERROR
    except CatalogError as exc:
        _say(log, f"Error reading star database: {exc}")
        write_ini(ini, None, cmdline, EXIT_DATABASE_ERROR, None, str(exc))
        return EXIT_DATABASE_ERROR
    if result.plate is None:
        code = EXIT_NO_SOLUTION
        if result.xy is not None and len(result.xy) < MIN_DETECTIONS:
            code = EXIT_NOT_ENOUGH_STARS
        _say(log, f"No solution found!  :(  ({result.reason})")
        write_ini(ini, None, cmdline, code, (width, height), f"starnav: {result.reason}")
        return code
    solution = AstapSolution.from_plate(result.plate)
    warning = _scale_warning(args.fov, solution, height)
    ra, dec = solution.crval
    _say(log, f"Solution found: RA {ra:.5f}° Dec {dec:+.5f}°, CROTA2 {solution.crota[1]:.3f}°")
    _say(log, f"Solved in {result.time_ms / 1e3:.1f} sec.")
    if warning:
        _say(log, warning)
    write_ini(ini, solution, cmdline, EXIT_SOLVED, (width, height), warning)
    header = wcs_header(solution, image, cmdline, warning, result.time_ms / 1e3)
    if args.wcs:
        header.tofile(wcs_path, overwrite=True, padding=True)
    else:
        text = header.tostring(sep="\n", endcard=True, padding=False)
        wcs_path.write_text(text + "\n")
    if args.update:
        try:
            update_input(image, result, solution)
        except (OSError, StarnavError) as exc:
            _say(log, f"Error updating input file !! {exc}")
            return EXIT_UPDATE_ERROR
    return EXIT_SOLVED


def _hints(args, width: int, height: int) -> PlateHints:
    """starnav's hints of ASTAP's options: -fov (the height) to a width range of ±10 %;
    -ra/-spd with -r below 180 to a position; -z to a downsampling factor."""
    from starnav.pipeline.plate import PlateHints, fov_range_from_scale

    fov_range = None
    if args.fov is not None and args.fov < 0:
        raise StarnavError(f"-fov must be 0 (unknown) or a height in degrees, got {args.fov}")
    if args.fov:  # the width a pinhole camera of this height has
        half = math.radians(args.fov) / 2.0
        width_deg = math.degrees(2.0 * math.atan(math.tan(half) * width / height))
        lo, hi = width_deg * (1 - FOV_TOLERANCE), width_deg * (1 + FOV_TOLERANCE)
        fov_range = fov_range_from_scale("degwidth", lo, hi, width, height)
    position: dict = {}
    radius = BLIND_RADIUS_DEG if args.r is None else args.r
    if args.ra is not None and args.spd is not None and radius < BLIND_RADIUS_DEG:
        dec = args.spd - 90.0
        if not -90.0 <= dec <= 90.0:
            raise StarnavError(f"-spd must be within 0-180 (Dec + 90), got {args.spd}")
        position = {"ra_deg": (args.ra * 15.0) % 360.0, "dec_deg": dec, "radius_deg": radius}
    downsample = args.z if args.z and args.z >= 1 else None
    return PlateHints(fov_range_deg=fov_range, downsample=downsample, crpix_center=True,
                      **position)  # fmt: skip


def _scale_warning(fov_deg: float | None, solution: AstapSolution, height: int) -> str:
    """ASTAP's warning when the given -fov is more than 5 % off the solved height."""
    if not fov_deg:
        return ""
    solved = height * abs(solution.cdelt[1])
    if abs(fov_deg - solved) <= SCALE_WARNING * solved:
        return ""
    return (f"Warning scale was inaccurate! Set FOV={solved:.2f}d, "
            f"scale={abs(solution.cdelt[1]) * 3600:.1f}\"")  # fmt: skip


def write_ini(
    path: Path,
    solution: AstapSolution | None,
    cmdline: str,
    code: int,
    size: tuple[int, int] | None,
    warning: str,
) -> None:
    """ASTAP's ``write_ini`` (astap_main.pas): PLTSOLVD first, the solution's numbers, CMDLINE,
    DIMENSIONS, the ERROR of ``code``, WARNING."""
    lines = ["PLTSOLVD=F"]
    if solution is not None:
        (c11, c12), (c21, c22) = solution.cd
        values = [
            ("CRPIX1", solution.crpix[0]), ("CRPIX2", solution.crpix[1]),
            ("CRVAL1", solution.crval[0]), ("CRVAL2", solution.crval[1]),
            ("CDELT1", solution.cdelt[0]), ("CDELT2", solution.cdelt[1]),
            ("CROTA1", solution.crota[0]), ("CROTA2", solution.crota[1]),
            ("CD1_1", c11), ("CD1_2", c12), ("CD2_1", c21), ("CD2_2", c22),
        ]  # fmt: skip
        lines = ["PLTSOLVD=T"] + [f"{k}={float_e(float(v))}" for k, v in values]
    lines.append(f"CMDLINE={cmdline}")
    if size is not None:
        lines.append(f"DIMENSIONS={size[0]} x {size[1]}")
    if code in ERRORS:
        lines.append(f"ERROR={ERRORS[code]}")
    if warning:
        lines.append(f"WARNING={warning}")
    path.write_text("\n".join(lines) + "\n")


def wcs_header(
    solution: AstapSolution, image: Path, cmdline: str, warning: str, solved_s: float
) -> fits.Header:
    """The .wcs header: SIMPLE, BITPIX 8, NAXIS 0, a FITS image's own cards (its size and WCS
    cards left out), then the solution (``AstapSolution.cards``), ASTAP's comments."""
    from astropy.io import fits

    from starnav.detect.header import is_fits

    header = fits.Header([("SIMPLE", True), ("BITPIX", 8), ("NAXIS", 0)])
    if is_fits(image):
        skip = {card[0] for card in solution.cards()} | {"SIMPLE", "BITPIX", "NAXIS", "EXTEND"}
        with fits.open(image, memmap=False) as hdul:
            for card in hdul[0].header.cards:
                keyword = card.keyword
                if keyword in skip or keyword.startswith(("NAXIS", "PC", "CD", "A_", "B_", "AP_",
                                                          "BP_")):  # fmt: skip
                    continue
                header.append(card)
    for card in solution.cards():
        header.append(card)
    header.append(("COMMENT", f"7 Solved in {solved_s:.1f} sec. by starnav."))
    if warning:
        header.append(("WARNING", warning))
    text = f"cmdline:{cmdline}"  # add_long_comment: pieces of 72 characters
    for i in range(0, len(text), 72):
        header.append(("COMMENT", text[i : i + 72]))
    return header


def update_input(image: Path, result: PlateResult, solution: AstapSolution) -> None:
    """ASTAP's -update: the solution added to a FITS file's header, or for another format a
    new FITS file of the image (input path, extension .fits) with it."""
    from astropy.io import fits

    from starnav.detect.header import is_fits
    from starnav.pipeline.plate import write_plate_files

    if is_fits(image):
        with fits.open(image, mode="update", memmap=False) as hdul:
            target = next((h for h in hdul if h.header.get("NAXIS") == 2), hdul[0])
            for card in solution.cards():
                target.header[card[0]] = card[1:]
        return
    write_plate_files(result, image, new_fits=image.with_suffix(".fits"))


if __name__ == "__main__":
    sys.exit(main())
