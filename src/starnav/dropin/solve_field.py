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

The command line is read as solve-field's getopt_long reads it (``getopt_argv``: unique
prefixes of long options, bundled short flags, values that begin with "-"), over solve-field's
whole option table. Options that mean something here are honoured (scale, position, parity,
sort column and order, ``--odds-to-solve`` as a false-match probability, the reference pixel,
``-T``, ``-C``, SExtractor); the others are accepted and each named once on stderr with the
reason. See docs/dropin.md for what each option does here.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from starnav.cli.parser import EXIT_BAD_INPUT, Parser, run_console
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
# solve-field's options that starnav accepts and does not apply (docs/dropin.md): the option,
# its short letter (None: long only) and why. A client's line runs; each one it gives is
# named once on stderr ("starnav-solve-field: ignored: --uniformize 0 (...)"). Options of
# solve-field's engine that the real tool has (solver/solve-field.c and the options of
# solver/augment-xylist.c it keeps) and the side files starnav does not write yet.
ENGINE = "tunes astrometry.net's engine; starnav verifies with its own false-match probability"
EXTRACT = "tunes astrometry.net's source extraction; starnav finds and orders stars its own way"
NO_REUSE = "starnav never reuses a WCS in the input's header"
ONE_LEVEL = "starnav has one verbosity"
INDEX = "astrometry.net's index files and engine; starnav uses its own catalog"
PLOTS = "starnav makes no plots"
TEMP = "starnav keeps no temporary files"
SIDE = "a file starnav does not write"
HEADER = "a FITS header's scale and position are always read"
VERIFY = "starnav solves every input; it does not verify a given WCS"
SIP = "starnav chooses the SIP order from the matched stars"
IGNORED_FLAGS = (
    "--no-verify", "--no-remove-lines", "--no-fits2fits", "--guess-scale", "--resort",
    "--no-background-subtraction", "--invert", "--no-delete-temp", "--fits-image",
    "--timestamp", "--verbose", "--no-verify-uniformize", "--no-verify-dedup",
    "--tag-all", "--dont-augment", "--just-augment", "--batch", "--use-wget",
)  # fmt: skip
IGNORED_VALUES = (
    "--uniformize", "--depth", "--temp-dir", "--keep-xylist", "--corr", "--match",
    "--rdls", "--index-xyls", "--axy", "--config", "--backend-config", "--tweak-order",
    "--sigma", "--nsigma", "--plot-scale", "--plot-bg", "--extension", "--code-tolerance",
    "--index-dir", "--index-file", "--kmz", "--scamp", "--scamp-config", "--pnm",
    "--solved-in", "--odds-to-tune-up", "--odds-to-reject", "--odds-to-stop-looking",
    "--quad-size-min", "--quad-size-max", "--sort-rdls", "--tag", "--scamp-ref", "--verify",
    "--verify-ext", "--predistort", "--xscale", "--fields",
)  # fmt: skip
SHORT_IGNORED = {"--tweak-order": "-t", "--depth": "-d", "--temp-dir": "-m",
                 "--keep-xylist": "-k", "--corr": "-B", "--match": "-M", "--rdls": "-R",
                 "--index-xyls": "-U", "--backend-config": "-b", "--no-verify": "-y",
                 "--resort": "-r", "--guess-scale": "-g", "--verbose": "-v",
                 "--no-delete-temp": "-7", "--no-remove-lines": "-9", "--extension": "-6",
                 "--code-tolerance": "-c", "--quad-size-min": "-q", "--quad-size-max": "-Q",
                 "--kmz": "-Z", "--scamp": "-i", "--scamp-config": "-n", "--scamp-ref": "-j",
                 "--solved-in": "-I", "--pnm": "-P", "--dont-augment": "-A", "--verify": "-V",
                 "--fields": "-F", "--use-wget": "-G"}  # fmt: skip
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
IGNORED_WHY = {
    **dict.fromkeys(("--guess-scale", "--fits-image", "--no-fits2fits"), HEADER),
    **dict.fromkeys(("--verify", "--verify-ext", "--solved-in"), VERIFY),
    **dict.fromkeys(("--no-remove-lines", "--resort", "--no-background-subtraction",
                     "--invert", "--uniformize", "--sigma", "--nsigma", "--extension",
                     "--predistort", "--xscale", "--fields"), EXTRACT),
    **dict.fromkeys(("--no-delete-temp", "--timestamp", "--temp-dir", "--dont-augment",
                     "--just-augment", "--use-wget"), TEMP),
    **dict.fromkeys(("--no-verify-uniformize", "--no-verify-dedup", "--depth",
                     "--code-tolerance", "--odds-to-tune-up", "--odds-to-reject",
                     "--odds-to-stop-looking", "--quad-size-min", "--quad-size-max"), ENGINE),
    **dict.fromkeys(("--config", "--backend-config", "--index-dir", "--index-file",
                     "--batch"), INDEX),
    **dict.fromkeys(("--plot-scale", "--plot-bg", "--pnm"), PLOTS),
    "--tweak-order": SIP,
    "--no-verify": NO_REUSE,
    "--verbose": ONE_LEVEL,
}  # fmt: skip


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
    """solve-field's options: those of ``solver/solve-field.c`` and the options of
    ``solver/augment-xylist.c`` it keeps (see the module docstring and docs/dropin.md)."""
    p = Parser(prog=PROG, description=__doc__.split("\n\n")[0], allow_abbrev=False)
    p.add_argument(
        "inputs",
        nargs="*",
        metavar="FILE",
        help="image (FITS, PNG, JPEG, TIFF) or xylist (FITS table of x, y)",
    )
    p.add_argument("--version", action="store_true", help="print the version and exit")
    p.add_argument("-O", "--overwrite", action="store_true", help="overwrite output files")
    p.add_argument("-K", "--continue", dest="continue_", action="store_true",
                   help="solve and write over existing output files, as --overwrite")  # fmt: skip
    p.add_argument("-J", "--skip-solved", action="store_true",
                   help="skip an input whose 'solved' file exists")  # fmt: skip
    p.add_argument("-f", "--files-on-stdin", action="store_true",
                   help="read the input file names on stdin, one a line")  # fmt: skip
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
    p.add_argument("--crpix-x", type=float, metavar="PIX",
                   help="the WCS reference pixel's x (FITS px; default the centre)")  # fmt: skip
    p.add_argument("--crpix-y", type=float, metavar="PIX",
                   help="the WCS reference pixel's y (FITS px; default the centre)")  # fmt: skip
    p.add_argument(
        "-8",
        "--parity",
        choices=("pos", "neg", "both"),
        default="both",
        help="solve-field's parity (pos: det CD < 0; normal images are neg)",
    )
    p.add_argument("-E", "--pixel-error", type=float,
                   help="centroid error (px) of the matching tolerances (default 1)")  # fmt: skip
    p.add_argument("--odds-to-solve", type=float, metavar="ODDS",
                   help="accept at a false-match probability of at most 1/(1+ODDS) "
                   "(at most starnav's default; default 1e9 is stricter than it)")  # fmt: skip
    p.add_argument("-l", "--cpulimit", type=float, help="time budget of the solve (seconds)")
    p.add_argument("-C", "--cancel", metavar="FILE",
                   help="stop solving when this file appears")  # fmt: skip
    p.add_argument("-T", "--no-tweak", action="store_true",
                   help="a plain TAN WCS (no SIP terms)")  # fmt: skip
    p.add_argument("-W", "--wcs", help="WCS output file (default BASE.wcs)")
    p.add_argument("-N", "--new-fits", help='new FITS file (default BASE.new; "none": not made)')
    p.add_argument("-S", "--solved", help="the 'solved' flag file (default BASE.solved)")
    p.add_argument("-D", "--dir", help="directory of the output files (default: the input's)")
    p.add_argument("-o", "--out", help="base name of the output files (default: the input's)")
    _add_source_list_options(p)
    p.add_argument("--temp-axy", action="store_true",
                   help="the augmented xylist (.axy) is not kept")  # fmt: skip
    side_flags = {flag for flag, *_ in SIDE_FILE_OPTIONS}
    for flag, short, _, text in SIDE_FILE_OPTIONS:
        p.add_argument(*(n for n in (short, flag) if n), metavar="FILE", help=text)
    for flag in IGNORED_FLAGS:
        short = SHORT_IGNORED.get(flag)
        names = (short, flag) if short else (flag,)
        p.add_argument(*names, action=_Ignored, nargs=0,
                       help="accepted and ignored (docs/dropin.md)")  # fmt: skip
    for flag in (f for f in IGNORED_VALUES if f not in side_flags):
        short = SHORT_IGNORED.get(flag)
        names = (short, flag) if short else (flag,)
        p.add_argument(*names, action=_Ignored, metavar="X",
                       help="accepted and ignored (docs/dropin.md)")  # fmt: skip
    p.set_defaults(ignored=[])
    return p


