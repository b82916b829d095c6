import json
import subprocess
import sys

import numpy as np
import pytest

from cli_helpers import run_cli
from shared_data import CONTEST
from starnav.cli import main
from starnav.identify import ALGORITHMS

CATALOG = str(CONTEST / "catalog.csv")
MAP1 = str(CONTEST / "images" / "xingtu01.csv")
EXPECTED_KEYS = {
    "solved",
    "reason",
    "ra_deg",
    "dec_deg",
    "roll_deg",
    "parity",
    "focal_px",
    "rms_px",
    "sigma_boresight_arcsec",
    "sigma_roll_arcsec",
    "false_match_probability",
    "time_ms",
    "stars",
}


def _identify(capsys, path, *extra):
    """``starnav identify PATH`` with the 12° / 512 px camera and the contest catalog."""
    argv = ["identify", str(path), "--fov-deg", "12", "--width", "512", "--catalog", CATALOG]
    return run_cli(capsys, *argv, *extra)


def test_identify_json_contest_map(capsys):
    code, out, err = _identify(
        capsys,
        MAP1,
        "--json",
    )
    assert code == 0 and err == ""
    result = json.loads(out)  # exactly one JSON object
    assert EXPECTED_KEYS <= set(result)
    assert result["solved"] is True and result["parity"] == -1
    assert abs(result["ra_deg"] - 109.6) < 0.05 and abs(result["dec_deg"] - 34.5) < 0.05
    assert [s["label"] for s in result["stars"]][:2] == ["A01", "A02"]
    assert set(result["stars"][0]) == {"label", "x", "y", "catalog_id", "residual_px"}


def test_identify_table_output(capsys):
    code, out, _ = _identify(capsys, MAP1)
    assert code == 0
    assert out.startswith("solved: RA 109.6") and "A15" in out


def test_not_solved_exits_1_with_json(capsys, tmp_path):
    path = tmp_path / "random.csv"
    xy = np.random.default_rng(2).uniform(0, 512, (10, 2))
    path.write_text("x,y\n" + "".join(f"{x:.2f},{y:.2f}\n" for x, y in xy))
    code, out, err = _identify(capsys, path, "--json")
    assert code == 1 and err == ""
    result = json.loads(out)
    assert result["solved"] is False and result["reason"]
    assert EXPECTED_KEYS <= set(result)
    assert result["ra_deg"] is None and len(result["stars"]) == 10
    assert all(s["catalog_id"] is None for s in result["stars"])
    assert [s["label"] for s in result["stars"]][:3] == ["1", "2", "3"]


BAD_FILES = {
    "empty": ("", "empty"),
    "header only": ("x,y\n", "no stars"),
    "two points": ("x,y\n1,2\n30,40\n", "at least 3"),
    "nan": ("x,y\n1,2\nnan,4\n30,40\n", "NaN"),
    "wrong columns": ("u,v\n1,2\n3,4\n5,6\n", "expected x,y"),
    "unknown column": ("x,y,color\n1,2,3\n30,40,5\n50,60,7\n", "unknown: color"),
    "far outside": ("x,y\n1,2\n30,40\n5000,60\n", "far outside"),
    "duplicates": ("x,y\n1,2\n30,40\n1,2\n", "duplicate"),
    "text": ("x,y\n1,2\nabc,40\n5,6\n", "not a number"),
    "short row": ("x,y,label\n1,2,a\n30,40\n5,6,c\n", "fields"),
    "empty column name": ("x,y,\n1,2,\n30,40,\n5,6,\n", "empty column name"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_star_list_exits_2_with_one_line(capsys, tmp_path, case):
    text, needle = BAD_FILES[case]
    path = tmp_path / "stars.csv"
    path.write_text(text)
    code, out, err = _identify(capsys, path, "--json")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--catalog", "/nonexistent/cat.csv"], "cannot read catalog"),
        (["--fov-deg", "-3"], "fov_deg"),
        (["--width", "abc"], "--width"),
        (["--sigma-px", "0"], "sigma_px"),
        (["--fov-deg", "nan"], "--fov-deg"),
        (["--width", "512.0"], "not a whole number"),
        (["--plot", "map.jpg"], "ending in .png"),
        (["--epoch", "2000"], "epoch applies"),
        (["--mag-limit", "-9"], "holds 0 stars"),
        (["--algorithm", "nope"], "invalid choice"),
        (["--triangle-selection", "dimmest"], "invalid choice"),
    ],
)
def test_bad_options_exit_2(capsys, argv, needle):
    base = {"--fov-deg": "12", "--width": "512", "--catalog": CATALOG}
    for k, v in zip(argv[::2], argv[1::2], strict=True):
        base[k] = v
    args = ["identify", MAP1] + [x for kv in base.items() for x in kv]
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and out == ""
    assert needle in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["demo", "--seed", "-1"], "at least 0"),
        (["demo", "--fov-deg", "0.01"], "choose a wider field"),
        (["database", "--fov-deg", "12", "--width", "512", "--mag-limit", "1e300"], "star pairs"),
        (
            ["simulate", "--ra-deg", "1e300", "--fov-deg", "12", "--width", "512", "-o", "x.csv"],
            "ra_deg must be",
        ),
        (
            [
                "simulate",
                "--fov-deg",
                "12",
                "--width",
                "512",
                "--false-stars",
                "99999999",
                "-o",
                "x.csv",
            ],
            "false_stars must be",
        ),
        (
            ["simulate", "--fov-deg", "12", "--width", "512", "-o", "/nonexistent/dir/x.csv"],
            "cannot write",
        ),
        (
            ["simulate", "--fov-deg", "12", "--width", "512", "--missing-frac", "1", "-o", "x.csv"],
            "missing_frac",
        ),
    ],
)
def test_bad_simulate_and_demo_options(capsys, tmp_path, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, *argv)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1


