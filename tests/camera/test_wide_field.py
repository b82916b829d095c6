"""Identification through the fisheye lens models, up to a 185° field."""

import json
import subprocess
import sys

import numpy as np
import pytest

from starnav.api import solve_stars
from starnav.camera import MODELS, save_camera
from starnav.catalog import load_catalog
from starnav.simulate import simulate_frame, write_frame_csv

KB = {"k1": 0.02, "k2": -0.003, "k3": 0.0005, "k4": -0.00005}


@pytest.fixture(scope="module")
def catalog():
    return load_catalog(None, mag_limit=6.0)


def fisheye(model: str, fov_deg: float):
    camera = MODELS[model].from_fov(fov_deg, 800, 800, **(KB if model == "kannala-brandt" else {}))
    return camera.with_circle(fov_deg) if fov_deg >= 150 else camera


CASES = [
    (m, f)
    for m in ("equidistant", "equisolid", "stereographic", "kannala-brandt")
    for f in (90.0, 120.0, 150.0, 185.0)
] + [("orthographic", f) for f in (90.0, 150.0, 180.0)]
# the fields of 180° and more take 1.3-2.1 s each: the quick loop keeps every model up to 150°
CASES = [pytest.param(*c, marks=pytest.mark.slow) if c[1] >= 180.0 else c for c in CASES]


@pytest.mark.parametrize(("model", "fov_deg"), CASES)
def test_fisheye_star_lists_solve_to_the_truth(catalog, model, fov_deg):
    """0.5 px noise, false stars, dropped stars: the attitude within 0.02°, no wrong answer."""
    camera = fisheye(model, fov_deg)
    for seed in range(2):
        frame = simulate_frame(
            catalog, camera, noise_px=0.5, false_stars=5, missing_frac=0.1, seed=seed
        )
        result = solve_stars(
            frame.xy, camera=camera, brightness=frame.brightness, catalog=catalog, sigma_px=0.5
        )
        diff = frame.compare(result.solution)
        assert diff is not None, result.reason
        assert diff["boresight_error_arcsec"] < 0.02 * 3600
        assert diff["roll_error_arcsec"] < 0.1 * 3600
        # close pairs a pixel or two apart (the orthographic edge squeezes the sky radially)
        assert diff["ids_wrong"] <= 0.05 * diff["ids_correct"]
        assert result.solution.camera_model == model


def test_wide_fields_use_a_bounded_database(catalog):
    """A 185° field holds half the sky; its pairs stay within 60° among the brightest."""
    from starnav.api import get_database
    from starnav.pipeline.solver import MAX_PAIR_DEG

    database = get_database(catalog, fisheye("equidistant", 185.0))
    assert np.degrees(database.max_angle_rad) <= MAX_PAIR_DEG + 0.5
    assert database.pair_stars < len(catalog) / 4
    assert database.pair_a.max() < len(catalog) and len(database.pair_a) < 200_000
    assert np.all(
        catalog.mag[np.unique(database.pair_a)] <= np.sort(catalog.mag)[database.pair_stars]
    )


@pytest.mark.slow
def test_random_points_in_a_fisheye_are_refused(catalog):
    camera = fisheye("equidistant", 185.0)
    rng = np.random.default_rng(5)
    r = 400 * np.sqrt(rng.uniform(0, 1, 30))
    phi = rng.uniform(0, 2 * np.pi, 30)
    xy = np.column_stack([400 + r * np.cos(phi), 400 + r * np.sin(phi)])
    result = solve_stars(xy, camera=camera, brightness=rng.uniform(0, 1, 30), catalog=catalog)
    assert result.solution is None


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "starnav.cli", *args], capture_output=True, text=True, timeout=600
    )


@pytest.mark.slow
def test_cli_identifies_with_a_camera_file_and_scans_a_lens(catalog, tmp_path):
    camera = fisheye("equisolid", 185.0)
    frame = simulate_frame(catalog, camera, ra_deg=250.0, dec_deg=-40.0, roll_deg=70.0, seed=2)
    write_frame_csv(tmp_path / "stars.csv", frame)
    save_camera(tmp_path / "cam.json", camera)
    out = _cli("identify", str(tmp_path / "stars.csv"), "--camera", str(tmp_path / "cam.json"),
               "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["camera_model"] == "equisolid"
    assert abs(got["dec_deg"] + 40.0) < 0.01
    # the lens known, its focal length not: scanned over a range of fields
    out = _cli("identify", str(tmp_path / "stars.csv"), "--width", "800", "--lens", "equisolid",
               "--fov-range", "160", "200", "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert abs(got["fov_deg"] - camera.fov_deg) < 0.1 and abs(got["dec_deg"] + 40.0) < 0.01


def test_cli_bad_camera_files_are_one_line_errors(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text(
        '{"model": "kannala-brandt", "width": 800, "height": 800, "focal_px": 250, "cx": 400,'
        ' "cy": 400, "k1": -0.3, "k2": 0, "k3": 0, "k4": 0}'
    )
    (tmp_path / "stars.csv").write_text("x,y\n1,2\n3,4\n5,6\n")
    out = _cli("identify", str(tmp_path / "stars.csv"), "--camera", str(path))
    assert out.returncode == 2 and "stops increasing" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