def _add_source_list_options(p: Parser) -> None:
    """The options of an xylist input and of SExtractor's source lists."""
    p.add_argument("-X", "--x-column", default="X", help="xylist: x column (default X)")
    p.add_argument("-Y", "--y-column", default="Y", help="xylist: y column (default Y)")
    p.add_argument("-s", "--sort-column", metavar="COLUMN",
                   help="xylist: sort the sources by this column (default: FLUX, FLUX_AUTO "
                   "or MAG_AUTO when there is one, else as given)")  # fmt: skip
    p.add_argument("-a", "--sort-ascending", action="store_true",
                   help="xylist: sort smallest first (a magnitude); default largest")  # fmt: skip
    p.add_argument("--objs", type=int, metavar="N",
                   help="xylist: solve the first (brightest) N sources")  # fmt: skip
    p.add_argument("-w", "--width", type=int, help="xylist: image width (px)")
    p.add_argument("-e", "--height", type=int, help="xylist: image height (px)")
    p.add_argument("--use-source-extractor", action="store_true",
                   help="find the sources with SExtractor (source-extractor) instead")  # fmt: skip
    p.add_argument("--source-extractor-path", metavar="PATH",
                   help="SExtractor's program (and arguments); implies the above")  # fmt: skip
    p.add_argument("--source-extractor-config", metavar="FILE",
                   help="SExtractor's config file; implies --use-source-extractor")  # fmt: skip


