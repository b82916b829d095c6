"""The command line's newcomer defects of issue 33, each fixed and held here: evaluate's
--frames without --sampling, the formats a directory is listed by, numpy scalars in error
messages, one FOV range for solve and identify, --version, and a help text on every option.
Every user error is exit 2 and one line on stderr, without a traceback."""

from __future__ import annotations

import argparse
import importlib.metadata
import re

import numpy as np
import pytest
from PIL import Image

import starnav
from cli_helpers import run_cli
from starnav.cli import build_parser, main, version
from starnav.cli.evaluate import DEFAULT_FRAMES, DEFAULT_GRID_STEP_DEG, choose_sampling
from starnav.cli.field import check_fov
from starnav.detect.read import read_image, readable_suffixes
from starnav.errors import StarnavError, shown
from starnav.pipeline.fov import FOV_LIMITS_DEG, LENS_FOV_LIMITS_DEG, fov_limits_deg
from starnav.pipeline.image import solve_image
from starnav.pipeline.image_batch import image_paths


def _one_line_error(code: int, out: str, err: str) -> str:
    """The message of a user error (exit 2, nothing on stdout, one line on stderr)."""
    assert code == 2 and out == "", (code, out, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err.split("error: ", 1)[1].strip()


@pytest.fixture
def blank_png(tmp_path):
    """A 64 x 64 px grey PNG: no stars, but an image the commands open."""
    path = tmp_path / "blank.png"
    Image.fromarray(np.full((64, 64), 10, np.uint8)).save(path)
    return path


@pytest.fixture
def star_list(tmp_path):
    path = tmp_path / "stars.csv"
    path.write_text("x,y\n10,10\n100,40\n200,300\n400,100\n")
    return path


# 1. evaluate --frames N without --sampling ran the 7200-frame grid


@pytest.mark.parametrize(
    ("sampling", "frames", "step", "chosen"),
    [
        (None, 200, None, ("uniform", 200)),
        (None, None, None, ("grid", DEFAULT_GRID_STEP_DEG)),
        (None, None, 10.0, ("grid", 10.0)),
        ("uniform", None, None, ("uniform", DEFAULT_FRAMES)),
        ("uniform", 5, None, ("uniform", 5)),
        ("grid", None, 30.0, ("grid", 30.0)),
    ],
)
def test_frames_alone_means_uniform_sampling(sampling, frames, step, chosen):
    assert choose_sampling(sampling, frames, step) == chosen


def test_evaluate_frames_runs_that_many_frames(monkeypatch):
    """``starnav evaluate --frames 200`` hands 200 uniform boresights to the evaluation
    (which is stopped there: the frames are not solved)."""

    class Stop(Exception):
        pass

    got = {}

    def record(config, boresights, **kwargs):
        got["boresights"] = boresights
        raise Stop

    monkeypatch.setattr("starnav.evaluate.evaluate", record)
    with pytest.raises(Stop):
        main(["evaluate", "--frames", "200", "--workers", "1"])
    assert len(got["boresights"].ra_deg) == 200


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--sampling", "grid", "--frames", "200"], "--frames is for --sampling uniform"),
        (["--sampling", "uniform", "--grid-step-deg", "10"], "--grid-step-deg is for"),
        (["--frames", "200", "--grid-step-deg", "10"], "give one"),
    ],
)
def test_an_option_of_the_other_sampling_is_a_usage_error(capsys, argv, needle):
    message = _one_line_error(*run_cli(capsys, "evaluate", "--workers", "1", *argv))
    assert needle in message


# 2. solve DIR/ skipped .bmp files without a word


def test_the_directory_listing_takes_every_format_the_reader_reads(tmp_path):
    suffixes = readable_suffixes()
    for suffix in (".fits", ".fits.gz", ".fz", ".png", ".jpg", ".jpeg", ".tif", ".tiff"):
        assert suffix in suffixes  # what the listing took before
    pixels = np.zeros((16, 16), np.uint8)
    pixels[5, 7] = 200
    for suffix in (".bmp", ".gif", ".webp", ".pgm", ".tga", ".png", ".jpg", ".tif"):
        assert suffix in suffixes
        path = tmp_path / f"frame{suffix}"
        Image.fromarray(pixels).save(path)
        assert read_image(path).shape == (16, 16)  # the reader opens what the listing takes
    for not_a_picture in (".txt", ".csv", ".json", ".mpg", ".h5", ".cr2"):
        assert not_a_picture not in suffixes


