"""simulate.render: PSF placement in our pixel convention, noise model, saturation, hot pixels,
frames from the catalog (with distortion; fisheyes with their image circle and vignetting),
presets, writing files and the CLI."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from starnav.camera import (
    Camera,
    Equidistant,
    Equisolid,
    Orthographic,
    camera_from_dict,
    save_camera,
)
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.detect.read import read_image
from starnav.detect.stars import detect_stars
from starnav.errors import ImageError, StarnavError
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate import project_catalog
from starnav.simulate.render import (
    PRESETS,
    RenderSettings,
    adjust_camera,
    flux_e_for_snr,
    imaged_directions,
    pixel_illumination,
    preset,
    render_frame,
    render_stars,
    star_electrons,
    star_snr,
    write_image,
    write_truth_csv,
)


@pytest.fixture(scope="module")
def hip7():
    return load_catalog(None, mag_limit=7.0)


def _moments(image: np.ndarray) -> tuple[float, float]:
    rows, cols = np.indices(image.shape)
    total = image.sum()
    return float(((cols + 0.5) * image).sum() / total), float(((rows + 0.5) * image).sum() / total)


def test_star_at_pixel_centre_lands_on_that_pixel():
    # x = 10.5, y = 20.5 is the centre of row 20, column 10
    e = star_electrons(np.array([[10.5, 20.5]]), np.array([1000.0]), 40, 40, 1.0)
    assert np.unravel_index(np.argmax(e), e.shape) == (20, 10)
    assert e.sum() == pytest.approx(1000.0, rel=1e-6)
    assert _moments(e) == pytest.approx((10.5, 20.5), abs=1e-9)
    # symmetric about the star: left and right neighbours equal, up and down equal
    assert e[20, 9] == pytest.approx(e[20, 11], rel=1e-12)
    assert e[19, 10] == pytest.approx(e[21, 10], rel=1e-12)


@pytest.mark.parametrize("sigma", [0.6, 1.0, 1.5])
def test_intensity_weighted_centroid_is_the_star_position(sigma):
    xy = np.array([[10.2, 20.9], [30.77, 15.01], [13.5, 33.25]])
    for star in xy:
        e = star_electrons(star[None], np.array([500.0]), 50, 50, sigma)
        assert e.sum() == pytest.approx(500.0, rel=1e-5)  # integrated PSF: all light counted
        # pixel-integrated Gaussian: first moment exact to ~1e-3 px even when undersampled
        assert _moments(e) == pytest.approx(tuple(star), abs=2e-3)


def test_rendered_image_centroid_and_dtype():
    settings = RenderSettings(background_e=0.0, read_noise_e=0.0, seed=1)
    image = render_stars(np.array([[10.5, 20.5]]), np.array([1e5]), 40, 30, settings)
    assert image.dtype == np.uint16 and image.shape == (30, 40)
    assert np.unravel_index(np.argmax(image), image.shape) == (20, 10)
    assert _moments(image.astype(float)) == pytest.approx((10.5, 20.5), abs=0.02)


def test_star_light_cut_by_the_image_edge():
    e = star_electrons(np.array([[0.0, 10.5]]), np.array([1000.0]), 20, 20, 1.0)
    assert e.sum() == pytest.approx(500.0, rel=1e-4)  # half of the star is outside


@pytest.mark.parametrize(("sky", "read"), [(50.0, 5.0), (10.0, 1.0)])  # Gaussian, Poisson sky
def test_background_noise_statistics(sky, read):
    settings = RenderSettings(background_e=sky, read_noise_e=read, gain_e_per_adu=1.0, seed=3)
    image = render_stars(np.zeros((0, 2)), np.zeros(0), 256, 256, settings).astype(float)
    assert image.mean() == pytest.approx(sky, abs=0.1)
    expected_var = sky + read**2 + 1.0 / 12.0
    assert image.var() == pytest.approx(expected_var, rel=0.03)


def test_star_photon_noise_is_poisson():
    # 400 identical stars on a noise-free sky: their summed electrons scatter as Poisson
    grid = (np.arange(20) + 0.5) * 16.0
    xy = np.stack(np.meshgrid(grid, grid), -1).reshape(-1, 2) + 0.25
    flux = 5000.0
    settings = RenderSettings(background_e=0.0, read_noise_e=0.0, seed=4)
    image = render_stars(xy, np.full(len(xy), flux), 320, 320, settings).astype(float)
    sums = image.reshape(20, 16, 20, 16).sum(axis=(1, 3)).ravel()
    assert sums.mean() == pytest.approx(flux, rel=0.01)
    assert sums.var() == pytest.approx(flux, rel=0.25)


def test_gain_and_saturation_clip_at_full_scale():
    settings = RenderSettings(gain_e_per_adu=2.0, background_e=100.0, read_noise_e=0.0, seed=5)
    image = render_stars(np.array([[20.5, 20.5]]), np.array([5e6]), 40, 40, settings)
    assert np.median(image) == pytest.approx(50.0, abs=1.0)  # 100 e at 2 e/ADU
    assert image.max() == 65535
    assert (image == 65535).sum() >= 9  # a flat, clipped top
    eight = render_stars(
        np.array([[20.5, 20.5]]),
        np.array([1e5]),
        40,
        40,
        dataclasses.replace(settings, bit_depth=8),
    )
    assert eight.dtype == np.uint8 and eight.max() == 255


def test_hot_pixels_are_single_bright_pixels(hip7):
    settings = RenderSettings(hot_pixels=25, hot_pixel_adu=20000.0, seed=6)
    camera = Camera.from_fov(10.0, 128, 96)
    frame = render_frame(hip7, camera, attitude_from_radec_roll(84.0, -2.0, 0.0), settings)
    assert frame.hot_xy.shape == (25, 2)
    cols = (frame.hot_xy[:, 0] - 0.5).astype(int)
    rows = (frame.hot_xy[:, 1] - 0.5).astype(int)
    assert (frame.image[rows, cols] > 19000).all()
    padded = np.pad(frame.image.astype(float), 1, mode="edge")
    neighbours = [
        padded[rows + 1 + dr, cols + 1 + dc] for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1))
    ]
    assert (np.max(neighbours, axis=0) < 0.1 * frame.image[rows, cols]).mean() > 0.9


def test_seed_reproducible():
    settings = RenderSettings(seed=7, hot_pixels=3)
    xy, flux = np.array([[5.5, 6.5]]), np.array([1e4])
    a = render_stars(xy, flux, 32, 32, settings)
    b = render_stars(xy, flux, 32, 32, settings)
    c = render_stars(xy, flux, 32, 32, settings, rng=8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_snr_helpers_and_limiting_magnitude():
    settings = RenderSettings()
    flux = flux_e_for_snr(50.0, settings)
    assert star_snr(flux, settings) == pytest.approx(50.0, rel=1e-9)
    # the 1024 px / 20° reference camera sees to about Hp 7
    _, ref = PRESETS["seed-1024"]
    assert 8.0 < star_snr(ref.flux_e(7.0), ref) < 15.0
    assert star_snr(ref.flux_e(8.0), ref) < 6.0


def test_render_frame_truth_matches_projection(hip7):
    camera = Camera(640, 480, 1800.0, 322.0, 236.0, k1=-0.08, k2=0.01)
    R = attitude_from_radec_roll(84.0, -2.0, 30.0)  # Orion: bright stars
    frame = render_frame(hip7, camera, R, RenderSettings(seed=9))
    rows, xy = project_catalog(hip7, R, camera)
    assert len(frame.xy) == len(rows) >= 10
    order = np.argsort(hip7.mag[rows], kind="stable")
    assert np.array_equal(frame.ids, hip7.ids[rows][order])
    assert np.allclose(frame.xy, xy[order])
    assert np.all(np.diff(frame.mag) >= 0)
    assert frame.image.shape == (480, 640)
    # the brightest star's peak sits on the pixel under its true position (incl. distortion)
    x, y = frame.xy[0]
    r, c = int(y), int(x)
    patch = frame.image[r - 1 : r + 2, c - 1 : c + 2]
    assert patch.max() == frame.image[max(r - 4, 0) : r + 5, max(c - 4, 0) : c + 5].max()
    assert frame.flux_e == pytest.approx(frame.settings.flux_e(frame.mag))


def test_truth_dict_and_csv(hip7, tmp_path):
    camera = Camera(640, 480, 1800.0, k1=-0.08)
    frame = render_frame(hip7, camera, attitude_from_radec_roll(84.0, -2.0, 30.0, -1))
    truth = frame.to_dict()
    assert truth["ra_deg"] == pytest.approx(84.0) and truth["roll_deg"] == pytest.approx(30.0)
    assert truth["parity"] == -1 and truth["n_stars"] == len(frame.xy) and truth["k1"] == -0.08
    path = tmp_path / "truth.csv"
    write_truth_csv(path, frame)
    lines = path.read_text().splitlines()
    assert lines[0] == "x,y,catalog_id,mag" and len(lines) == len(frame.xy) + 1
    assert int(lines[1].split(",")[2]) == frame.ids[0]
    with pytest.raises(StarnavError, match="cannot write"):
        write_truth_csv(tmp_path / "no" / "truth.csv", frame)


def test_adjusted_preset_camera():
    camera, _ = preset("seed-1024")
    assert adjust_camera(camera) == camera
    wide = adjust_camera(camera, width=512)
    assert (wide.width, wide.height) == (512, 512) and wide.fov_deg == pytest.approx(camera.fov_deg)
    tall = adjust_camera(camera, height=300, k1=-0.01)
    assert (tall.width, tall.height, tall.k1) == (camera.width, 300, -0.01)
    assert adjust_camera(camera, fov_deg=10.0).fov_deg == pytest.approx(10.0)


def test_frame_without_stars(hip7):
    camera = Camera.from_fov(10.0, 64, 48)
    settings = RenderSettings(mag_limit=-5.0, seed=10)
    frame = render_frame(hip7, camera, np.eye(3), settings)
    assert frame.xy.shape == (0, 2) and len(frame.ids) == 0
    assert frame.image.shape == (48, 64)
    assert abs(float(frame.image.mean()) - 50.0) < 1.0


def test_mag_limit_and_presets(hip7):
    camera, settings = preset("seed-512")
    assert (camera.width, camera.height) == (512, 512)
    assert camera.fov_deg == pytest.approx(12.0)
    assert settings.mag_limit == 6.0
    R = attitude_from_radec_roll(84.0, -2.0, 0.0)
    frame = render_frame(hip7, camera, R, dataclasses.replace(settings, seed=1))
    assert len(frame.mag) > 0 and frame.mag.max() <= 6.0
    camera, settings = PRESETS["seed-1024"]
    assert camera.fov_deg == pytest.approx(20.0) and camera.width == 1024
    with pytest.raises(StarnavError, match="unknown render preset 'seed-9'"):
        preset("seed-9")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"psf_sigma_px": 0.0}, "psf_sigma_px"),
        ({"exposure_s": -1.0}, "exposure_s"),
        ({"bit_depth": 12}, "bit_depth"),
        ({"hot_pixels": -1}, "hot_pixels"),
        ({"read_noise_e": float("nan")}, "read_noise_e"),
        ({"gain_e_per_adu": "2"}, "gain_e_per_adu"),
        ({"seed": 1.5}, "seed"),
    ],
)
def test_settings_validated(kwargs, match):
    with pytest.raises(StarnavError, match=match):
        RenderSettings(**kwargs)


def test_render_stars_validates_input():
    with pytest.raises(StarnavError, match="2 star positions but 1 fluxes"):
        render_stars(np.zeros((2, 2)), np.ones(1), 10, 10, RenderSettings())
    with pytest.raises(StarnavError, match="finite"):
        render_stars(np.array([[np.nan, 1.0]]), np.ones(1), 10, 10, RenderSettings())


def test_write_image_rejects_bad_input(tmp_path):
    image = np.zeros((4, 5), np.uint16)
    with pytest.raises(ImageError, match=r"unknown suffix '\.bmp'"):
        write_image(tmp_path / "a.bmp", image)
    with pytest.raises(ImageError, match="2-D"):
        write_image(tmp_path / "a.png", np.zeros((4, 5, 3), np.uint8))
    with pytest.raises(ImageError, match="dtype float64"):
        write_image(tmp_path / "a.png", image.astype(float))
    with pytest.raises(ImageError, match="cannot write"):
        write_image(tmp_path / "missing-folder" / "a.png", image)


# ----------------------------------------------------------------------------------------------
# fisheyes: stars where the lens projects them, black outside the image circle, vignetting


def _allsky() -> Equidistant:
    return Equidistant.from_fov(185.0, 512, 512).with_circle(185.0)


def _radius_px(camera) -> np.ndarray:
    cols, rows = np.meshgrid(np.arange(camera.width) + 0.5, np.arange(camera.height) + 0.5)
    return np.hypot(cols - camera.cx, rows - camera.cy)


@pytest.fixture(scope="module")
def allsky_frame(hip7):
    settings = RenderSettings(psf_sigma_px=1.2, background_e=100.0, mag_limit=6.0, seed=11)
    return render_frame(hip7, _allsky(), attitude_from_radec_roll(84.0, -2.0, 30.0), settings)


def test_fisheye_stars_land_where_the_lens_projects_them(allsky_frame, hip7):
    frame, camera = allsky_frame, allsky_frame.camera
    c = hip7.vectors[hip7.rows(frame.ids)] @ frame.R_cam_from_icrs.T
    assert np.allclose(frame.xy, camera.bearings_to_pixels(c))
    assert len(frame.xy) > 1000 and (c[:, 2] >= np.cos(np.radians(92.5)) - 1e-12).all()
    assert c[:, 2].min() < 0.0  # stars behind the image plane are drawn too
    found = detect_stars(frame.image, max_stars=100)
    tree = cKDTree(frame.xy)
    dist, nearest = tree.query(found.xy)
    # 0.36° pixels: a third of the stars have a neighbour within 5 px, whose light moves the
    # centroid; the isolated ones are found where they were drawn
    isolated = (tree.query(frame.xy, k=2)[0][:, 1] > 5.0)[nearest]
    assert isolated.sum() >= 20 and dist[isolated].max() < 0.3 and np.median(dist) < 0.1
    assert dist.max() < 3.0  # no detection away from a star (none at the circle's edge)
    # the detections are the bright stars, across the whole disc
    assert np.median(frame.mag[nearest]) < 4.0
    assert np.hypot(*(found.xy - (camera.cx, camera.cy)).T).max() > 0.85 * 256


def test_fisheye_is_black_outside_its_image_circle(allsky_frame):
    frame, camera = allsky_frame, allsky_frame.camera
    r = _radius_px(camera)
    outside = frame.image[r > 257.0].astype(float)
    # read noise only (5 e rms, clipped at 0): no sky, no star light
    assert outside.mean() < 3.0 and outside.max() < 35
    assert np.median(frame.image[r < 50.0]) > 95.0  # the sky (100 e) and faint stars
    lit = pixel_illumination(camera, 0.0)
    assert (lit[r > 256.01] == 0).all() and (lit[r < 255.99] == 1).all()
    assert not lit.flags.writeable


def test_vignetting_scales_sky_and_stars(hip7):
    camera = _allsky()
    R = attitude_from_radec_roll(84.0, -2.0, 30.0)
    settings = RenderSettings(background_e=400.0, read_noise_e=1.0, mag_limit=4.0, seed=12)
    assert settings.vignetting_power_for(camera) == 2.0  # a fisheye's default
    assert settings.vignetting_power_for(Camera.from_fov(10.0, 64)) == 0.0
    frame = render_frame(hip7, camera, R, settings)
    flat = render_frame(hip7, camera, R, dataclasses.replace(settings, vignetting_power=0.0))
    r = _radius_px(camera)
    edge = (r > 240.0) & (r < 250.0)  # θ ≈ 88°: cos²(44°) = 0.52
    theta = r[edge] / camera.focal_px
    expected = 400.0 * np.cos(0.5 * theta) ** 2
    assert np.median(frame.image[edge]) == pytest.approx(np.median(expected), rel=0.02)
    assert np.median(flat.image[edge]) == pytest.approx(400.0, rel=0.02)
    c = hip7.vectors[hip7.rows(frame.ids)] @ R.T
    assert frame.flux_e == pytest.approx(settings.flux_e(frame.mag) * (0.5 * (1 + c[:, 2])))
    assert frame.to_dict()["vignetting_power"] == 2.0


def test_a_lens_that_stops_inside_the_image_leaves_the_rest_black(hip7):
    camera = Orthographic(400, 300, 120.0)  # r = f sin θ reaches 120 px at 90°
    frame = render_frame(
        hip7, camera, attitude_from_radec_roll(84.0, -2.0, 0.0), RenderSettings(seed=13)
    )
    r = _radius_px(camera)
    assert frame.image[r > 121.0].mean() < 3.0
    assert np.hypot(*(frame.xy - (200.0, 150.0)).T).max() <= 120.0
    lit = pixel_illumination(camera, 0.0)
    assert (lit[r > 120.01] == 0).all() and (lit[r < 119.99] == 1).all()
    # directions past 90° would fold back inside: the lens images none of them
    past = np.array([[np.sin(np.radians(91.0)), 0.0, np.cos(np.radians(91.0))]])
    assert not imaged_directions(camera, past)[0]


def test_cli_render_with_a_camera_file(tmp_path, capsys, hip7):
    camera_path, png, truth_csv = tmp_path / "cam.json", tmp_path / "sky.png", tmp_path / "t.csv"
    save_camera(camera_path, Equisolid.from_fov(185.0, 400, 400).with_circle(185.0))
    args = ["render", "-o", str(png), "--camera", str(camera_path), "--truth", str(truth_csv)]
    view = ["--ra-deg", "84", "--dec-deg", "-2", "--roll-deg", "30", "--mag-limit", "5"]
    assert main([*args, *view, "--seed", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["camera_model"] == "equisolid" and out["camera"]["image_circle_deg"] == 185.0
    assert (out["width"], out["height"]) == (400, 400) and out["vignetting_power"] == 2.0
    camera = camera_from_dict(out["camera"])
    with truth_csv.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == out["n_stars"] > 300
    xy = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    ids = np.array([int(r["catalog_id"]) for r in rows])
    c = hip7.vectors[hip7.rows(ids)] @ np.array(out["R_cam_from_icrs"]).T
    assert np.allclose(xy, camera.bearings_to_pixels(c), atol=1e-3)
    image = read_image(png)
    assert image.shape == (400, 400) and image[0, 0] < 30  # a corner: outside the circle
    assert main([*args, "--fov-deg", "20"]) == 2
    err = capsys.readouterr().err.strip()
    assert "drop --fov-deg" in err and "\n" not in err