class _Ignored(argparse.Action):
    """An option starnav accepts and does not apply: kept as (option, value) in
    ``ignored``, to be named once on stderr (``IGNORED_WHY`` says why)."""

    def __call__(self, parser, namespace, values, option_string=None):
        long_name = next(o for o in self.option_strings if o.startswith("--"))
        namespace.ignored = [*namespace.ignored, (long_name, values)]


def main(argv: Sequence[str] | None = None) -> int:
    """Run solve-field's command line (``starnav.cli.parser.run_console``: no
    garbage collections; the console script's process ends at once); its exit code."""
    return run_console(_main, argv)


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(getopt_argv(parser, sys.argv[1:] if argv is None else argv))
    if args.version:
        from starnav.cli import version

        print(f"starnav {version()} (solve-field's command line)")
        return EXIT_OK
    try:
        inputs = list(args.inputs)
        if args.files_on_stdin:
            inputs += [line.strip() for line in sys.stdin if line.strip()]
        if not inputs:
            raise StarnavError("no input file (FILE, or names on stdin with --files-on-stdin)")
        hints_common = _hints(args)
        _report_ignored(args.ignored)
        for i, infile in enumerate(inputs, start=1):
            _solve_one(Path(infile), i, len(inputs), args, hints_common)
    except (StarnavError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


def getopt_argv(parser: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """``argv`` as getopt_long reads it (``util/an-opts.c``), written out for argparse: a
    long option may be any unique prefix of its name (an exact name wins; a prefix of
    several is an error, exit 2), a required value is the next word whatever it starts with
    ("--dec -30:00:00"), short flags may be bundled ("-pO") and a short option's value
    attached ("-L60"). Options come out as "--name=value" or a flag, then "--" and the
    input files (getopt takes files anywhere on the line)."""
    longs: dict[str, argparse.Action] = {}
    shorts: dict[str, argparse.Action] = {}
    for action in parser._actions:
        for name in action.option_strings:
            (longs if name.startswith("--") else shorts)[name] = action
    out: list[str] = []
    files: list[str] = []
    items = list(argv)
    i = 0

    def value_after(j: int, name: str) -> str:
        if j >= len(items):
            parser.error(f"option {name!r} requires an argument")
        return items[j]

    while i < len(items):
        word = items[i]
        i += 1
        if word == "--":
            files += items[i:]
            break
        if word.startswith("--"):
            name, eq, value = word.partition("=")
            full = _long_name(parser, longs, name)
            takes = longs[full].nargs != 0
            if takes and not eq:
                value = value_after(i, full)
                i += 1
            if eq and not takes:
                parser.error(f"option {full!r} doesn't allow an argument")
            out.append(f"{full}={value}" if takes else full)
        elif word.startswith("-") and len(word) > 1:
            for k, letter in enumerate(word[1:], start=1):
                action = shorts.get(f"-{letter}")
                if action is None:
                    parser.error(f"invalid option -- {letter!r}")
                full = next((o for o in action.option_strings if o.startswith("--")), f"-{letter}")
                if action.nargs == 0:
                    out.append(full)
                    continue
                value = word[k + 1 :]
                if not value:
                    value = value_after(i, f"-{letter}")
                    i += 1
                out.append(f"{full}={value}")
                break
        else:
            files.append(word)
    return [*out, "--", *files]


def _long_name(parser, longs: dict, name: str) -> str:
    """getopt_long's reading of a long option ``name``: the option itself, else the one
    option it is a prefix of (exit 2 when none or several)."""
    if name in longs:
        return name
    matches = sorted({longs[o].option_strings[-1] for o in longs if o.startswith(name)})
    if len(matches) == 1:
        return matches[0]
    if not matches:
        parser.error(f"unrecognized option {name!r}")
    parser.error(f"option {name!r} is ambiguous; possibilities: {' '.join(matches)}")
    raise AssertionError  # parser.error exits


def _report_ignored(ignored: list[tuple[str, object]]) -> None:
    """Name each option given that starnav does not apply, once, on stderr; solve-field's
    "none" (a side file not written) is what starnav does anyway."""
    seen: set[str] = set()
    for option, value in ignored:
        if option in seen or (isinstance(value, str) and value.lower() == "none"):
            continue
        seen.add(option)
        shown = option if not isinstance(value, str) else f"{option} {value}"
        why = IGNORED_WHY.get(option, SIDE)
        print(f"{PROG}: ignored: {shown} ({why})", file=sys.stderr)


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
    if args.odds_to_solve is not None:
        out["max_false_match_probability"] = false_match_of_odds(args.odds_to_solve)
    for name in ("crpix_x", "crpix_y"):
        value = getattr(args, name)
        if value is not None and not math.isfinite(value):
            raise StarnavError(f"--{name.replace('_', '-')} must be a number, got {value}")
    if args.objs is not None and args.objs < 1:
        raise StarnavError(f"--objs must be at least 1, got {args.objs}")
    return out


def false_match_of_odds(odds: float) -> float:
    """starnav's acceptance of astrometry.net's ``--odds-to-solve``: a false-match probability
    of at most 1 / (1 + odds) (the odds ratio of a true match against a false one), never
    looser than starnav's default (``DEFAULT_MAX_FALSE_MATCH_PROBABILITY``): odds of 1e9,
    solve-field's default, accept at 1e-9; odds under 1e4 keep the default 1e-4."""
    from starnav.pipeline.options import DEFAULT_MAX_FALSE_MATCH_PROBABILITY

    if not (math.isfinite(odds) and odds > 0):
        raise StarnavError(f"--odds-to-solve must be a positive number, got {odds}")
    return min(1.0 / (1.0 + odds), DEFAULT_MAX_FALSE_MATCH_PROBABILITY)


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
    """The source list of an xylist file (``starnav.pipeline.plate.read_xylist`` with the
    columns, sort order, size and ``--objs`` of the command line), None for an image."""
    from starnav.pipeline.plate import read_xylist as read

    return read(path, x_column=args.x_column, y_column=args.y_column,
                sort_column=args.sort_column, sort_ascending=args.sort_ascending,
                width=args.width, height=args.height, max_sources=args.objs)  # fmt: skip


def _solve_one(infile: Path, number: int, count: int, args, common: dict) -> None:
    from starnav.pipeline.plate import PlateHints, solve_plate

    if not infile.is_file():
        raise StarnavError(f"input file {str(infile)!r} does not exist")
    paths = output_paths(infile, args)
    paths.base.parent.mkdir(parents=True, exist_ok=True)  # solve-field makes --dir
    if args.skip_solved and paths.solved is not None and paths.solved.exists():
        print(f'Solved file exists: "{paths.solved}"; skipping input file "{infile}".')
        return
    existing = paths.existing()
    if existing and not (args.overwrite or args.continue_):
        print(f'Output file already exists: "{existing[0]}".\n'
              "Use the --overwrite flag to overwrite existing files,\n"
              " or the --continue  flag to not overwrite existing files but still try solving.\n"
              "Continuing to next input file.")  # fmt: skip
        return
    print(f'Reading input file {number} of {count}: "{infile}"...', flush=True)

    def hints(width: int, height: int) -> PlateHints:  # the scale needs the width
        return PlateHints(fov_range_deg=_fov_range(args, width, height),
                          crpix_fits=_crpix(args, width, height), **common)  # fmt: skip

    xylist, result = None, None
    with CancelWatch(args.cancel, on_cancel=lambda: _cancelled(infile, args, paths)) as cancel:
        if not cancel.requested():
            xylist = _source_list(infile, args)
            source: Path | XYList = xylist if xylist is not None else infile
            print("Solving...", flush=True)
            result = solve_plate(source, hints, time_budget_s=args.cpulimit)
    if result is None:
        _cancelled(infile, args, paths)
        return
    _remove_stale(paths)
    if args.no_tweak and result.plate is not None:
        result = _without_sip(result)
    image = xylist is None and not _extracts(args)
    print_result(result, str(infile), paths, image=image)
    sys.stdout.flush()


def _remove_stale(paths: OutputPaths) -> None:
    for p in paths.outputs():
        if p is not None and p.exists():
            p.unlink()  # a stale file must not read as this run's answer


def _cancelled(infile: Path, args, paths: OutputPaths) -> None:
    """solve-field's lines for a field whose cancel file appeared; no output files."""
    _remove_stale(paths)
    print(f'Field 1 did not solve (cancel file "{args.cancel}" exists).')
    print(f"Field: {infile}")
    print("Did not solve (or no WCS file was written).", flush=True)


def _crpix(args, width: int, height: int) -> tuple[float, float] | None:
    """The WCS reference pixel of --crpix-x / --crpix-y (FITS px; the one not given: the
    centre's), None for the centre (as --crpix-center, which wins, as in solve-field)."""
    if args.crpix_center or (args.crpix_x is None and args.crpix_y is None):
        return None
    x = (width + 1) / 2.0 if args.crpix_x is None else args.crpix_x
    y = (height + 1) / 2.0 if args.crpix_y is None else args.crpix_y
    return (x, y)


def _fov_range(args, width: int, height: int) -> tuple[float, float] | None:
    if args.scale_low is None and args.scale_high is None:
        return None
    low = args.scale_low if args.scale_low is not None else args.scale_high
    high = args.scale_high if args.scale_high is not None else args.scale_low
    units = SCALE_UNIT_NAMES[args.scale_units.lower()]
    from starnav.pipeline.plate import fov_range_from_scale

    return fov_range_from_scale(units, low, high, width, height)


def _extracts(args) -> bool:
    """Whether SExtractor finds the sources (--use-source-extractor or its path or config)."""
    return bool(
        args.use_source_extractor or args.source_extractor_path or args.source_extractor_config
    )


def _source_list(infile: Path, args) -> XYList | None:
    """The source list solved: the xylist an input is, else SExtractor's of the image when
    asked (``source_extractor_list``), else None (starnav detects the image's stars)."""
    xylist = read_xylist(infile, args)
    if xylist is not None or not _extracts(args):
        return xylist
    return source_extractor_list(infile, args)


# solve-field's SExtractor parameters and filter when no config is given (augment-xylist.c):
# the columns it reads, and a 5 x 5 Gaussian of 2 px FWHM, written out by its numbers
SEXTRACTOR_PARAMS = "X_IMAGE\nY_IMAGE\nMAG_AUTO\nFLUX_AUTO\n"
SEXTRACTOR_FILTER_FWHM_PX = 2.0


def _gaussian_filter_text(fwhm_px: float, size: int = 5) -> str:
    """SExtractor's convolution filter file: a normalised-by-SExtractor Gaussian PSF."""
    import numpy as np

    sigma = fwhm_px / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    r = np.arange(size) - size // 2
    g = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2.0 * sigma**2))
    rows = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in g)
    return f"CONV NORM\n# {size}x{size} Gaussian PSF, FWHM {fwhm_px:g} px\n{rows}\n"