def test_simulate_then_identify(capsys, tmp_path):
    out_csv = tmp_path / "frame.csv"
    code, out, _ = run_cli(
        capsys,
        "simulate",
        "--ra-deg",
        "83.8",
        "--dec-deg",
        "-5.4",
        "--roll-deg",
        "30",
        "--fov-deg",
        "12",
        "--width",
        "512",
        "--noise-px",
        "0.5",
        "--false-stars",
        "2",
        "--missing-frac",
        "0.1",
        "--seed",
        "4",
        "--epoch",
        "2000",
        "-o",
        str(out_csv),
        "--json",
    )
    assert code == 0
    truth = json.loads(out)
    assert truth["n_false"] == 2 and out_csv.exists()
    code, out, _ = run_cli(
        capsys,
        "identify",
        str(out_csv),
        "--fov-deg",
        "12",
        "--width",
        "512",
        "--epoch",
        "2000",
        "--json",
    )
    assert code == 0
    result = json.loads(out)
    assert abs(result["ra_deg"] - 83.8) < 0.01 and abs(result["dec_deg"] + 5.4) < 0.01
    assert abs((result["roll_deg"] - 30 + 180) % 360 - 180) < 0.3
    assert sum(s["catalog_id"] is None for s in result["stars"]) >= 2


def test_demo_and_database(capsys):
    code, out, _ = run_cli(capsys, "demo", "--seed", "3", "--json")
    result = json.loads(out)
    assert code == 0 and result["solution"]["solved"]
    assert result["comparison"]["ids_wrong"] == 0
    assert result["comparison"]["boresight_error_arcsec"] < 60
    code, out, _ = run_cli(capsys, "database", "--fov-deg", "12", "--width", "512", "--json")
    info = json.loads(out)
    assert code == 0 and info["stars"] == 4559 and info["pairs"] > 100000 and info["bytes"] > 0


def test_console_script_no_traceback(tmp_path):
    """The installed command itself: bad input gives one line and exit 2."""
    path = tmp_path / "bad.csv"
    path.write_text("x,y\n1,2\n")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "starnav.cli",
            "identify",
            str(path),
            "--fov-deg",
            "12",
            "--width",
            "512",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "Traceback" not in proc.stderr


def test_identify_plot_writes_png(capsys, tmp_path):
    png = tmp_path / "map.png"
    code, _, _ = _identify(
        capsys,
        MAP1,
        "--plot",
        str(png),
    )
    assert code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10000
    code, _, err = _identify(
        capsys,
        MAP1,
        "--plot",
        str(tmp_path / "no" / "map.png"),
    )
    assert code == 2 and "cannot write plot" in err


def test_flux_column_orders_the_search(capsys, tmp_path):
    """A flux column is read as brightness: the frame solves with the rows shuffled."""
    code, out, _ = run_cli(
        capsys,
        "simulate",
        "--ra-deg",
        "250",
        "--dec-deg",
        "36",
        "--roll-deg",
        "5",
        "--fov-deg",
        "12",
        "--width",
        "512",
        "--seed",
        "1",
        "--epoch",
        "2000",
        "-o",
        str(tmp_path / "f.csv"),
        "--json",
    )
    lines = (tmp_path / "f.csv").read_text().splitlines()
    rows = [line.split(",") for line in lines[1:]]
    rng = np.random.default_rng(0)
    flux_csv = tmp_path / "flux.csv"
    flux_csv.write_text(
        "label,x,y,flux\n"
        + "".join(
            f"{r[0]},{r[1]},{r[2]},{10 ** (-0.4 * float(r[3]))}\n"
            for r in (rows[k] for k in rng.permutation(len(rows)))
        )
    )
    code, out, _ = run_cli(
        capsys,
        "identify",
        str(flux_csv),
        "--fov-deg",
        "12",
        "--width",
        "512",
        "--epoch",
        "2000",
        "--json",
    )
    result = json.loads(out)
    assert code == 0 and abs(result["ra_deg"] - 250) < 0.01 and abs(result["dec_deg"] - 36) < 0.01


@pytest.mark.parametrize(
    "argv",
    [["--algorithm", name] for name in ALGORITHMS]
    + [["--algorithm", "triangle", "--triangle-selection", "brightest"]],
    ids=lambda argv: "-".join(argv[1::2]),
)
def test_every_algorithm_from_the_cli_on_contest_map_1(capsys, argv):
    """Each algorithm, chosen by name, identifies all 15 points of map 1 at its published
    attitude (RA 109.6°, Dec 34.5°)."""
    assert (
        main(
            [
                "identify",
                MAP1,
                "--fov-deg",
                "12",
                "--width",
                "512",
                "--catalog",
                CATALOG,
                "--json",
                *argv,
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["algorithm"] == argv[1] and out["n_matched"] == 15
    assert out["ra_deg"] == pytest.approx(109.6, abs=0.01)
    assert out["dec_deg"] == pytest.approx(34.5, abs=0.01)
