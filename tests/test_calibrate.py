"""Calibration of a fisheye (Kannala-Brandt) camera from star images: the sky as the target."""

import dataclasses
import json

import numpy as np
import pytest

from starnav.calibrate import calibrate
from starnav.camera import KannalaBrandt, load_camera, save_camera
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.errors import StarnavError
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import solve_image
from starnav.simulate import project_catalog
from starnav.simulate.render import write_image

TRUE = dataclasses.replace(
    KannalaBrandt.from_fov(170.0, 1024, 1024, k1=0.02, k2=-0.004), cx=515.3, cy=508.7
)
POINTINGS = [(10, 40, 0), (120, -30, 40), (250, 5, 80), (200, 70, 150)]  # RA, Dec, roll (deg)
SPOT_SIGMA_PX = 1.2
_HALF = 5  # spot stamps are (2 * _HALF + 1) px square


def _draw(cat, R, seed):
    """A 1024 x 1024 float image of the catalog stars through TRUE at attitude R: Gaussian
    spots (flux from magnitude) on a flat background with Gaussian noise."""
    rng = np.random.default_rng(seed)
    rows, xy = project_catalog(cat, R, TRUE)
    image = np.full((TRUE.height, TRUE.width), 100.0)
    flux = 2e4 * 10.0 ** (-0.4 * (cat.mag[rows] - 1.0))
    dy, dx = np.mgrid[-_HALF : _HALF + 1, -_HALF : _HALF + 1]
    for (x, y), f in zip(xy, flux, strict=True):
        col, row = int(x) + dx, int(y) + dy  # pixel (col, row) has its centre at +0.5
        r2 = (col + 0.5 - x) ** 2 + (row + 0.5 - y) ** 2
        spot = f / (2 * np.pi * SPOT_SIGMA_PX**2) * np.exp(-0.5 * r2 / SPOT_SIGMA_PX**2)
        inside = (col >= 0) & (col < TRUE.width) & (row >= 0) & (row < TRUE.height)
        np.add.at(image, (row[inside], col[inside]), spot[inside])
    return image + rng.normal(0.0, 5.0, image.shape)


@pytest.fixture(scope="module")
def frames():
    cat = load_catalog(None, mag_limit=5.0)
    Rs = [attitude_from_radec_roll(ra, dec, roll, 1) for ra, dec, roll in POINTINGS]
    return [_draw(cat, R, seed) for seed, R in enumerate(Rs)], Rs


@pytest.fixture(scope="module")
def fisheye_calibration(frames):
    return calibrate(frames[0], model="kannala-brandt", fov_deg=170.0, max_stars=200)


@pytest.mark.slow
def test_kannala_brandt_recovered_within_its_sigmas(fisheye_calibration):
    cal = fisheye_calibration
    cam = cal.camera
    assert isinstance(cam, KannalaBrandt) and len(cal.frames) == 4 and not cal.failed
    assert set(cal.sigma) == {"focal_px", "cx", "cy", "k1", "k2", "k3", "k4"}
    for key in ("focal_px", "cx", "cy", "k1", "k2"):
        assert abs(getattr(cam, key) - getattr(TRUE, key)) < 4 * cal.sigma[key], key
    # the sigmas are those of ~800 stars at ~0.2 px, not zero nor a failed inversion
    assert 0.005 < cal.sigma["focal_px"] < 0.3
    assert 0.002 < cal.sigma["cx"] < 0.1 and 0.002 < cal.sigma["cy"] < 0.1
    assert 1e-5 < cal.sigma["k1"] < 2e-3 and 1e-5 < cal.sigma["k2"] < 2e-3
    assert cal.rms_px < 0.3 and cal.n_stars > 600
    # the fitted lens maps the sky where the true one does, corners included
    edge = np.linspace(0.5, 1023.5, 21)
    xy = np.array([(x, y) for x in edge for y in edge])
    moved = cam.bearings_to_pixels(TRUE.pixels_to_bearings(xy)) - xy
    assert np.max(np.hypot(*moved.T)) < 0.2


@pytest.mark.slow
def test_calibrated_fisheye_file_solves_an_image(fisheye_calibration, frames, tmp_path):
    path = tmp_path / "fisheye.json"
    save_camera(path, fisheye_calibration.camera)
    cam = load_camera(path)
    assert cam == fisheye_calibration.camera
    res = solve_image(frames[0][1], camera=cam, max_stars=200)
    assert res.solution is not None, res.reason
    bore, roll = attitude_difference_deg(res.solution.R_cam_from_icrs, frames[1][1])
    assert bore * 3600 < 30 and roll < 0.02


@pytest.mark.slow
def test_cli_calibrates_a_fisheye_then_solves_with_its_file(frames, tmp_path, capsys):
    paths = []
    for k, image in enumerate(frames[0][:3]):
        paths.append(tmp_path / f"sky{k}.fits")
        write_image(paths[-1], image)
    cam_file = tmp_path / "camera.json"
    args = ["calibrate", *map(str, paths), "-o", str(cam_file), "--model", "kannala-brandt"]
    code = main([*args, "--fov-range", "150", "190", "--max-stars", "200", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out
    assert out["model"] == "kannala-brandt" and len(out["frames"]) == 3
    assert out["k1"] == pytest.approx(TRUE.k1, abs=5 * out["sigma"]["k1"])
    cam = load_camera(cam_file)
    assert cam.model == "kannala-brandt" and cam.focal_px == pytest.approx(out["focal_px"])
    code = main(["solve", str(paths[2]), "--camera", str(cam_file), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["solved"]
    assert out["camera_model"] == "kannala-brandt" and out["k1"] == pytest.approx(cam.k1)


def test_unknown_model_is_a_one_line_error(tmp_path, capsys):
    image = tmp_path / "blank.png"
    write_image(image, np.zeros((64, 64), dtype=np.uint16))
    with pytest.raises(StarnavError, match="unknown lens model 'fish'"):
        calibrate([image], model="fish")
    with pytest.raises(SystemExit) as exit_:
        main(["calibrate", str(image), "-o", str(tmp_path / "c.json"), "--model", "fish"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and "fish" in err
