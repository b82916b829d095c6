"""``starnav-solve-field``: astrometry.net's ``solve-field`` command line, solved by starnav.

Made for the programs that run ``solve-field`` and read what it prints and writes (INDI's
``indi_astrometry``, Ekos, CCDciel, ...). It takes their arguments, writes the files under
solve-field's names (``BASE.wcs``, ``BASE.new``, ``BASE.solved``) and prints solve-field's
result lines (``solver/solve-field.c``, ``after_solved``), with the numbers of
``starnav.pipeline.plate.Plate`` (astrometry.net's own formulas on the WCS). Pixels are FITS pixels
(1-based, row order of the data, no flip: a JPEG's top row is y = 1, as solve-field reads it).

One line is out of solve-field's order: its engine prints "RA,Dec = (...), pixel scale S
arcsec/pix." while solving, before the "Field ..." block. ``indi_astrometry`` stops reading at
the line that completes its four numbers (centre, rotation angle, pixel scale), so with
solve-field's order it never sees the parity line; printed after "Field parity:", the pixel
scale line lets it read all five. Exit status as solve-field: 0 solved or not (it prints "Did
not solve"); 2 for bad arguments or an unreadable input (one line on stderr).
See docs/dropin.md for what each option does here.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from starnav.cli.parser import EXIT_BAD_INPUT, Parser, freeze_at_exit
from starnav.errors import StarnavError

if TYPE_CHECKING:  # numpy and the solver are imported when a file is solved: --help needs neither
    import numpy as np

    from starnav.pipeline.plate import Plate, PlateHints, PlateResult, XYList

PROG = "starnav-solve-field"
EXIT_OK = 0  # solve-field exits 0 whether or not the field solved
# solve-field's names of the scale units (solver/augment-xylist.c, parse_scale_units)
SCALE_UNIT_NAMES = {
    "degwidth": "degwidth", "degw": "degwidth", "dw": "degwidth",
    "arcminwidth": "arcminwidth", "amw": "arcminwidth", "aw": "arcminwidth",
    "arcsecperpix": "arcsecperpix", "app": "arcsecperpix",
    "focalmm": "focalmm",
}  # fmt: skip
# accepted so that clients' command lines run; they tune astrometry.net's own engine, index
# files or by-products that starnav does not have (docs/dropin.md says why for each)
IGNORED_FLAGS = (
    "--no-verify", "--no-remove-lines", "--continue", "--no-fits2fits", "--guess-scale",
    "--resort", "--no-background-subtraction", "--no-tweak", "--invert",
    "--no-delete-temp", "--fits-image", "--timestamp", "--temp-axy", "--verbose",
)  # fmt: skip
IGNORED_VALUES = (
    "--uniformize", "--objs", "--depth", "--temp-dir", "--config", "--backend-config",
    "--tweak-order",
    "--sigma", "--nsigma", "--plot-scale", "--plot-bg", "--extension", "--code-tolerance",
    "--index-dir", "--index-file", "--scamp", "--scamp-config",
    "--sort-column", "--pnm", "--cancel", "--solved-in",
)  # fmt: skip
SHORT_IGNORED = {"--tweak-order": "-t", "--depth": "-d", "--temp-dir": "-m",
                 "--backend-config": "-b", "--objs": None}  # fmt: skip
# the side files' options (``output_paths``): (option, short letter or None, default
# path with "%s" for BASE or None, help); an option here is written, not ignored
# (solver/solve-field.c: .axy, .corr, .match, .rdls, -indx.xyls by default, "none" disables
# them but .axy, which --temp-axy drops; --keep-xylist and --kmz only when given)
SIDE_FILE_OPTIONS: tuple[tuple[str, str | None, str | None, str], ...] = (
    ("--axy", None, "%s.axy", "augmented xylist: sources and solver keywords (default BASE.axy)"),
    ("--corr", "-B", "%s.corr", "matched field and catalog stars (default BASE.corr)"),
    ("--match", "-M", "%s.match", "the match's summary, MatchObj (default BASE.match)"),
    ("--rdls", "-R", "%s.rdls", "RA, Dec of the catalog stars in the field (default BASE.rdls)"),
    ("--index-xyls", "-U", "%s-indx.xyls", "x, y of those stars (default BASE-indx.xyls)"),
    ("--keep-xylist", "-k", None, "the sources, unaugmented xylist (not written by default)"),
    ("--kmz", "-Z", None, "a KML ground overlay of the image, zipped (not written by default)"),
)


@dataclass(frozen=True)
class OutputPaths:
    """Where one input's files go (None: not written): ``wcs``, ``new_fits``, ``solved`` and
    the side files by ``write_plate_files``'s kind (``side``: axy, corr, match, rdls,
    index_xyls, xyls, kmz)."""

    base: Path
    wcs: Path | None
    new_fits: Path | None
    solved: Path | None
    side: dict[str, Path] = field(default_factory=dict)

    def outputs(self) -> list[Path]:
        """Every file this input's solve writes."""
        return [p for p in (self.wcs, self.new_fits, self.solved, *self.side.values()) if p]

    def existing(self) -> list[Path]:
        """The outputs that exist already."""
        return [p for p in self.outputs() if p.exists()]