def test_solve_directory_solves_a_bmp_and_names_what_it_skips(capsys, tmp_path, blank_png):
    folder = tmp_path / "night"
    folder.mkdir()
    Image.open(blank_png).save(folder / "a.bmp")
    Image.open(blank_png).save(folder / "b.png")
    (folder / "notes.txt").write_text("not an image")
    (folder / "IMG_0001.CR2").write_bytes(b"raw")
    (folder / "older").mkdir()
    code, out, err = run_cli(capsys, "solve", str(folder), "--workers", "1")
    assert code == 1  # opened, not solved: no stars
    assert [line.split(":")[0] for line in out.splitlines()] == [
        str(folder / "a.bmp"),
        str(folder / "b.png"),
    ]
    skipped = [line for line in err.splitlines() if "skipped" in line]
    assert len(skipped) == 1
    for name in ("IMG_0001.CR2", "notes.txt", "older/"):
        assert str(folder / name) in skipped[0]
    assert "skipped 3 entries" in skipped[0]


def test_a_directory_without_images_says_what_it_holds(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    message = _one_line_error(*run_cli(capsys, "solve", str(tmp_path)))
    assert "no image files in" in message and "notes.txt" in message
    skipped = []
    with pytest.raises(StarnavError, match="no image files"):
        image_paths([tmp_path], skipped)
    assert skipped == [tmp_path / "notes.txt"]


# 3. error messages printed np.float64(nan)


def test_shown_prints_numpy_scalars_as_plain_numbers():
    assert shown(np.float64("nan")) == "nan"
    assert shown(np.float32(12.5)) == "12.5"
    assert shown(np.int64(3)) == "3"
    assert shown((np.float64(2.0), 30.0)) == "(2.0, 30.0)"
    assert shown("abc") == "'abc'" and shown(None) == "None"


@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ({"fov_deg": np.float64("nan")}, "fov_deg must be above 0 and below 179 degrees, got nan"),
        ({"fov_deg": 12.0, "sigma_px": np.float64("nan")}, "got nan"),
        ({"fov_deg": 12.0, "time_budget_s": np.float64(-1.0)}, "got -1.0"),
        ({"fov_deg": 12.0, "max_false_match_probability": np.float64(2)}, "got 2.0"),
        ({"fov_deg": 12.0, "parity": np.int64(3)}, "got 3"),
    ],
)
def test_api_errors_print_plain_numbers(star_list, options, needle):
    xy = np.loadtxt(star_list, delimiter=",", skiprows=1)
    with pytest.raises(StarnavError) as info:
        starnav.solve_stars(xy, width=512, **options)
    assert needle in str(info.value) and "np." not in str(info.value)


def test_image_errors_print_plain_numbers():
    pixels = np.zeros((64, 64), np.float32)
    for options in (
        {"fov_deg": np.float64("nan")},
        {"fov_deg": np.float64(0.3)},
        {"threshold_sigma": np.float64("nan")},
        {"max_stars": np.float64(2.5)},
    ):
        with pytest.raises(StarnavError) as info:
            solve_image(pixels, **options)
        assert "np." not in str(info.value)
        assert re.search(r"got (nan|2\.5|0\.3)\b", str(info.value)), str(info.value)


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "{png}", "--fov-deg", "nan"],
        ["solve", "{png}", "--threshold-sigma", "-1"],
        ["identify", "{csv}", "--width", "512", "--fov-deg", "12", "--sigma-px", "nan"],
        ["identify", "{csv}", "--width", "512", "--fov-deg", "12", "--prior-sigma-deg", "99",
         "--prior-ra-deg", "1", "--prior-dec-deg", "2", "--prior-roll-deg", "3"],
    ],
)  # fmt: skip
def test_cli_errors_print_plain_numbers(capsys, blank_png, star_list, argv):
    argv = [a.format(png=blank_png, csv=star_list) for a in argv]
    message = _one_line_error(*run_cli(capsys, *argv))
    assert "np." not in message


# 4. --fov-deg limits differed between solve (3..100) and identify (0..179): a searched field
# (solve's and calibrate's --fov-deg, every --fov-range) has one definition, the lens model's
# search limits; identify's --fov-deg is exact (no search: the camera model's own limits)


@pytest.mark.parametrize(
    ("lens", "fov"),
    [("pinhole", "0.3"), ("pinhole", "150"), ("pinhole", "nan"), ("equidistant", "5")],
)
def test_solve_identify_and_calibrate_refuse_the_same_fields_alike(
    capsys, tmp_path, blank_png, star_list, lens, fov
):
    lens_options = ["--lens", lens]
    messages = {
        "solve": run_cli(capsys, "solve", str(blank_png), "--fov-deg", fov, *lens_options),
        "calibrate": run_cli(
            capsys, "calibrate", str(blank_png), "-o", str(tmp_path / "cam.json"), "--fov-deg",
            fov, "--model", lens,
        ),
    }  # fmt: skip
    messages = {command: _one_line_error(*result) for command, result in messages.items()}
    assert len(set(messages.values())) == 1, messages  # one definition, one message
    lo, hi = fov_limits_deg(lens)
    if fov != "nan":  # argparse refuses nan first, alike
        needle = f"fov_deg must be within {lo:g}..{hi:g} degrees for the {lens} lens"
        assert needle in messages["solve"]
        with pytest.raises(StarnavError) as info:  # the API says the same
            solve_image(np.zeros((64, 64), np.float32), fov_deg=float(fov), lens=lens)
        assert str(info.value) == messages["solve"]
        # a searched range: the same limits in solve and identify
        wide = [str(lo / 2), str(hi)] if lo / 2 > 0 else ["0.5", str(hi)]
        ranges = {
            "solve": run_cli(capsys, "solve", str(blank_png), "--fov-range", *wide, *lens_options),
            "identify": run_cli(
                capsys, "identify", str(star_list), "--width", "512", "--fov-range", *wide,
                *lens_options,
            ),
        }  # fmt: skip
        ranges = {command: _one_line_error(*result) for command, result in ranges.items()}
        assert len(set(ranges.values())) == 1, ranges
        assert f"fov range must satisfy {lo:g} <= low < high <= {hi:g}" in ranges["solve"]


