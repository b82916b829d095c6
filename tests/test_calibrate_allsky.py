"""Calibrating all-sky cameras from their frames (rendered with known truth): a circular,
decentred fisheye Kannala-Brandt lens whose r(θ) turns over in the dark corners, a mirrored
one, the fixed camera's mount, and a later frame tracked from the camera file."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from starnav.calibrate import _converted, calibrate
from starnav.camera import Equisolid, KannalaBrandt, load_camera, save_camera
from starnav.camera.lens import kernels
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.errors import CameraError, StarnavError
from starnav.geometry import attitude_difference_deg
from starnav.navigation.mount import (
    Mount,
    R_enu_from_icrs,
    fit_mount,
    mount_prior,
    predict_attitude,
)
from starnav.simulate.render import RenderSettings, render_frame, write_image

SITE = (50.0, 10.0, 300.0)  # lat, lon (degrees), height (m)
UTCS = ("2026-03-14T21:00:00", "2026-03-14T21:20:00", "2026-03-14T22:30:00")
W, H = 1000, 840


def _between(w_ortho: float, f: float, cx: float, cy: float) -> KannalaBrandt:
    """A circular (180°) Kannala-Brandt lens whose r(θ) is (1 - w) equisolid + w
    orthographic over the sky (fitted to 92°): it turns over beyond the horizon."""
    theta = np.linspace(0.01, math.radians(92.0), 200)
    r = f * ((1 - w_ortho) * 2 * np.sin(theta / 2) + w_ortho * np.sin(theta))
    a, *_ = np.linalg.lstsq(np.column_stack([theta ** (2 * j + 1) for j in range(5)]), r)
    return KannalaBrandt(W, H, a[0], cx, cy, 180.0, *(a[1:] / a[0]))


TRUE = _between(0.1, 330.0, 515.0, 410.0)  # 18 px from the image centre
# x north, y west, z up, tilted 2° about x: a levelled-ish upward camera
_T = math.radians(2.0)
MOUNT = np.array([[1, 0, 0], [0, math.cos(_T), -math.sin(_T)], [0, math.sin(_T), math.cos(_T)]])
MOUNT = MOUNT @ np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])
MIRROR = np.diag([-1.0, 1.0, 1.0])  # a flipped readout: x reversed


def _r(camera, theta: float) -> float:
    return camera.focal_px * kernels().radial_g(camera.model_code, camera.params, theta)[0]


def _frame(camera, R, seed: int) -> np.ndarray:
    settings = RenderSettings(seed=seed, mag_limit=6.5, background_e=400.0)
    return render_frame(load_catalog(None, mag_limit=6.5), camera, R, settings).image


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    """PNG files of TRUE at the three UTCs, a bumped camera at the last, and the truths."""
    folder = tmp_path_factory.mktemp("allsky")
    truths = [MOUNT @ R_enu_from_icrs(utc, *SITE) for utc in UTCS]
    paths = []
    for k, R in enumerate(truths):
        paths.append(folder / f"sky{k}.png")
        write_image(paths[-1], _frame(TRUE, R, k))
    c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
    bumped = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ truths[2]
    paths.append(folder / "bumped.png")
    write_image(paths[-1], _frame(TRUE, bumped, 9))
    return paths, [*truths, bumped]


@pytest.fixture(scope="module")
def kb_calibration(sky):
    paths, _ = sky
    return calibrate(paths[:2], model="kannala-brandt", times=UTCS[:2], site=SITE)


@pytest.mark.slow
def test_circular_decentred_kannala_brandt_within_its_sigmas(kb_calibration):
    cal = kb_calibration
    cam = cal.camera
    assert isinstance(cam, KannalaBrandt) and len(cal.frames) == 2 and not cal.failed
    assert cal.start_lens == "equisolid on the image circle"  # the circle's centre as a start
    for key in ("focal_px", "cx", "cy"):
        assert abs(getattr(cam, key) - getattr(TRUE, key)) < 4 * cal.sigma[key], key
    assert 0.002 < cal.sigma["cx"] < 0.2 and 0.005 < cal.sigma["focal_px"] < 0.5
    # the fitted r(θ) is the true one over the sky
    for deg in range(5, 90, 5):
        assert abs(_r(cam, math.radians(deg)) - _r(TRUE, math.radians(deg))) < 0.1, deg
    assert cal.rms_px < 0.2 and min(cal.frame_stars) > 40 and max(cal.frame_rms_px) < 0.2
    # the camera records its circle: r(θ) increases to there, not into the dark corners,
    # where the lens turns over (what made the calibration refuse it before)
    assert 175.0 < cam.image_circle_deg < 181.0
    with pytest.raises(CameraError, match="stops increasing"):
        TRUE.with_circle(None).check_monotonic("the lens without its circle")
    assert cal.models[0].model == "kannala-brandt" and len(cal.models) == 1


@pytest.mark.slow
def test_calibrated_mount_predicts_the_attitude(kb_calibration, sky):
    cal = kb_calibration
    assert cal.mount is not None and cal.mount.spread_deg < 0.02
    angle = math.degrees(math.acos((np.trace(cal.mount.R_cam_from_enu @ MOUNT.T) - 1) / 2))
    assert angle < 0.03
    _, truths = sky
    bore, roll = attitude_difference_deg(predict_attitude(cal.mount, UTCS[2]), truths[2])
    assert bore < 0.03 and roll < 0.05


@pytest.mark.slow
def test_cli_calibrates_one_frame_then_tracks_a_later_one(sky, tmp_path, capsys):
    paths, truths = sky
    cam_file, plot = tmp_path / "allsky.json", tmp_path / "residuals.png"
    args = ["calibrate", str(paths[0]), "-o", str(cam_file), "--model", "kannala-brandt"]
    args += ["--utc", UTCS[0], "--lat", "50", "--lon", "10", "--height-m", "300"]
    assert main([*args, "--plot", str(plot), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "kannala-brandt" and out["mount"]["lat_deg"] == 50.0
    assert plot.stat().st_size > 10_000 and out["frames"][0]["n_stars"] > 40
    data = json.loads(cam_file.read_text())
    assert data["image_circle_deg"] > 175 and set(data["sigma"]) >= {"focal_px", "k4"}
    assert load_camera(cam_file).model == "kannala-brandt"  # loads: checked up to its circle
    # a frame 90 minutes later: the attitude predicted, tracked and verified
    solve = ["solve", str(paths[2]), "--camera", str(cam_file), "--utc", UTCS[2], "--json"]
    assert main(solve) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] and out["algorithm"] == "tracking"
    assert out["false_match_probability"] < 1e-6 and out["mount_prior"]["off_deg"] < 0.05
    R = np.array(out["R_cam_from_icrs"])
    bore, roll = attitude_difference_deg(R, truths[2])
    assert bore * 3600 < 60 and roll < 0.05
    # the camera was bumped by 20°: still solved right, from the same prior (the tracking
    # window is the field plus 3 sigma: for an all-sky lens most of the sky; a prediction that
    # does not verify falls back to the full search through the camera)
    bumped = ["solve", str(paths[3]), "--camera", str(cam_file), "--utc", UTCS[2], "--json"]
    assert main(bumped) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] and out["false_match_probability"] < 1e-6
    bore, _ = attitude_difference_deg(np.array(out["R_cam_from_icrs"]), truths[3])
    assert bore < 0.02 and 19.5 < out["mount_prior"]["off_deg"] < 20.5


@pytest.mark.slow
def test_mirrored_decentred_equisolid_chosen_by_auto(tmp_path):
    true = Equisolid(W, H, 290.0, 480.0, 440.0, image_circle_deg=180.0)
    frames = [
        _frame(true, MIRROR @ MOUNT @ R_enu_from_icrs(utc, *SITE), 20 + k)
        for k, utc in enumerate(UTCS[:2])
    ]
    cal = calibrate(frames, model="auto", times=UTCS[:2], site=SITE)
    assert cal.parity == -1 and cal.mount is not None
    assert np.linalg.det(cal.mount.R_cam_from_enu) < 0
    best = min(cal.models, key=lambda m: m.bic)
    assert best.model == cal.camera.model == "equisolid"
    assert {m.model for m in cal.models} >= {"equisolid", "kannala-brandt", "equidistant"}
    for key in ("focal_px", "cx", "cy"):
        assert abs(getattr(cal.camera, key) - getattr(true, key)) < 4 * cal.sigma[key], key


def test_kannala_brandt_start_matches_a_fixed_lens():
    eq = Equisolid(W, H, 300.0, 510.0, 400.0)
    kb = _converted(eq, KannalaBrandt, math.radians(90.0))
    assert (kb.cx, kb.cy) == (510.0, 400.0)
    for deg in range(5, 91, 5):
        assert abs(_r(kb, math.radians(deg)) - _r(eq, math.radians(deg))) < 0.05


def test_mount_fit_round_trip_and_parity():
    times = UTCS[:2]
    for parity_matrix in (np.eye(3), MIRROR):
        truth = parity_matrix @ MOUNT
        attitudes = [truth @ R_enu_from_icrs(t, *SITE) for t in times]
        mount = fit_mount(attitudes, list(times), *SITE)
        assert np.allclose(mount.R_cam_from_enu, truth, atol=1e-9) and mount.spread_deg < 1e-6
        again = Mount.from_dict(json.loads(json.dumps(mount.to_dict())))
        assert np.allclose(
            predict_attitude(again, UTCS[2]), truth @ R_enu_from_icrs(UTCS[2], *SITE)
        )
    # one hour of the sky's turn is 15° about the pole: the prediction follows it
    a, b = (predict_attitude(mount, t) for t in ("2026-03-14T21:00:00", "2026-03-14T22:00:00"))
    assert abs(math.degrees(math.acos((np.trace(a @ b.T) - 1) / 2)) - 15.04) < 0.01


def test_camera_file_without_mount_gives_no_prior(tmp_path):
    path = tmp_path / "cam.json"
    save_camera(path, Equisolid(W, H, 300.0))
    assert mount_prior(path, None, UTCS[0]) is None
    save_camera(path, Equisolid(W, H, 300.0), mount={"lat_deg": 50.0})
    with pytest.raises(StarnavError, match="mount: needs R_cam_from_enu"):
        mount_prior(path, None, UTCS[0])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--lat", "50"], "give both --lat and --lon"),
        (["--lat", "95", "--lon", "10"], "latitude must be in [-90, 90]"),
        (["--plot", "x.jpg"], "ending in .png"),
    ],
)
def test_calibrate_refuses_bad_site_and_plot(tmp_path, capsys, extra, message):
    image = tmp_path / "blank.png"
    write_image(image, np.zeros((64, 64), dtype=np.uint16))
    code = main(["calibrate", str(image), "-o", str(tmp_path / "c.json"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1


def test_calibrate_utc_is_for_one_image(tmp_path, capsys):
    image = tmp_path / "blank.png"
    write_image(image, np.zeros((64, 64), dtype=np.uint16))
    args = ["calibrate", str(image), str(image), "-o", str(tmp_path / "c.json")]
    code = main([*args, "--utc", UTCS[0], "--lat", "50", "--lon", "10"])
    err = capsys.readouterr().err
    assert code == 2 and "--utc is for one image" in err


@pytest.mark.slow
def test_starting_camera_file_solves_and_the_fit_leaves_it(sky, tmp_path):
    paths, _ = sky
    # a hand-made equisolid camera: the focal length from the spec, the centre a few px off
    start = dataclasses.replace(
        _converted(TRUE, Equisolid, math.radians(90.0)), cx=TRUE.cx - 3.0, cy=TRUE.cy + 2.0
    )
    path = tmp_path / "start.json"
    save_camera(path, start)
    cal = calibrate(paths[:1], model="kannala-brandt", camera=path)
    assert cal.start_lens == "camera" and isinstance(cal.camera, KannalaBrandt)
    for key in ("cx", "cy"):
        assert abs(getattr(cal.camera, key) - getattr(TRUE, key)) < 4 * cal.sigma[key], key
    for deg in range(5, 90, 5):
        assert abs(_r(cal.camera, math.radians(deg)) - _r(TRUE, math.radians(deg))) < 0.2, deg