def build_parser() -> Parser:
    """solve-field's options (those clients pass; see the module docstring)."""
    p = Parser(prog=PROG, description=__doc__.split("\n\n")[0], allow_abbrev=False)
    p.add_argument(
        "inputs",
        nargs="+",
        metavar="FILE",
        help="image (FITS, PNG, JPEG, TIFF) or xylist (FITS table of x, y)",
    )
    p.add_argument("-O", "--overwrite", action="store_true", help="overwrite output files")
    p.add_argument(
        "-p",
        "--no-plots",
        action="store_true",
        help="accepted: starnav never makes solve-field's plots",
    )
    p.add_argument(
        "-u",
        "--scale-units",
        default="degwidth",
        help="units of --scale-low/--scale-high: degwidth (dw), arcminwidth (amw), "
        "arcsecperpix (app), focalmm (default degwidth)",
    )
    p.add_argument("-L", "--scale-low", type=float, help="lower bound of the scale")
    p.add_argument("-H", "--scale-high", type=float, help="upper bound of the scale")
    p.add_argument("-3", "--ra", help="RA of the field centre: degrees or HH:MM:SS")
    p.add_argument("-4", "--dec", help="Dec of the field centre: degrees or [+-]DD:MM:SS")
    p.add_argument("-5", "--radius", type=float, help="search within this radius (degrees)")
    p.add_argument("-z", "--downsample", type=int, help="bin the image by N (default: to 4.2 MP)")
    p.add_argument(
        "--crpix-center",
        action="store_true",
        help="put the WCS reference pixel at the image centre",
    )
    p.add_argument(
        "-8",
        "--parity",
        choices=("pos", "neg", "both"),
        default="both",
        help="solve-field's parity (pos: det CD < 0; normal images are neg)",
    )
    p.add_argument("--pixel-error", type=float,
                   help="centroid error (px) of the matching tolerances (default 1)")  # fmt: skip
    p.add_argument("-l", "--cpulimit", type=float, help="time budget of the solve (seconds)")
    p.add_argument("-W", "--wcs", help="WCS output file (default BASE.wcs)")
    p.add_argument("-N", "--new-fits", help='new FITS file (default BASE.new; "none": not made)')
    p.add_argument("-S", "--solved", help="the 'solved' flag file (default BASE.solved)")
    p.add_argument("-D", "--dir", help="directory of the output files (default: the input's)")
    p.add_argument("-o", "--out", help="base name of the output files (default: the input's)")
    p.add_argument("-X", "--x-column", default="X", help="xylist: x column (default X)")
    p.add_argument("-Y", "--y-column", default="Y", help="xylist: y column (default Y)")
    p.add_argument("-w", "--width", type=int, help="xylist: image width (px)")
    p.add_argument("-e", "--height", type=int, help="xylist: image height (px)")
    for flag, short, _, text in SIDE_FILE_OPTIONS:
        p.add_argument(*(n for n in (short, flag) if n), metavar="FILE", help=text)
    for flag in IGNORED_FLAGS:
        p.add_argument(flag, action="store_true", help="accepted and ignored (docs/dropin.md)")
    for flag in IGNORED_VALUES:
        short = SHORT_IGNORED.get(flag)
        names = (short, flag) if short else (flag,)
        p.add_argument(*names, metavar="X", help="accepted and ignored (docs/dropin.md)")
    p.add_argument("-y", dest="no_verify_short", action="store_true", help="= --no-verify")
    p.add_argument("-r", dest="resort_short", action="store_true", help="= --resort")
    p.add_argument("-K", dest="continue_short", action="store_true", help="= --continue")
    p.add_argument("-g", dest="guess_scale_short", action="store_true", help="= --guess-scale")
    p.add_argument("-v", dest="verbose_short", action="store_true", help="= --verbose")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run solve-field's command line; the exit status."""
    freeze_at_exit()
    args = build_parser().parse_args(_joined_values(sys.argv[1:] if argv is None else argv))
    try:
        hints_common = _hints(args)
        for i, infile in enumerate(args.inputs, start=1):
            _solve_one(Path(infile), i, len(args.inputs), args, hints_common)
    except (StarnavError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


def _joined_values(argv: Sequence[str]) -> list[str]:
    """ "--dec -30:00:00" as "--dec=-30:00:00": getopt takes a value that starts with "-",
    argparse would take it for an option."""
    out: list[str] = []
    names = {"-3": "--ra", "-4": "--dec", "--ra": "--ra", "--dec": "--dec"}
    items = list(argv)
    i = 0
    while i < len(items):
        if items[i] in names and i + 1 < len(items) and items[i + 1].startswith("-"):
            out.append(f"{names[items[i]]}={items[i + 1]}")
            i += 2
            continue
        out.append(items[i])
        i += 1
    return out


def _hints(args) -> dict:
    """The hints that do not depend on the image (the scale needs its width)."""
    from starnav.pipeline.plate import dec_deg_from_text, parity_from_nova, ra_deg_from_text

    out: dict = {"parity": parity_from_nova(args.parity), "crpix_center": args.crpix_center}
    if (args.ra is None) != (args.dec is None):
        raise StarnavError("--ra and --dec go together")
    if args.ra is not None:
        out.update(ra_deg=ra_deg_from_text(args.ra), dec_deg=dec_deg_from_text(args.dec),
                   radius_deg=args.radius)  # fmt: skip
    if args.downsample is not None and args.downsample < 1:
        raise StarnavError(f"--downsample must be at least 1, got {args.downsample}")
    out["downsample"] = args.downsample
    out["positional_error_px"] = args.pixel_error
    if args.scale_units.lower() not in SCALE_UNIT_NAMES:
        raise StarnavError(f"unknown --scale-units {args.scale_units!r}; known: "
                           f"{', '.join(SCALE_UNIT_NAMES)}")  # fmt: skip
    if args.cpulimit is not None and not (math.isfinite(args.cpulimit) and args.cpulimit > 0):
        raise StarnavError(f"--cpulimit must be a positive number of seconds, got {args.cpulimit}")
    return out


def output_paths(infile: Path, args) -> OutputPaths:
    """solve-field's names (``solver/solve-field.c``): BASE is ``--dir`` (else the input's
    directory) / ``--out`` (else the input's name without .gz/.bz2 and a 2-4 letter suffix);
    ``-W``, ``--new-fits``, ``--solved`` and the side files' options (``SIDE_FILE_OPTIONS``)
    replace a file's path ("%s" in them: BASE; "none": not written, as solve-field reads it for
    every file but .axy, which ``--temp-axy`` drops)."""
    name = args.out or infile.name
    for packed in (".gz", ".bz2"):
        name = name.removesuffix(packed)
    dot = name.rfind(".")
    if not args.out and len(name) - dot in (3, 4, 5) and dot > 0:
        name = name[:dot]
    base = Path(args.dir) / name if args.dir else infile.parent / name

    def path(option: str | None, suffix: str) -> Path | None:
        if option is not None and option.lower() == "none":
            return None  # solve-field's none_is_null: the file is not written
        return Path(option.replace("%s", str(base))) if option else Path(f"{base}{suffix}")

    new_fits = path(args.new_fits, ".new")
    side = {}
    for flag, _, default, _ in SIDE_FILE_OPTIONS:
        given = getattr(args, flag[2:].replace("-", "_"), None) or default
        if given and given.lower() != "none":
            side[_SIDE_KIND.get(flag, flag[2:])] = Path(given.replace("%s", str(base)))
    if getattr(args, "temp_axy", False):
        side.pop("axy", None)  # solve-field keeps it in its temporary directory
    return OutputPaths(base, path(args.wcs, ".wcs"), new_fits, path(args.solved, ".solved"),
                       side)  # fmt: skip


_SIDE_KIND = {"--index-xyls": "index_xyls", "--keep-xylist": "xyls"}


def read_xylist(path: Path, args) -> XYList | None:
    """The source list of an xylist file (a FITS file whose first table has the ``--x-column``,
    ``--y-column`` columns, FITS pixels), None for an image. The image size: ``--width``,
    ``--height``, else the header's IMAGEW, IMAGEH, else the largest x, y rounded up."""
    from starnav.detect.header import is_fits

    if not is_fits(path):
        return None
    import numpy as np
    from astropy.io import fits

    from starnav.pipeline.plate import XYList

    try:
        with fits.open(path, memmap=False) as hdul:
            table = next((h for h in hdul if isinstance(h, fits.BinTableHDU | fits.TableHDU)),
                         None)  # fmt: skip
            if table is None or hdul[0].data is not None:
                return None
            names = {n.upper(): n for n in table.columns.names}
            missing = [c for c in (args.x_column, args.y_column) if c.upper() not in names]
            if missing:
                raise StarnavError(f"xylist {str(path)!r} has no column {missing[0]!r} "
                                   f"(columns: {', '.join(table.columns.names)})")  # fmt: skip
            x = np.asarray(table.data[names[args.x_column.upper()]], dtype=float)
            y = np.asarray(table.data[names[args.y_column.upper()]], dtype=float)
            header = hdul[0].header + table.header
    except OSError as exc:
        raise StarnavError(f"cannot read {str(path)!r} as FITS: {exc}") from None
    width = args.width or header.get("IMAGEW") or math.ceil(float(np.max(x, initial=1.0)))
    height = args.height or header.get("IMAGEH") or math.ceil(float(np.max(y, initial=1.0)))
    return XYList.make(x, y, width, height)


def _solve_one(infile: Path, number: int, count: int, args, common: dict) -> None:
    from starnav.pipeline.plate import PlateHints, solve_plate

    if not infile.is_file():
        raise StarnavError(f"input file {str(infile)!r} does not exist")
    paths = output_paths(infile, args)
    paths.base.parent.mkdir(parents=True, exist_ok=True)  # solve-field makes --dir
    existing = paths.existing()
    if existing and not args.overwrite:
        print(f'Output file already exists: "{existing[0]}".\n'
              "Use the --overwrite flag to overwrite existing files,\n"
              " or the --continue  flag to not overwrite existing files but still try solving.\n"
              "Continuing to next input file.")  # fmt: skip
        return
    print(f'Reading input file {number} of {count}: "{infile}"...', flush=True)
    xylist = read_xylist(infile, args)
    source: Path | XYList = xylist if xylist is not None else infile

    def hints(width: int, height: int) -> PlateHints:  # the scale needs the image's width
        return PlateHints(fov_range_deg=_fov_range(args, width), **common)

    print("Solving...", flush=True)
    result = solve_plate(source, hints, time_budget_s=args.cpulimit)
    for p in paths.outputs():
        if p is not None and p.exists():
            p.unlink()  # a stale file must not read as this run's answer
    print_result(result, str(infile), paths, image=xylist is None)
    sys.stdout.flush()


def _fov_range(args, width: int) -> tuple[float, float] | None:
    if args.scale_low is None and args.scale_high is None:
        return None
    low = args.scale_low if args.scale_low is not None else args.scale_high
    high = args.scale_high if args.scale_high is not None else args.scale_low
    units = SCALE_UNIT_NAMES[args.scale_units.lower()]
    from starnav.pipeline.plate import fov_range_from_scale

    return fov_range_from_scale(units, low, high, width)


def print_result(result: PlateResult, field: str, paths: OutputPaths, *, image: bool) -> None:
    """Write the files and print solve-field's lines for one solve."""
    from starnav.pipeline.plate import write_plate_files

    plate = result.plate
    source = None if result.image is None else field
    sources_only = {k: v for k, v in paths.side.items() if k in ("axy", "xyls")}
    if plate is None:
        write_plate_files(result, source, **sources_only)  # solve-field writes them first
        print(f"Field 1 did not solve ({result.reason}).")
        print(f"Field: {field}")
        print("Did not solve (or no WCS file was written).")
        return
    side = {k: v for k, v in paths.side.items() if image or k != "kmz"}
    write_plate_files(result, source, wcs=paths.wcs,
                      new_fits=paths.new_fits if image else None, **side)  # fmt: skip
    print("Field 1: solved with index starnav (Hipparcos).")
    if paths.solved is not None:
        print(f"Field 1 solved: writing to file {paths.solved} to indicate this.")
        paths.solved.write_bytes(b"\x01")
    print(f"Field: {field}")
    for line in result_lines(plate):
        print(line)
    if image and paths.new_fits is not None:
        print(f'Creating new FITS file "{paths.new_fits}"...')


def result_lines(plate: Plate) -> list[str]:
    """solve-field's lines for a solved field, then the pixel scale line (module docstring)."""
    rastr, decstr = ra_hms_string(plate.ra_deg), dec_dms_string(plate.dec_deg)
    width, height, units = field_size(plate)
    return [
        f"Field center: (RA,Dec) = ({plate.ra_deg:3.6f}, {plate.dec_deg:3.6f}) deg.",
        f"Field center: (RA H:M:S, Dec D:M:S) = ({rastr}, {decstr}).",
        f"Field size: {_g(width)} x {_g(height)} {units}",
        f"Field rotation angle: up is {_g(plate.orientation_deg)} degrees E of N",
        f"Field parity: {plate.parity_name}",
        f"  RA,Dec = ({_g(plate.ra_deg)},{_g(plate.dec_deg)}), "
        f"pixel scale {_g(plate.pixscale_arcsec)} arcsec/pix.",
    ]


def _g(value: float) -> str:
    """C's %g."""
    return f"{value:g}"


def ra_hms_string(ra_deg: float) -> str:
    """The text "HH:MM:SS.sss" (``util/starutil.c``, ``ra2hmsstring``)."""
    rem = (ra_deg % 360.0) / 15.0
    h = math.floor(rem)
    rem = (rem - h) * 60.0
    m = math.floor(rem)
    return _sexagesimal("", h, m, (rem - m) * 60.0)


def dec_dms_string(dec_deg: float) -> str:
    """The text "+DD:MM:SS.sss" (``util/starutil.c``, ``dec2dmsstring``)."""
    sign = "+" if dec_deg >= 0 else "-"
    rem = abs(dec_deg)
    d = math.floor(rem)
    rem = (rem - d) * 60.0
    m = math.floor(rem)
    return _sexagesimal(sign, d, m, (rem - m) * 60.0)


def _sexagesimal(sign: str, a: int, m: int, s: float) -> str:
    ss = math.floor(s)
    ds = round((s - ss) * 1000.0)
    if ds >= 1000:
        ss, ds = ss + 1, ds - 1000
    if ss >= 60:
        ss, m = ss - 60, m + 1
    if m >= 60:
        m, a = m - 60, a + 1
    return f"{sign}{a:02d}:{m:02d}:{ss:02d}.{ds:03d}"


def field_size(plate: Plate) -> tuple[float, float, str]:
    """Width and height through the middle of the image, in arcseconds, arcminutes or degrees
    as solve-field chooses (``util/sip-utils.c``, ``sip_get_field_size``)."""
    import numpy as np

    w, h = plate.width, plate.height
    mid_x, mid_y = (0.5 + w + 0.5) / 2.0, (0.5 + h + 0.5) / 2.0
    across = [(0.5, mid_y), (mid_x, mid_y), (w + 0.5, mid_y)]
    down = [(mid_x, 0.5), (mid_x, mid_y), (mid_x, h + 0.5)]
    width, height = (_path_arcsec(plate.wcs.all_pix2world(np.array(p), 1)) for p in (across, down))
    if min(width, height) < 60.0:
        return width, height, "arcseconds"
    if min(width, height) < 3600.0:
        return width / 60.0, height / 60.0, "arcminutes"
    return width / 3600.0, height / 3600.0, "degrees"


def _path_arcsec(radec_deg: np.ndarray) -> float:
    import numpy as np

    from starnav.geometry import radec_to_unit

    v = radec_to_unit(np.radians(radec_deg[:, 0]), np.radians(radec_deg[:, 1]))
    dots = np.clip(np.sum(v[:-1] * v[1:], axis=1), -1.0, 1.0)
    return float(np.degrees(np.sum(np.arccos(dots))) * 3600.0)


if __name__ == "__main__":
    sys.exit(main())