def test_identify_takes_its_field_as_exact_within_the_camera_model(capsys, star_list):
    """identify's --fov-deg is not searched: a 120° pinhole field (docs/wide_field.md) is
    identified as given, and beyond the pinhole model's 179° the camera model says why."""
    code, _, err = run_cli(
        capsys, "identify", str(star_list), "--width", "512", "--fov-deg", "120", "--json"
    )
    assert code in (0, 1) and "error" not in err, err  # solved or not, not bad input
    message = _one_line_error(
        *run_cli(capsys, "identify", str(star_list), "--width", "512", "--fov-deg", "179.5")
    )
    assert "fov_deg must be above 0 and below 179 degrees, got 179.5" in message


def test_the_fov_limits_depend_on_the_lens_model_alone():
    assert fov_limits_deg("pinhole") == FOV_LIMITS_DEG
    for lens in ("equidistant", "equisolid", "stereographic", "orthographic", "kannala-brandt"):
        assert fov_limits_deg(lens) == LENS_FOV_LIMITS_DEG
    parser = build_parser()
    for command in (
        ["solve", "x.png", "--lens", "equisolid", "--fov-deg", "180"],
        ["identify", "x.csv", "--lens", "equidistant", "--fov-deg", "150", "--width", "800"],
        ["identify", "x.csv", "--fov-deg", "100", "--width", "800"],
        ["solve", "x.png", "--fov-deg", "3"],
        ["solve", "x.png", "--camera", "cam.json"],  # a camera file brings its own field
    ):
        args = parser.parse_args(command)
        check_fov(args, args.lens)  # taken: no error


# 5. no starnav --version


def test_version(capsys):
    code, out, err = run_cli(capsys, "--version")
    assert code == 0 and err == ""
    assert out.strip() == f"starnav {importlib.metadata.version('starnav')}"


def test_version_of_a_source_tree_not_installed(monkeypatch):
    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert version() == starnav.__version__


# 6. options without help text, units or defaults

UNIT_SUFFIXES = ("-deg", "-px", "-s", "-e", "-mb", "-e-per-s", "-e-per-adu", "-arcsec")


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (subparsers,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {"starnav": parser, **subparsers.choices}


def test_every_option_of_every_command_has_help():
    bare = []
    for name, parser in _commands().items():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            if not (action.help or "").strip():
                bare.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert not bare, f"options without help: {', '.join(bare)}"


def test_numeric_options_with_a_unit_say_their_default():
    """An option named with a unit (--fov-deg, --noise-px, --exposure-s, ...) that is not
    required says its default, and a numeric default is the one it says."""
    silent = []
    for name, parser in _commands().items():
        formatter = parser._get_formatter()
        for action in parser._actions:
            flags = [f for f in action.option_strings if f.startswith("--")]
            if action.required or not flags or not flags[0].endswith(UNIT_SUFFIXES):
                continue
            text = formatter._expand_help(action)
            number = action.default
            says = "default" in text.lower()
            if isinstance(number, int | float) and not isinstance(number, bool):
                says = says and f"{number:g}" in text
            if not says:
                silent.append(f"{name} {flags[0]}: {text!r}")
    assert not silent, "\n".join(silent)


def test_every_help_page_renders(capsys):
    for name in _commands():
        argv = ["--help"] if name == "starnav" else [name, "--help"]
        code, out, _ = run_cli(capsys, *argv)
        assert code == 0 and "usage:" in out


def test_a_negative_seed_is_a_usage_error_in_every_command(capsys):
    """``evaluate --seed -1`` and ``locate-study --seed -1`` ended in numpy's traceback."""
    seeded = [
        name
        for name, parser in _commands().items()
        if any("--seed" in a.option_strings for a in parser._actions)
    ]
    assert {"evaluate", "locate-study", "simulate", "render"} <= set(seeded)
    for name in seeded:
        message = _one_line_error(*run_cli(capsys, name, "--seed", "-1"))
        assert "--seed" in message, name
