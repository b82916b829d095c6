"""Celestial fix from image files: rendered images of the locate simulator's cameras (exact star
positions, pixel-integrated Gaussian PSF, sky, photon and read noise) must fix the site within
60 m and the heading within 3″; the UTC comes from FITS DATE-OBS or EXIF DateTimeOriginal when
the file has none; bad input is one line and exit 2."""

import json
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits
from PIL import Image

from shared_data import ROOT
from starnav.camera import Camera, save_camera
from starnav.cli import main
from starnav.navigation import ObservationError, locate, parse_observation, read_observation
from starnav.navigation.frames import radii_of_curvature_m
from starnav.navigation.simulate import render_views, simulate_observation
from starnav.simulate.render import RenderSettings, write_image

SITE = {"lat_deg": 47.37, "lon_deg": 8.54}
UTC = "2025-06-01T22:00:00Z"
HEADING_DEG = 30.0
EXIF_IFD, DATE_TIME_ORIGINAL, SUBSEC_TIME_ORIGINAL = 0x8769, 36867, 37521


def _sky(width, heading_deg=HEADING_DEG, pitch_deg=1.0, mounts=None):
    options = {} if mounts is None else {"mounts": mounts}
    return simulate_observation(
        **SITE, utc=UTC, heading_deg=heading_deg, pitch_deg=pitch_deg, width=width, **options
    )


def _errors(fix, heading_deg):
    """Position error (m) and heading error (arcsec) against the simulated truth."""
    m_north, m_east = radii_of_curvature_m(SITE["lat_deg"])
    north = np.radians(fix.lat_deg - SITE["lat_deg"]) * m_north
    east = np.radians(fix.lon_deg - SITE["lon_deg"]) * m_east * np.cos(np.radians(SITE["lat_deg"]))
    heading = ((fix.azimuth_deg - heading_deg + 180.0) % 360.0 - 180.0) * 3600.0
    return float(np.hypot(north, east)), float(heading)


def _write_obs(folder: Path, sky, files, *, utc=UTC, lens=None, **top) -> Path:
    """An observation file whose cameras give the images ``files`` (names in ``folder``) and
    the simulated mounts; ``lens``: the keys giving each camera's lens (default its FOV)."""
    cameras = []
    for view, name in zip(sky.observation.cameras, files, strict=True):
        entry = {"name": view.name, "R_cam_from_body": view.R_cam_from_body.tolist()}
        entry.update({"fov_deg": view.fov_deg} if lens is None else lens)
        cameras.append({**entry, "image": name})
    data = {
        "gravity_body": sky.observation.gravity_body.tolist(),
        "pressure_hpa": sky.observation.pressure_hpa,  # 0: the simulation has no refraction
        "cameras": cameras,
        **top,
    }
    if utc is not None:
        data["utc"] = utc
    path = folder / "obs.json"
    path.write_text(json.dumps(data))
    return path