def source_extractor_list(image: Path, args) -> XYList:
    """The sources SExtractor finds in ``image``, as solve-field asks for them: without
    --source-extractor-config, the parameters X_IMAGE, Y_IMAGE, MAG_AUTO, FLUX_AUTO and a
    2 px Gaussian filter, sorted by MAG_AUTO, brightest first; with one, its catalog's
    --x-column, --y-column and --sort-column. A non-FITS image is handed over as FITS
    (the rows as starnav reads them, row 0 = FITS y = 1). ``StarnavError`` when SExtractor
    cannot run or fails."""
    import shlex
    import subprocess
    import tempfile

    from starnav.detect.header import is_fits
    from starnav.pipeline.plate import read_xylist as read

    command = shlex.split(args.source_extractor_path or "source-extractor")
    with tempfile.TemporaryDirectory(prefix="starnav-sextractor-") as tmp:
        work = Path(tmp)
        fits_image = image
        from starnav.detect.read import read_image

        pixels = read_image(image)
        if not is_fits(image):
            from astropy.io import fits

            fits_image = work / "image.fits"
            fits.PrimaryHDU(pixels.astype("float32")).writeto(fits_image)
        catalog = work / "sources.fits"
        x_column, y_column = args.x_column, args.y_column
        sort_column, ascending = args.sort_column, args.sort_ascending
        if args.source_extractor_config:
            command += ["-c", str(Path(args.source_extractor_config).resolve())]
        else:
            (work / "sources.param").write_text(SEXTRACTOR_PARAMS)
            (work / "gauss.conv").write_text(_gaussian_filter_text(SEXTRACTOR_FILTER_FWHM_PX))
            command += ["-PARAMETERS_NAME", "sources.param", "-FILTER_NAME", "gauss.conv"]
            x_column, y_column, sort_column, ascending = "X_IMAGE", "Y_IMAGE", "MAG_AUTO", True
        command += ["-CATALOG_TYPE", "FITS_1.0", "-CATALOG_NAME", str(catalog),
                    str(Path(fits_image).resolve())]  # fmt: skip
        try:
            done = subprocess.run(command, cwd=work, capture_output=True, text=True)
        except OSError as exc:
            raise StarnavError(f"cannot run SExtractor {command[0]!r}: {exc}") from None
        if done.returncode != 0 or not catalog.exists():
            last = (done.stderr.strip().splitlines() or ["no catalog written"])[-1]
            raise StarnavError(f"SExtractor failed (exit {done.returncode}): {last}")
        height, width = pixels.shape
        found = read(catalog, x_column=x_column, y_column=y_column, sort_column=sort_column,
                     sort_ascending=ascending, width=width, height=height,
                     max_sources=args.objs)  # fmt: skip
    if found is None:
        raise StarnavError("SExtractor's catalog holds no table of sources")
    return found


