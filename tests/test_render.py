"""starnav.render: PSF placement in our pixel convention, noise model, saturation, hot pixels,
frames from the catalog (with distortion), presets and writing files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.errors import ImageError, StarnavError
from starnav.geometry import attitude_from_radec_roll
from starnav.render import (
    PRESETS,
    RenderSettings,
    adjust_camera,
    flux_e_for_snr,
    preset,
    render_frame,
    render_stars,
    star_electrons,
    star_snr,
    write_image,
    write_truth_csv,
)
from starnav.simulate import project_catalog


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
