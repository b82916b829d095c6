"""Celestial fix: observations made independently with astropy's AltAz frame
(tests/data/locate/make_observations.py) must give the site within 10 m and the heading within
1″; bad observations give one line and exit 2."""

import json

import numpy as np
import pytest

from shared_data import DATA as TEST_DATA
from starnav.cli import main
from starnav.navigation import ObservationError, locate, parse_observation, read_observation
from starnav.navigation.frames import radii_of_curvature_m
from starnav.navigation.simulate import simulate_observation

DATA = TEST_DATA / "locate"
CASES = sorted(p.name.removesuffix(".truth.json") for p in DATA.glob("*.truth.json"))


def _errors(fix, truth):
    """North and east position error (m) and heading error (arcsec)."""
    m_north, m_east = radii_of_curvature_m(truth["lat_deg"])
    north = np.radians(fix.lat_deg - truth["lat_deg"]) * m_north
    east = (
        np.radians((fix.lon_deg - truth["lon_deg"] + 180.0) % 360.0 - 180.0)
        * m_east
        * np.cos(np.radians(truth["lat_deg"]))
    )
    heading = ((fix.azimuth_deg - truth["azimuth_deg"] + 180.0) % 360.0 - 180.0) * 3600.0
    return north, east, heading


@pytest.mark.parametrize("case", CASES)
def test_independent_astropy_observations(case):
    assert len(CASES) >= 5
    truth = json.loads((DATA / f"{case}.truth.json").read_text())
    fix = locate(read_observation(DATA / f"{case}.json"), sigma_px=0.1)
    north, east, heading = _errors(fix, truth)
    assert np.hypot(north, east) < 10.0
    assert abs(heading) < 1.0
    assert fix.rms_arcsec < 0.1  # exact centroids: the model and the generator agree
    assert fix.ellipse_major_m >= fix.ellipse_minor_m > 0


def test_a_camera_without_stars_is_reported_and_the_others_fix():
    fix = locate(read_observation(DATA / "ground_camera.json"))
    used = {c.name: c.stars_used for c in fix.cameras}
    assert used["camera 2"] == 0 and "fewer than 3" in fix.cameras[1].reason
    assert used["camera 1"] >= 10 and used["camera 3"] >= 10


def test_noisy_fix_is_within_its_ellipse():
    """0.5 px centroid noise: the position errors of 12 fixes against the reported 1-sigma
    ellipse (chi-square with 2 degrees of freedom: mean 2)."""
    rng = np.random.default_rng(3)
    d2 = []
    for _ in range(12):
        sky = simulate_observation(
            lat_deg=-33.9,
            lon_deg=18.4,
            utc="2025-06-01T22:00:00Z",
            heading_deg=float(rng.uniform(0, 360)),
            pitch_deg=1.0,
            noise_px=0.5,
            seed=rng,
        )
        fix = locate(sky.observation, sigma_px=0.5)
        north, east, _ = _errors(
            fix, {"lat_deg": -33.9, "lon_deg": 18.4, "azimuth_deg": fix.azimuth_deg}
        )
        a = np.radians(fix.ellipse_angle_deg)
        along = north * np.cos(a) + east * np.sin(a)
        across = -north * np.sin(a) + east * np.cos(a)
        d2.append((along / fix.ellipse_major_m) ** 2 + (across / fix.ellipse_minor_m) ** 2)
    assert 0.5 < np.mean(d2) < 5.0


def _observation(**changes):
    data = json.loads((DATA / "reference_level.json").read_text())
    data.update(changes)
    return data


