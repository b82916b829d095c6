"""The size limits of ``read_image``, checked from each format's header before its pixels
exist: small files claiming huge images are refused in a moment with one line naming the size
and the limit, in a process whose memory stays small; images within the limits still read."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from bomb_files import (
    compressed_fits,
    gzip_fits,
    jpeg_claiming,
    png_claiming,
    tiff_claiming,
    zero_png16,
)
from cli_helpers import run_cli
from starnav.detect.read import MAX_BYTES_PER_PIXEL, MAX_PIXELS, read_image
from starnav.errors import ImageError

PEAK_MB = 400  # a refused read stays far below the gigabytes it claims (the process's peak)


def refused(path, **kw) -> str:
    with pytest.raises(ImageError) as err:
        read_image(path, **kw)
    text = str(err.value)
    assert "\n" not in text and str(path) in text
    return text


def peak_rss_mb(path) -> tuple[float, str]:
    """read_image(path) in a new process: its peak RSS (MB, VmHWM: a ``wait4`` maximum would
    start from the forking test process's) and what it printed."""
    if not os.path.exists("/proc/self/status"):
        pytest.skip("the peak RSS is read from Linux's /proc")
    code = (
        "import sys\nfrom starnav.detect.read import read_image\n"
        "try:\n    read_image(sys.argv[1])\nexcept Exception as exc:\n    print(exc)\n"
        "hwm = [x for x in open('/proc/self/status') if x.startswith('VmHWM')][0]\n"
        "print(int(hwm.split()[1]) / 1e3)\n"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                         text=True, env=os.environ, check=True).stdout  # fmt: skip
    message, peak = out.strip().rsplit("\n", 1)
    return float(peak), message


def test_the_attack_gzip_fits_is_refused_from_its_header(tmp_path):
    # the issue's: 14000 x 14000 float64 behind ~1.5 MB of gzip (1.57 GB decoded; the worker
    # peaked at 12.3 GB for 71 s): 196 MP is within the pixel limit, 8 bytes a pixel is not
    path = gzip_fits(tmp_path / "bomb.fits.gz", (14000, 14000), -64)
    assert path.stat().st_size < 3e6
    text = refused(path)
    assert "decodes to 1568 MB (14000 x 14000 px, 8 bytes a pixel)" in text
    assert f"over the limit of {MAX_PIXELS * MAX_BYTES_PER_PIXEL / 1e6:.0f} MB" in text
    peak, out = peak_rss_mb(path)
    assert "over the limit" in out and peak < PEAK_MB


def test_a_gzip_fits_over_the_pixel_limit(tmp_path):
    path = gzip_fits(tmp_path / "big.fits.gz", (14000, 14000), 16)
    text = refused(path, max_pixels=100_000_000)
    assert "is 14000 x 14000 px (196 MP), over the limit of 100 MP" in text
    wide = gzip_fits(tmp_path / "wide.fits.gz", (20000, 20000), 8)
    assert "(400 MP), over the limit of 200 MP" in refused(wide)


def test_a_gzip_fits_without_the_fits_name_is_checked_off_the_stream(tmp_path):
    path = gzip_fits(tmp_path / "bomb.gz", (20000, 20000), 16)
    assert "(400 MP), over the limit of 200 MP" in refused(path)


def test_cubes_count_every_plane_in_their_bytes(tmp_path):
    # 3 planes of 12000 x 12000 float32: 144 MP, 1728 MB decoded
    cube = gzip_fits(tmp_path / "cube.fits.gz", (3, 12000, 12000), -32)
    assert "decodes to 1728 MB (12000 x 12000 px, 12 bytes a pixel)" in refused(cube)
    small = gzip_fits(tmp_path / "small.fits.gz", (3, 40, 50), -32)
    assert read_image(small).shape == (40, 50)


@pytest.mark.parametrize("gzipped", [False, True], ids=["fz", "fz.gz"])
def test_tile_compressed_fits_by_its_znaxis(tmp_path, gzipped):
    name = "tiles.fits.gz" if gzipped else "tiles.fz"
    path = compressed_fits(tmp_path / name, 30000, 20000, gzipped=gzipped)
    assert "is 30000 x 20000 px (600 MP), over the limit of 200 MP" in refused(path)


def test_a_16_bit_rgb_png_by_its_header(tmp_path):
    path = png_claiming(tmp_path / "deep.png", 30000, 20000)
    assert "is 30000 x 20000 px (600 MP), over the limit of 200 MP" in refused(path)
    # 16-bit RGBA within a pixel limit raised to its size: 8 bytes a pixel are too many
    rgba = png_claiming(tmp_path / "rgba.png", 30000, 20000, colour_type=6)
    assert "decodes to 4800 MB (30000 x 20000 px, 8 bytes a pixel), over the limit of 3600 MB" in (
        refused(rgba, max_pixels=600_000_000)
    )
    peak, out = peak_rss_mb(path)
    assert "over the limit" in out and peak < PEAK_MB


def test_a_jpeg_by_its_header(tmp_path):
    path = jpeg_claiming(tmp_path / "wide.jpg", 60000, 40000)
    assert "is 60000 x 40000 px (2400 MP), over the limit of 200 MP" in refused(path)


@pytest.mark.parametrize("planar", [True, False], ids=["planar", "contiguous"])
def test_a_float_rgb_tiff_pillow_cannot_open_by_tifffile_s_page(tmp_path, planar):
    pytest.importorskip("tifffile", reason="colour TIFFs of over 8 bits are read by tifffile")
    from PIL import Image, UnidentifiedImageError

    path = tiff_claiming(tmp_path / "float.tif", 60000, 50000, planar=planar)
    with pytest.raises(UnidentifiedImageError):
        Image.open(path)
    assert "is 60000 x 50000 px (3000 MP), over the limit of 200 MP" in refused(path)
    peak, out = peak_rss_mb(path)
    assert "over the limit" in out and peak < PEAK_MB


def test_a_16_bit_rgb_tiff_by_tifffile_s_page(tmp_path):
    pytest.importorskip("tifffile", reason="colour TIFFs of over 8 bits are read by tifffile")
    path = tiff_claiming(tmp_path / "deep.tif", 40000, 30000, dtype="uint16", planar=False)
    assert "is 40000 x 30000 px (1200 MP), over the limit of 200 MP" in refused(path)


def test_a_deep_pgm_by_its_header(tmp_path):
    path = tmp_path / "deep.pgm"
    path.write_bytes(b"P5\n30000 20000\n65535\n" + bytes(64))
    assert "is 30000 x 20000 px (600 MP), over the limit of 200 MP" in refused(path)


def test_images_within_the_limits_read(tmp_path):
    png = zero_png16(tmp_path / "zeros.png", 64, 48)
    assert read_image(png, max_pixels=64 * 48).shape == (48, 64)
    assert "(0.003072 MP), over the limit of 0.003071 MP" in refused(png, max_pixels=64 * 48 - 1)
    fits_gz = gzip_fits(tmp_path / "ok.fits.gz", (48, 64), 16)
    np.testing.assert_array_equal(read_image(fits_gz), np.zeros((48, 64), np.float32))


@pytest.mark.parametrize("bad", [0, -5, 1.5, True, None])
def test_a_bad_limit_is_one_line(tmp_path, bad):
    png = zero_png16(tmp_path / "zeros.png", 8, 8)
    with pytest.raises(ImageError, match="max_pixels must be a positive whole number"):
        read_image(png, max_pixels=bad)


def test_starnav_solve_refuses_each_attack_in_one_line(tmp_path, capsys):
    pytest.importorskip("tifffile", reason="colour TIFFs of over 8 bits are read by tifffile")
    files = [
        gzip_fits(tmp_path / "bomb.fits.gz", (14000, 14000), -64),
        png_claiming(tmp_path / "deep.png", 30000, 20000),
        tiff_claiming(tmp_path / "float.tif", 60000, 50000),
    ]
    for path in files:
        code, out, err = run_cli(capsys, "solve", str(path))
        assert code == 2 and out == ""
        assert err.count("\n") == 1 and "over the limit of" in err, err
