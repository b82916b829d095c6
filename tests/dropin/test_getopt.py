"""starnav-solve-field reads its command line as solve-field's getopt_long does
(util/an-opts.c over the options of solver/solve-field.c and solver/augment-xylist.c): unique
prefixes of long options, values that begin with "-", bundled short flags, attached values;
ambiguous or unknown options are one line and exit 2. And the options it does not apply are
named once on stderr; --odds-to-solve becomes a false-match probability."""

from __future__ import annotations

import pytest

from starnav.dropin import solve_field as sf


def parse(*argv: str):
    parser = sf.build_parser()
    return parser.parse_args(sf.getopt_argv(parser, list(argv)))


def test_unique_prefixes_as_getopt_long():
    args = parse("--scale-unit", "app", "--scale-l", "10", "--scale-h", "20", "--overwr", "x.fits")
    assert (args.scale_units, args.scale_low, args.scale_high) == ("app", 10.0, 20.0)
    assert args.overwrite and args.inputs == ["x.fits"]
    assert parse("--no-verify", "f").ignored == [("--no-verify", [])]  # exact beats longer ones
    assert parse("--crpix-c", "f").crpix_center
    assert parse("--sort-c", "MAG_AUTO", "--sort-a", "f").sort_column == "MAG_AUTO"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scale", "10", "f"], "'--scale' is ambiguous; possibilities: --scale-high"),
        (["--no-v", "f"], "'--no-v' is ambiguous"),
        (["--sort", "FLUX", "f"], "'--sort' is ambiguous"),
        (["--odds-to-tune-down", "1e3", "f"], "unrecognized option '--odds-to-tune-down'"),
        (["--frobnicate", "f"], "unrecognized option '--frobnicate'"),
        (["-x", "f"], "invalid option -- 'x'"),
        (["--no-plots=yes", "f"], "doesn't allow an argument"),
        (["f", "--ra"], "'--ra' requires an argument"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(capsys, argv, message):
    with pytest.raises(SystemExit) as stop:
        parse(*argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err


def test_values_bundles_and_files_anywhere():
    args = parse("in.fits", "--dec", "-30:00:00", "-3", "-1.5", "-pO", "-L60", "-H", "90",
                 "-u", "aw", "--ra=10", "-vv", "--", "-odd-name.fits")  # fmt: skip
    assert args.dec == "-30:00:00" and args.ra == "10"  # the last --ra, as getopt
    assert args.no_plots and args.overwrite
    assert (args.scale_low, args.scale_high, args.scale_units) == (60.0, 90.0, "aw")
    assert args.inputs == ["in.fits", "-odd-name.fits"]
    assert [name for name, _ in args.ignored] == ["--verbose", "--verbose"]


def test_nina_minus_center_is_a_code_tolerance():
    """N.I.N.A. writes "-center"; getopt reads -c with the value "enter"."""
    assert parse("-center", "f").ignored == [("--code-tolerance", "enter")]


def test_every_client_option_is_known():
    """The options of the lines in docs/dropin.md, each accepted (honoured or ignored)."""
    args = parse(
        "-C", "stop", "--temp-axy", "-p", "-O", "-N", "none", "-R", "none", "-M", "none",
        "-B", "none", "-U", "none", "-S", "none", "--crpix-center", "-s", "FLUX", "-T",
        "--odds-to-solve", "1e+09", "--odds-to-tune-up", "1e+06", "--no-remove-lines",
        "--uniformize", "0", "--backend-config", "x.cfg", "--cancel", "c", "--solved", "s",
        "--axy", "a.axy", "--keep-xylist", "k.xyls", "--fits-image", "--resort", "--objs",
        "50", "--depth", "20-40", "--no-verify", "--guess-scale", "--use-source-extractor",
        "--source-extractor-path", "source-extractor", "--crpix-x", "10", "--crpix-y", "20",
        "-E", "1.5", "--index-xyls", "none", "--corr", "none", "--rdls", "none", "f",
    )  # fmt: skip
    assert args.cancel == "c" and args.no_tweak and args.sort_column == "FLUX"
    assert (args.crpix_x, args.crpix_y, args.pixel_error, args.objs) == (10.0, 20.0, 1.5, 50)


def test_ignored_options_named_once(capsys):
    sf._report_ignored([("--uniformize", "0"), ("--uniformize", "0"), ("--rdls", "none"),
                        ("--no-remove-lines", [])])  # fmt: skip
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "starnav-solve-field: ignored: --uniformize 0 (tunes astrometry.net's source "
        "extraction; starnav finds and orders stars its own way)",
        "starnav-solve-field: ignored: --no-remove-lines (tunes astrometry.net's source "
        "extraction; starnav finds and orders stars its own way)",
    ]


def test_odds_to_solve_as_false_match_probability():
    assert sf.false_match_of_odds(1e9) == pytest.approx(1.0 / (1.0 + 1e9))
    assert sf.false_match_of_odds(1e12) == pytest.approx(1e-12, rel=1e-6)
    assert sf.false_match_of_odds(10.0) == 1e-4  # never looser than starnav's default
    with pytest.raises(sf.StarnavError, match="positive"):
        sf.false_match_of_odds(0.0)


def test_crpix_options():
    args = parse("--crpix-x", "100.5", "f")
    assert sf._crpix(args, 1280, 960) == (100.5, 480.5)  # the other at the centre
    assert sf._crpix(parse("--crpix-x", "1", "--crpix-center", "f"), 1280, 960) is None
    assert sf._crpix(parse("f"), 1280, 960) is None