@pytest.mark.parametrize(
    "data,needle",
    [
        ({k: v for k, v in _observation().items() if k != "utc"}, "'utc' is missing"),
        (_observation(utc="yesterday"), "not an ISO 8601 time"),
        (_observation(gravity_body=[0, 0, 0]), "zero vector"),
        (_observation(gravity_body=[0, 1]), "gravity_body"),
        (_observation(cameras=[]), "non-empty list"),
        (_observation(wind_knots=3), "unknown keys"),
        (
            _observation(cameras=[{"fov_deg": 20, "width": 1024, "height": 1024, "lens": "x"}]),
            "unknown keys",
        ),
        (
            _observation(cameras=[{"fov_deg": 20, "width": 1024, "height": 1024, "stars": []}]),
            "mount is missing",
        ),
        (
            _observation(
                cameras=[
                    {
                        "fov_deg": 20,
                        "width": 1024,
                        "height": 1024,
                        "azimuth_deg": 0,
                        "elevation_deg": 45,
                        "image": "sky.fits",
                    }
                ]
            ),
            "sky.fits' does not exist",
        ),
        (
            _observation(
                cameras=[
                    {
                        "fov_deg": 20,
                        "width": 1024,
                        "height": 1024,
                        "R_cam_from_body": [[1, 0, 0], [0, 1, 0], [0, 0, 2]],
                        "stars": [],
                    }
                ]
            ),
            "not a rotation",
        ),
        (_observation(gravity_sigma_deg=-1), "gravity_sigma_deg"),
        (_observation(gravity_sigma_deg="1°"), "gravity_sigma_deg must be a number"),
    ],
)
def test_bad_observations_are_one_line_exit_2(tmp_path, capsys, data, needle):
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ObservationError, match=needle):
        parse_observation(data)
    assert main(["locate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err and "Traceback" not in err


def test_unreadable_and_not_json(tmp_path, capsys):
    assert main(["locate", str(tmp_path / "missing.json")]) == 2
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["locate", str(bad)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_no_camera_with_stars_is_not_solved_exit_1(tmp_path, capsys):
    data = _observation()
    for camera in data["cameras"]:
        camera["stars"] = camera["stars"][:2]
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(data))
    assert main(["locate", str(path), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] is False and "camera 1: fewer than 3 stars" in out["reason"]


def test_cli_json_and_text(capsys):
    assert main(["locate", str(DATA / "reference_level.json"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in (
        "lat_deg",
        "lon_deg",
        "azimuth_deg",
        "ellipse_major_m",
        "ellipse_minor_m",
        "ellipse_angle_deg",
        "stars_used",
        "rms_arcsec",
    ):
        assert key in out
    assert set(out["stars_used"]) == {"camera 1", "camera 2", "camera 3"}
    assert main(["locate", str(DATA / "reference_level.json")]) == 0
    assert "fix: lat +47.3700" in capsys.readouterr().out


def test_study_tilt_maps_to_31_m_per_arcsec_and_stars_average_down():
    """1″ of tilt about one axis moves the fix by 1″ of arc on the ground (30.9 m); about each
    of two axes, sqrt(2) times that. More stars, smaller error."""
    from starnav.studies.locate import run_locate_study

    tables = run_locate_study(trials=4, fovs_deg=(10.0, 30.0), progress=False)
    for row, tilt in zip(tables["tilt"], (3, 5, 10, 15, 20), strict=True):
        assert row.mean_position_m == pytest.approx(30.87 * tilt, rel=0.03)
    for row, tilt in zip(tables["tilt2"], (3, 5, 10, 15, 20), strict=True):
        assert row.mean_position_m == pytest.approx(30.87 * np.sqrt(2) * tilt, rel=0.03)
    assert tables["star"][0].mean_position_m < tables["star3"][0].mean_position_m
    narrow, wide = tables["fov"]
    assert wide.stars > narrow.stars


def test_cli_locate_study(capsys, tmp_path):
    png = tmp_path / "study.png"
    assert main(["locate-study", "--trials", "2", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "| 3″ | 126.99 |" in out and png.stat().st_size > 10_000
    assert main(["locate-study", "--fov-deg", "0"]) == 2


def test_study_takes_the_camera_set_up_one_upward_camera():
    """One upward-looking camera (a 90° pinhole standing in for a fisheye) as the study's
    set-up and compared with three 20° cameras at the same star and tilt errors."""
    from starnav.camera import Camera
    from starnav.studies.locate import run_locate_study, three_cameras, upward_camera

    up = upward_camera(Camera.from_fov(90.0, 1024))
    tables = run_locate_study(trials=3, fovs_deg=(), cameras=up, progress=False)
    assert [r.setting for r in tables["cameras"]] == ["one upward 90° camera"]
    assert tables["fov"] == []
    for row, tilt in zip(tables["tilt"], (3, 5, 10, 15, 20), strict=True):
        assert row.mean_position_m == pytest.approx(30.87 * tilt, rel=0.03)
    tables = run_locate_study(
        trials=3, fovs_deg=(), compare=(up,), compare_conditions=((2.0, 0.0),), progress=False
    )
    three, upward = tables["setups"]
    assert three.setting == f"{three_cameras().label}, 2″ stars, 0″ tilt"
    assert upward.setting.startswith("one upward 90° camera")
    assert upward.stars > 3 * three.stars  # 2.1 sr of sky against 3 x 0.12 sr
    assert 0 < upward.mean_position_m < 30 and 0 < three.mean_position_m < 30


def test_cli_locate_study_upward_camera(capsys, tmp_path):
    from starnav.camera import Camera, save_camera

    up = tmp_path / "up.json"
    save_camera(up, Camera.from_fov(90.0, 512))
    assert main(["locate-study", "--trials", "2", "--upward-camera", str(up)]) == 0
    out = capsys.readouterr().out
    assert "| camera set-up |" in out and "| one upward 90° camera, 2″ stars, 5″ tilt |" in out
    assert main(["locate-study", "--upward-camera", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "none.json does not exist" in err and "\n" not in err


def test_an_upward_fisheye_fixes_within_its_stated_levelling():
    """One levelled upward all-sky camera (an equidistant 180° fisheye): the zenith of the
    fitted camera is the vertical. Level, the fix is metres off; tilted 1° while gravity still
    says level, it is ~111 km off, and the 1° the observation states covers it."""
    from dataclasses import replace

    from starnav.camera.fisheye import Equidistant

    lens = Equidistant.from_fov(180.0, 800)
    site = {"lat_deg": 78.148, "lon_deg": 16.043, "utc": "2020-12-11T20:09:33"}
    for tilt_deg in (0.0, 1.0):
        sky = simulate_observation(
            **site, heading_deg=30.0, pitch_deg=tilt_deg, mounts=((0.0, 90.0),), camera=lens,
            mag_limit=5.0, seed=2,
        )  # fmt: skip
        level = replace(sky.observation, gravity_body=np.array([0.0, 0.0, 1.0]),
                        gravity_sigma_deg=1.0)  # fmt: skip
        fix = locate(level)
        m_north, m_east = radii_of_curvature_m(site["lat_deg"])
        north = np.radians(fix.lat_deg - site["lat_deg"]) * m_north
        east = np.radians(fix.lon_deg - site["lon_deg"]) * np.cos(np.radians(78.148)) * m_east
        off_m = float(np.hypot(north, east))
        assert fix.cameras[0].stars_used > 50
        if tilt_deg == 0.0:
            assert off_m < 100.0
        else:
            assert 0.9 * fix.gravity_north_m < off_m < 1.1 * fix.gravity_north_m
        assert fix.gravity_north_m == pytest.approx(111_700, rel=0.01)
        assert fix.to_dict()["gravity_east_m"] == pytest.approx(fix.gravity_east_m)
