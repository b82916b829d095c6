"""Many image files in one process (starnav.pipeline.image_batch, ``starnav solve A B DIR/``), image
sequences tracked, FITS hints in and FITS with the WCS out, pictures of unsolved images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits
from astropy.wcs import WCS

from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.detect.header import fits_hints
from starnav.errors import StarnavError
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import solve_image
from starnav.pipeline.image_batch import ImageOutputs, image_paths, solve_files, summarize
from starnav.simulate.render import RenderSettings, render_frame, write_image

CAMERA = Camera.from_fov(12.0, 640, 480)
# a slow pan: 0.3° between frames, the prior of each frame good to 1° (tracking's default)
PAN = [(83.0 + 0.3 * k, -5.0, 30.0 + 0.1 * k) for k in range(5)]


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    """Five PNG frames of a pan across Orion, with their true attitudes."""
    sky = load_catalog(None, mag_limit=7.0)
    folder = tmp_path_factory.mktemp("pan")
    truth = []
    for k, (ra, dec, roll) in enumerate(PAN):
        R = attitude_from_radec_roll(ra, dec, roll, 1)
        frame = render_frame(sky, CAMERA, R, RenderSettings(seed=10 + k))
        write_image(folder / f"frame{k:02d}.png", frame.image)
        truth.append(R)
    return folder, truth


def _check(solution, R_true) -> None:
    bore, roll = attitude_difference_deg(solution.R_cam_from_icrs, R_true)
    assert bore * 3600 < 10 and roll < 0.02


def test_image_paths_expand_directories_in_order(sequence, tmp_path):
    folder, _ = sequence
    (tmp_path / "notes.txt").write_text("not an image")
    paths = image_paths([folder, tmp_path / "missing.jpg"])
    assert [p.name for p in paths] == [f"frame{k:02d}.png" for k in range(5)] + ["missing.jpg"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(StarnavError, match="no image files"):
        image_paths([empty])


@pytest.mark.parametrize("workers", [1, 2])
def test_a_batch_solves_every_file_and_records_the_failures(sequence, tmp_path, workers):
    folder, truth = sequence
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"not a png")
    paths = [*image_paths([folder]), broken, tmp_path / "missing.png"]
    results = solve_files(paths, {}, workers=workers)
    assert len(results) == 7
    for r, R in zip(results[:5], truth, strict=True):
        assert r.solution is not None, r.record["reason"]
        _check(r.solution, R)
        assert r.record["file"].endswith(".png") and r.record["solved"]
    for r in results[5:]:
        assert r.bad_input and r.record["reason"].startswith("error: ")
    summary = summarize(results, 1.0)
    assert (summary.files, summary.solved, summary.errors, summary.unsolved) == (7, 5, 2, 0)
    assert summary.solve_ms is not None and summary.file_ms >= summary.solve_ms


def test_a_tracked_sequence_uses_each_answer_as_the_next_prior(sequence):
    folder, truth = sequence
    results = solve_files(image_paths([folder]), {}, workers=1, track=True)
    assert [r.record["tracked"] for r in results] == [False, True, True, True, True]
    assert results[0].record["algorithm"] == "fov-search"
    assert all(r.record["algorithm"] == "tracking" for r in results[1:])
    for r, R in zip(results, truth, strict=True):
        _check(r.solution, R)


def test_cli_batch_jsonl_outputs_and_summary(sequence, tmp_path, capsys):
    folder, _ = sequence
    out = tmp_path / "out.jsonl"
    code = main(["solve", str(folder), str(tmp_path / "missing.png"), "--jsonl", str(out),
                 "--wcs", str(tmp_path / "wcs"), "--workers", "2"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 2  # a file that does not exist is bad input; the batch went on
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == 6 and sum(r["solved"] for r in lines) == 5
    assert lines[-1]["reason"].startswith("error: image file")
    assert "5 solved" in captured.err and "per file after it" in captured.err
    assert len(captured.out.splitlines()) == 6
    for k in range(5):
        header = fits.getheader(tmp_path / "wcs" / f"frame{k:02d}.wcs")
        assert header["CTYPE1"].startswith("RA---TAN")


def test_fits_hints_are_read_and_used(tmp_path):
    sky = load_catalog(None, mag_limit=7.0)
    R = attitude_from_radec_roll(*PAN[0], 1)
    frame = render_frame(sky, CAMERA, R, RenderSettings(seed=3))
    header = fits.Header()
    header["OBJCTRA"] = "05 32 00"
    header["OBJCTDEC"] = "-05 00 00"
    header["FOCALLEN"] = 50.0  # mm, with 16.42 um pixels: 67.7 arcsec per px
    header["XPIXSZ"] = 16.42
    header["DATE-OBS"] = "2026-01-15T22:00:00"
    path = tmp_path / "hinted.fits"
    fits.PrimaryHDU(frame.image.astype(np.float32), header).writeto(path)
    hints = fits_hints(path)
    assert hints.ra_deg == pytest.approx(83.0) and hints.dec_deg == pytest.approx(-5.0)
    assert hints.fov_deg == pytest.approx(12.0, rel=2e-3)
    assert hints.epoch_year == pytest.approx(2026.04, abs=0.01)
    assert hints.sources == ("OBJCTRA/OBJCTDEC", "FOCALLEN/XPIXSZ", "FITS DATE-OBS")
    res = solve_image(path)
    assert res.solution is not None, res.reason
    _check(res.solution, R)
    assert res.to_dict()["hints"]["sources"] == list(hints.sources)
    assert res.solution.fov_deg == pytest.approx(12.0, rel=1e-3)


@pytest.mark.slow
def test_a_wrong_fov_hint_costs_time_not_the_answer(tmp_path):
    sky = load_catalog(None, mag_limit=7.0)
    R = attitude_from_radec_roll(*PAN[1], 1)
    frame = render_frame(sky, CAMERA, R, RenderSettings(seed=4))
    header = fits.Header()
    header["PIXSCALE"] = 150.0  # arcsec per px: a 27° field, twice the true one
    header["RA"], header["DEC"] = 200.0, 40.0  # far from the truth
    path = tmp_path / "wrong.fits"
    fits.PrimaryHDU(frame.image.astype(np.float32), header).writeto(path)
    res = solve_image(path)
    assert res.solution is not None, res.reason
    _check(res.solution, R)


def test_new_fits_keeps_the_data_and_header_and_adds_the_wcs(tmp_path, capsys):
    sky = load_catalog(None, mag_limit=7.0)
    R = attitude_from_radec_roll(*PAN[2], 1)
    frame = render_frame(sky, CAMERA, R, RenderSettings(seed=5))
    data = frame.image.astype(np.int16)  # signed 16 bit: FITS BZERO-free integers
    header = fits.Header()
    header["EXPTIME"] = 2.5
    header["OBJECT"] = "Orion"
    src = tmp_path / "in.fits"
    fits.PrimaryHDU(data, header).writeto(src)
    new = tmp_path / "out.new.fits"
    assert main(["solve", str(src), "--new-fits", str(new), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    with fits.open(new) as hdul:
        np.testing.assert_array_equal(hdul[0].data, data)
        h = hdul[0].header
        assert h["EXPTIME"] == 2.5 and h["OBJECT"] == "Orion"
        wcs = WCS(h)
    # the WCS puts the boresight (our image centre, 0-based astropy (W-1)/2, (H-1)/2 +0.5)
    # where the solve does, within 3 of the solve's own sigmas: the WCS is fitted on the Gaia
    # stars the detections hold (output.tweak), the printed boresight on the matched stars
    # (here the WCS's centre is 0.8" from the truth, the printed one 10.6")
    from astropy.coordinates import SkyCoord

    sky_centre = wcs.pixel_to_world(CAMERA.cx - 0.5, CAMERA.cy - 0.5)
    printed = SkyCoord(out["ra_deg"], out["dec_deg"], unit="deg")
    assert sky_centre.separation(printed).arcsec < 3.0 * out["sigma_boresight_arcsec"]


def test_an_unsolved_image_is_annotated_with_its_reason(tmp_path, capsys):
    from PIL import Image

    rng = np.random.default_rng(0)
    pixels = rng.normal(100.0, 3.0, (480, 640)).astype(np.float32)
    for x, y in rng.uniform(20, 460, (30, 2)):  # thirty "stars" that are no constellation
        yy, xx = np.mgrid[0:480, 0:640]
        pixels += 200.0 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / 2.0)
    src = tmp_path / "noise.fits"
    fits.PrimaryHDU(pixels).writeto(src)
    png = tmp_path / "why.png"
    code = main(["solve", str(src), "--annotate", str(png), "--time-budget", "0.5"])
    assert code == 1
    assert capsys.readouterr().out.startswith("not solved: ")
    with Image.open(png) as img:
        assert img.size[0] >= 1024  # drawn, at the annotation's size


def test_batch_outputs_must_be_directories(sequence, tmp_path, capsys):
    folder, _ = sequence
    (tmp_path / "file.png").write_text("x")
    code = main(["solve", str(folder), "--annotate", str(tmp_path / "file.png")])
    err = capsys.readouterr().err
    assert code == 2 and "directory" in err and err.count("\n") == 1


def test_outputs_of_a_batch_are_named_per_file():
    out = ImageOutputs(wcs_dir=Path("w"), new_fits_dir=None, annotate_dir=Path("p"))
    assert out.paths(Path("a/b/m31.fits.gz")) == {
        "wcs": Path("w/m31.wcs"),
        "new_fits": None,
        "annotate": Path("p/m31.png"),
    }


@pytest.mark.slow
def test_a_batch_on_a_local_dask_cluster_tracks_in_runs(sequence):
    pytest.importorskip("distributed")
    folder, truth = sequence
    results = solve_files(image_paths([folder]), {}, workers=2, dask_address="local", track=True)
    assert [r.record["file"] for r in results] == [str(p) for p in image_paths([folder])]
    for r, R in zip(results, truth, strict=True):
        _check(r.solution, R)
    # two runs, one per worker, each tracked after its first frame
    assert [r.record["tracked"] for r in results] == [False, True, True, False, True]


def test_a_batch_reads_each_files_hints_unless_told_not_to(tmp_path):
    from starnav.detect.header import ImageHints
    from starnav.pipeline.image_batch import solve_file

    sky = load_catalog(None, mag_limit=7.0)
    frame = render_frame(sky, CAMERA, attitude_from_radec_roll(*PAN[3], 1), RenderSettings(seed=6))
    header = fits.Header()
    header["RA"], header["DEC"] = 84.0, -5.0
    path = tmp_path / "hinted.fits"
    fits.PrimaryHDU(frame.image.astype(np.float32), header).writeto(path)
    read = solve_file(path, {}, ImageOutputs())
    assert read.record["hints"]["sources"] == ["RA/DEC"]
    ignored = solve_file(path, {"hints": ImageHints()}, ImageOutputs())
    assert ignored.record["hints"] is None
    assert read.solution is not None and ignored.solution is not None