@pytest.fixture(scope="module")
def three_1024(tmp_path_factory):
    """Three 20° cameras, 1024 px (the reference set-up), rendered to 16-bit PNGs."""
    folder = tmp_path_factory.mktemp("three")
    sky = _sky(1024)
    files = []
    for k, image in enumerate(render_views(sky, RenderSettings(), seed=10)):
        write_image(folder / f"cam{k + 1}.png", image)
        files.append(f"cam{k + 1}.png")
    return folder, sky, files


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The same cameras at 512 px: quick images for the time and error cases."""
    folder = tmp_path_factory.mktemp("small")
    sky = _sky(512)
    return folder, sky, render_views(sky, RenderSettings(), seed=20)


def test_three_20_degree_cameras_from_images_within_60_m_and_3_arcsec(three_1024, capsys):
    folder, sky, files = three_1024
    path = _write_obs(folder, sky, files)
    observation = read_observation(path)
    assert [len(v.xy) for v in observation.cameras] == [50, 50, 50]  # solve IMAGE's 50 brightest
    fix = locate(observation, sigma_px=0.1)
    position_m, heading_arcsec = _errors(fix, HEADING_DEG)
    print(f"three 20° cameras, 1024 px images: {position_m:.1f} m, {heading_arcsec:+.2f}″")
    assert position_m < 60.0
    assert abs(heading_arcsec) < 3.0
    assert all(c.stars_used >= 15 for c in fix.cameras)
    # the same through the CLI
    capsys.readouterr()
    assert main(["locate", str(path), "--json", "--sigma-px", "0.1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["lat_deg"] == pytest.approx(fix.lat_deg, abs=1e-12)
    assert out["utc"] == UTC and out["utc_source"] == "file"


def test_the_images_centroids_are_the_camera_star_list(three_1024):
    """An image entry and a stars entry holding its detected centroids give the same fix."""
    folder, sky, files = three_1024
    from_images = read_observation(_write_obs(folder, sky, files))
    data = json.loads((folder / "obs.json").read_text())
    for entry, view in zip(data["cameras"], from_images.cameras, strict=True):
        del entry["image"]
        entry.update(stars=view.xy.tolist(), width=1024, height=1024)
    from_stars = parse_observation(data)
    a, b = locate(from_images, sigma_px=0.1), locate(from_stars, sigma_px=0.1)
    assert (a.lat_deg, a.lon_deg, a.azimuth_deg) == (b.lat_deg, b.lon_deg, b.azimuth_deg)


def test_camera_file_and_inline_camera(three_1024, tmp_path):
    folder, sky, files = three_1024
    camera = Camera.from_fov(20.0, 1024, 1024)
    save_camera(folder / "lens.json", camera)
    by_fov = locate(read_observation(_write_obs(folder, sky, files)), sigma_px=0.1)
    by_file = locate(
        read_observation(_write_obs(folder, sky, files, lens={"camera": "lens.json"})),
        sigma_px=0.1,
    )
    inline = locate(
        read_observation(_write_obs(folder, sky, files, lens={"camera": camera.to_dict()})),
        sigma_px=0.1,
    )
    for fix in (by_file, inline):
        assert fix.lat_deg == pytest.approx(by_fov.lat_deg, abs=1e-9)
        assert fix.azimuth_deg == pytest.approx(by_fov.azimuth_deg, abs=1e-9)
        assert fix.cameras[0].focal_px == pytest.approx(camera.focal_px)
    # a star list with a camera takes its size from the camera, and must agree with a given one
    data = json.loads((folder / "obs.json").read_text())  # the inline camera's
    views = read_observation(folder / "obs.json").cameras
    for entry, view in zip(data["cameras"], views, strict=True):
        entry["stars"] = view.xy.tolist()
        del entry["image"]
    observation = parse_observation(data)
    assert [(v.width, v.height) for v in observation.cameras] == [(1024, 1024)] * 3
    assert locate(observation, sigma_px=0.1).lat_deg == pytest.approx(by_fov.lat_deg, abs=1e-9)
    data["cameras"][0]["width"] = 512
    with pytest.raises(ObservationError, match="width 512 px, but the camera's is 1024 px"):
        parse_observation(data)


@pytest.mark.slow
def test_fov_searched_when_not_given(three_1024):
    """No camera and no fov_deg: the FOV search finds the focal length, and the bearings use
    it."""
    folder, sky, files = three_1024
    fix = locate(read_observation(_write_obs(folder, sky, files, lens={})), sigma_px=0.1)
    truth = Camera.from_fov(20.0, 1024).focal_px
    for camera in fix.cameras:
        assert camera.stars_used >= 10
        assert camera.focal_px == pytest.approx(truth, rel=2e-3)
    position_m, heading_arcsec = _errors(fix, HEADING_DEG)
    assert position_m < 150.0 and abs(heading_arcsec) < 6.0


def test_fits_date_obs_gives_the_utc(small, tmp_path, capsys):
    _, sky, images = small
    stamps = ["2025-06-01T22:00:00.2", None, ("2025-06-01", "21:59:59.8")]
    files = []
    for k, (image, stamp) in enumerate(zip(images, stamps, strict=True)):
        header = fits.Header()
        if isinstance(stamp, str):
            header["DATE-OBS"] = stamp
        elif stamp is not None:
            header["DATE-OBS"], header["TIME-OBS"] = stamp
        fits.PrimaryHDU(image, header=header).writeto(tmp_path / f"cam{k}.fits")
        files.append(f"cam{k}.fits")
    path = _write_obs(tmp_path, sky, files, utc=None)
    observation = read_observation(path)
    assert observation.utc == "2025-06-01T22:00:00.000Z"  # the mean of the two times
    assert "camera 1: FITS DATE-OBS" in observation.utc_source
    assert "camera 3: FITS DATE-OBS + TIME-OBS" in observation.utc_source
    assert "camera 2" not in observation.utc_source
    assert main(["locate", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["utc"] == observation.utc and out["utc_source"].startswith("images")
    position_m, _ = _errors(locate(observation), HEADING_DEG)
    assert position_m < 200.0
    # a TT DATE-OBS is turned into UTC (TT - UTC = 69.184 s in 2025)
    with fits.open(tmp_path / "cam0.fits", mode="update") as hdul:
        hdul[0].header["DATE-OBS"] = "2025-06-01T22:01:09.184"
        hdul[0].header["TIMESYS"] = "TT"
    data = json.loads(path.read_text())
    data["cameras"] = data["cameras"][:1]
    observation = parse_observation(data, tmp_path)
    assert observation.utc == "2025-06-01T22:00:00.000Z"
    assert "(TT)" in observation.utc_source


def _jpeg(path, image, stamp, subsec=None):
    exif = Image.Exif()
    exif.get_ifd(EXIF_IFD)[DATE_TIME_ORIGINAL] = stamp
    if subsec is not None:
        exif.get_ifd(EXIF_IFD)[SUBSEC_TIME_ORIGINAL] = subsec
    scaled = np.clip(image.astype(float) / 16.0, 0, 255).astype(np.uint8)
    Image.fromarray(scaled).save(path, quality=95, exif=exif)


def test_exif_date_time_original_with_utc_offset(small, tmp_path):
    """EXIF time is local: 2025:06:02 00:00:00.25 at UTC+2 is 2025-06-01T22:00:00.25Z."""
    _, sky, images = small
    files = []
    for k, image in enumerate(images):
        _jpeg(tmp_path / f"cam{k}.jpg", image, "2025:06:02 00:00:00", subsec="25")
        files.append(f"cam{k}.jpg")
    path = _write_obs(tmp_path, sky, files, utc=None, utc_offset_hours=2)
    observation = read_observation(path)
    assert observation.utc == "2025-06-01T22:00:00.250Z"
    assert "EXIF DateTimeOriginal" in observation.utc_source
    assert [len(v.xy) for v in observation.cameras] == [50, 50, 50]
    # the camera's own offset wins over the top level's
    data = json.loads(path.read_text())
    for entry in data["cameras"]:
        entry["utc_offset_hours"] = 1.5
    assert parse_observation(data, tmp_path).utc == "2025-06-01T22:30:00.250Z"
    fix = locate(observation)
    assert sum(c.stars_used for c in fix.cameras) >= 30


def _bad(tmp_path, sky, images, **changes):
    """An observation file of one 512 px camera (image cam.png) with ``changes`` to its camera
    entry (a value None deletes the key) and to the top level (key ``top``)."""
    write_image(tmp_path / "cam.png", images[0])
    view = sky.observation.cameras[0]
    entry = {"azimuth_deg": 0, "elevation_deg": 45, "fov_deg": 20, "image": "cam.png"}
    top = changes.pop("top", {})
    entry.update(changes)
    entry = {k: v for k, v in entry.items() if v is not None}
    data = {
        "utc": UTC,
        "gravity_body": view.R_cam_from_body[2].tolist(),
        "pressure_hpa": 0,
        "cameras": [entry],
    }
    data.update(top)
    data = {k: v for k, v in data.items() if v is not None}
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "changes,needle",
    [
        ({"image": "missing.png"}, "missing.png' does not exist"),
        ({"image": "notes.png"}, "cannot read image file"),
        ({"image": None}, "'stars' (a list of [x, y] centroids) or 'image' (a file) is missing"),
        ({"stars": [[1, 2], [3, 4], [5, 6]]}, "give either 'stars' or 'image', not both"),
        ({"image": 7}, "'image' must be a file path"),
        ({"width": 1024}, "width 1024 px, but the image cam.png is 512 px"),
        ({"camera": "lens.json", "fov_deg": None}, "camera is for 1024 x 1024 px images"),
        ({"camera": "lens.json"}, "give either 'camera' or 'fov_deg', not both"),
        ({"camera": "nowhere.json", "fov_deg": None}, "nowhere.json does not exist"),
        ({"camera": {"model": "pinhole"}, "fov_deg": None}, "its camera lacks width"),
        ({"top": {"utc": None}}, "no image records its time"),
        ({"top": {"utc_offset_hours": 30}}, "utc_offset_hours must be between -14 and 14"),
    ],
)
def test_bad_image_entries_are_one_line_exit_2(small, tmp_path, capsys, changes, needle):
    _, sky, images = small
    (tmp_path / "notes.png").write_text("not an image")
    save_camera(tmp_path / "lens.json", Camera.from_fov(20.0, 1024))
    path = _bad(tmp_path, sky, images, **changes)
    with pytest.raises(ObservationError, match=r"^camera 1: |^'utc'|^utc_offset") as caught:
        read_observation(path)
    assert needle in str(caught.value)
    assert main(["locate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err and "Traceback" not in err


def test_image_times_that_disagree_or_lack_an_offset(small, tmp_path, capsys):
    _, sky, images = small
    header = fits.Header({"DATE-OBS": "2025-06-01T22:00:00"})
    fits.PrimaryHDU(images[0], header=header).writeto(tmp_path / "a.fits")
    header["DATE-OBS"] = "2025-06-01T22:00:01.5"
    fits.PrimaryHDU(images[1], header=header).writeto(tmp_path / "b.fits")
    _jpeg(tmp_path / "c.jpg", images[2], "2025:06:02 00:00:00")
    path = _write_obs(tmp_path, sky, ["a.fits", "b.fits", "c.jpg"], utc=None, utc_offset_hours=2)
    with pytest.raises(ObservationError, match=r"the images' times differ by 1\.5 s"):
        read_observation(path)
    assert main(["locate", str(path)]) == 2
    assert "differ by 1.5 s" in capsys.readouterr().err
    # agreeing times, but the JPEG's local time cannot be placed without an offset
    path = _write_obs(tmp_path, sky, ["a.fits", "a.fits", "c.jpg"], utc=None)
    with pytest.raises(ObservationError, match=r"camera 3: .*local time: give 'utc_offset_hours'"):
        read_observation(path)
    assert main(["locate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "utc_offset_hours" in err and "\n" not in err
    # a date without a time
    fits.PrimaryHDU(images[0], header=fits.Header({"DATE-OBS": "2025-06-01"})).writeto(
        tmp_path / "d.fits"
    )
    path = _write_obs(tmp_path, sky, ["d.fits", "a.fits", "a.fits"], utc=None)
    with pytest.raises(ObservationError, match="date without a time and there is no TIME-OBS"):
        read_observation(path)
    # the file's utc is used as it is, whatever the images say
    path = _write_obs(tmp_path, sky, ["a.fits", "b.fits", "c.jpg"], utc="2025-06-01T22:00:00Z")
    assert read_observation(path).utc_source == "file"


@pytest.mark.slow
def test_the_committed_example(capsys):
    """docs/examples/locate_images (made by its make_images.py) works from the CLI, from any
    working directory: its utc from the FITS and JPEG headers, one camera's FOV searched."""
    folder = ROOT / "docs" / "examples" / "locate_images"
    truth = json.loads((folder / "truth.json").read_text())
    assert main(["locate", str(folder / "obs.json"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["utc"] == "2025-06-01T22:00:00.000Z"
    assert "fore: FITS DATE-OBS" in out["utc_source"]
    assert "right: EXIF DateTimeOriginal" in out["utc_source"]
    assert all(c["stars_used"] >= 10 for c in out["cameras"])
    m_north, m_east = radii_of_curvature_m(truth["lat_deg"])
    north = np.radians(out["lat_deg"] - truth["lat_deg"]) * m_north
    east = np.radians(out["lon_deg"] - truth["lon_deg"]) * m_east * np.cos(np.radians(47.37))
    assert np.hypot(north, east) < 200.0
    assert abs(out["azimuth_deg"] - truth["azimuth_deg"]) * 3600 < 10.0