def _without_sip(result: PlateResult) -> PlateResult:
    """-T/--no-tweak: the plate's WCS as a plain TAN (its linear part, SIP terms dropped)."""
    from dataclasses import replace

    from starnav.pipeline.plate import Plate

    plate = result.plate
    if plate.wcs.sip is None:
        return result
    tan = plate.wcs.deepcopy()
    tan.sip = None
    tan.wcs.ctype = [c.replace("-SIP", "") for c in tan.wcs.ctype]
    return replace(result, plate=Plate.from_wcs(tan, plate.width, plate.height))


class CancelWatch:
    """solve-field's --cancel FILE around one solve: a file there before the solve starts
    stops it at once (``requested``), as in solve-field's engine; one that appears while it
    runs (looked for every ``POLL_S`` seconds by a thread) ends it: the thread calls
    ``on_cancel`` (the field's "did not solve" lines) and ends the process, exit 0, as
    solve-field ends a cancelled run. Nothing is written before a solve ends, and the lock
    keeps the thread from acting once it has: no file is left half written."""

    POLL_S = 0.1

    def __init__(self, path: str | None, on_cancel=None) -> None:
        self.path = None if path is None else Path(path)
        self.on_cancel = on_cancel
        self._seen = False
        self._done = None
        self._lock = None
        self._thread = None

    def requested(self) -> bool:
        """Whether the cancel file has appeared."""
        if self.path is not None and not self._seen and self.path.exists():
            self._seen = True
        return self._seen

    def __enter__(self) -> CancelWatch:
        if self.path is None or self.requested():
            return self
        import threading

        self._done, self._lock = threading.Event(), threading.Lock()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _watch(self) -> None:
        while not self._done.wait(self.POLL_S):
            if self.requested():
                with self._lock:
                    if self._done.is_set():
                        return  # the solve ended first: its answer stands
                    if self.on_cancel is not None:
                        self.on_cancel()
                    import os

                    os._exit(EXIT_OK)

    def __exit__(self, *exc) -> None:
        if self._done is not None:
            with self._lock:
                self._done.set()
            self._thread.join()


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
