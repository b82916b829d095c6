"""The sky's state (``starnav sky``): its pieces, its refusals, and real all-sky frames: the
KHO frame of ../shared/data/allsky (clear), and the tudo all_sky_cloud_detection frames
(clear and overcast; read from $STARNAV_TUDO_FRAMES, skipped when it is not set) with the
camera and mount we measured on one clear frame of each camera (tests/data/allsky/
tudo_cameras.json, benchmarks/images/sky_cameras.py)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import run_cli
from shared_data import ALLSKY, DATA, shared_file
from starnav.errors import StarnavError
from starnav.sky.state import Site, airmass, limiting_magnitude, local_shift, read_mount

KHO = ALLSKY / "kho_sony_a7s_20201211_200933.jpg"
KHO_SITE = ["--lat", "78.148", "--lon", "16.043", "--height-m", "520",
            "--utc", "2020-12-11T20:09:33"]  # fmt: skip
CAMERAS = DATA / "allsky" / "tudo_cameras.json"


def test_limiting_magnitude_is_where_half_the_stars_are_lost():
    mag = np.linspace(1.0, 8.0, 141)
    assert limiting_magnitude(mag, mag < 5.2) == pytest.approx(5.0, abs=0.5)
    assert limiting_magnitude(mag, np.zeros_like(mag, dtype=bool)) is None
    assert limiting_magnitude(mag[:2], np.ones(2, dtype=bool)) is None


def test_airmass_is_one_at_the_zenith_and_about_two_at_30_degrees():
    assert airmass(np.array([90.0]))[0] == pytest.approx(1.0, abs=1e-3)
    assert airmass(np.array([30.0]))[0] == pytest.approx(2.0, abs=0.01)


def test_local_shift_follows_a_smooth_error_of_the_lens_model():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 1000, (800, 2))
    mag = rng.uniform(1, 7, 800)
    error = np.column_stack([3.0 + xy[:, 0] / 250.0, -2.0 + xy[:, 1] / 500.0])  # 3-7 px
    seen = xy + error + rng.normal(0, 0.3, xy.shape)
    moved = local_shift(xy, mag, seen[:400])
    assert np.median(np.hypot(*(moved - xy - error).T)) < 0.5
    assert np.array_equal(local_shift(xy, mag, seen[:3]), xy)  # too few to say


def test_a_mount_file_is_read_from_the_sky_json_or_alone(tmp_path):
    R = np.eye(3)[[1, 0, 2]] * [[1], [1], [-1]]
    nested = tmp_path / "sky.json"
    nested.write_text(json.dumps({"sky": {"R_cam_from_enu": R.tolist(), "mag_limit": 5.5}}))
    got, limit = read_mount(nested)
    assert np.allclose(got, R) and limit == 5.5
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"R_cam_from_enu": [[1, 2, 3]] * 3}))
    with pytest.raises(StarnavError, match="no R_cam_from_enu"):
        read_mount(bad)


def test_a_site_out_of_range_is_refused():
    with pytest.raises(StarnavError, match="latitude"):
        Site(91.0, 0.0, 0.0, "2020-01-01T00:00:00")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--lat", "10"], "give both --lat and --lon"),
        (["--utc", "2020-01-01T00:00:00"], "--utc needs the site"),
        (["--png", "x.jpg"], "ending in .png"),
        (["--mount", "m.json"], "--mount needs --camera"),
        (["--lat", "1", "--lon", "2", "--utc", "noon"], "not an ISO 8601 time"),
    ],
)
def test_bad_options_exit_2_with_one_line(capsys, extra, message):
    code, _, err = run_cli(capsys, "sky", str(shared_file(KHO)), *extra)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
@pytest.mark.corpus
def test_kho_clear_frame_is_mostly_clear(capsys, tmp_path):
    png = tmp_path / "sky.png"
    code, out, _ = run_cli(
        capsys, "sky", str(shared_file(KHO)), "--lens", "equisolid", "--fov-deg", "180",
        "--max-stars", "100", *KHO_SITE, "--json", "--png", str(png),
    )  # fmt: skip
    assert code == 0 and png.stat().st_size > 100_000
    sky = json.loads(out)["sky"]
    assert sky["state"] == "clear" and sky["clear_fraction"] >= 0.65
    high = [c for c in sky["cells"] if c["alt_min_deg"] >= 30]
    assert sum(c["state"] == "clear" for c in high) >= 0.75 * len(high)
    assert sky["limiting_mag"] >= 6.5  # a Sony a7s, 180° fisheye
    assert np.allclose(np.array(sky["R_cam_from_enu"]) @ np.array(sky["R_cam_from_enu"]).T,
                       np.eye(3), atol=1e-6)  # fmt: skip


def _tudo(name: str) -> Path:
    folder = os.environ.get("STARNAV_TUDO_FRAMES")
    if not folder:
        pytest.skip("STARNAV_TUDO_FRAMES is not set (the folder of the tudo frames)")
    return shared_file(Path(folder) / name)


def _mounted(capsys, tmp_path, name: str, camera: str, utc: str) -> dict:
    spec = json.loads(CAMERAS.read_text())[camera]
    camera_file, mount_file = tmp_path / "camera.json", tmp_path / "mount.json"
    camera_file.write_text(json.dumps(spec["camera"]))
    mount_file.write_text(json.dumps({k: spec[k] for k in ("R_cam_from_enu", "mag_limit")}))
    site = spec["site"]
    code, out, err = run_cli(
        capsys, "sky", str(_tudo(name)), "--camera", str(camera_file), "--mount",
        str(mount_file), "--lat", str(site["lat_deg"]), "--lon", str(site["lon_deg"]),
        "--height-m", str(site["height_m"]), "--utc", utc, "--json",
    )  # fmt: skip
    assert code == 0, err
    return json.loads(out)["sky"]


@pytest.mark.corpus
@pytest.mark.parametrize(
    ("name", "camera", "utc"),
    [
        ("iceact_starry.fits", "iceact", "2017-05-03T03:13:04"),
        ("magic_20180817_0341.fits", "magic", "2018-08-17T03:38:58"),
        ("magic_20180816_2101.fits", "magic", "2018-08-16T20:59:05"),
    ],
)
def test_tudo_clear_frames_are_clear(capsys, tmp_path, name, camera, utc):
    sky = _mounted(capsys, tmp_path, name, camera, utc)
    assert sky["state"] == "clear" and sky["clear_fraction"] >= 0.68
    assert sky["cell_counts"]["clear"] >= 14
    zenith = sky["cells"][-1]
    assert zenith["state"] == "clear"


@pytest.mark.corpus
def test_tudo_overcast_frame_is_cloudy_round_its_thinner_hole(capsys, tmp_path):
    """IceAct, 2017-06-11: lit cloud all round; stars only in a thinner hole about the zenith
    and S of it (the image's left of centre)."""
    sky = _mounted(capsys, tmp_path, "iceact_cloudy.fits", "iceact", "2017-06-11T04:10:03")
    assert sky["clear_fraction"] < 0.5
    counts = sky["cell_counts"]
    assert counts["cloudy"] + counts["partly"] >= 3 * counts["clear"]
    low = [c for c in sky["cells"] if c["alt_max_deg"] <= 30]
    assert sum(c["state"] == "cloudy" for c in low) >= 4
    assert sky["cells"][-1]["state"] != "cloudy"  # the hole
