"""What all-sky cameras write, read as stored: FITS cubes and stacks, tile-compressed FITS,
16-bit PGM / PPM (auroral imagers), gzip-compressed images. The files are written here by
astropy, Pillow and pypng, or byte by byte (PNM's header is three numbers)."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from starnav.detect.read import read_image, readable_suffixes
from starnav.errors import ImageError

REC709 = (0.2126, 0.7152, 0.0722)


@pytest.fixture(scope="module")
def frame():
    """A 16-bit frame: a gradient, noise and a star near the top left (row 0 at the top)."""
    rng = np.random.default_rng(37)
    rows, cols = np.mgrid[0:48, 0:64]
    image = 1000 + 20 * rows + 3 * cols + rng.integers(0, 50, (48, 64))
    image[5:8, 9:12] = 61000
    return image.astype(np.uint16)


def _pnm(magic: bytes, data: np.ndarray, maxval: int, comment: bytes = b"") -> bytes:
    height, width = data.shape[:2]
    head = magic + b"\n" + comment + b"%d %d\n%d\n" % (width, height, maxval)
    return head + data.astype(">u2").tobytes()


def test_fits_stack_reads_its_first_frame_and_colour_cubes_their_luminance(tmp_path, frame):
    from astropy.io import fits

    stack = np.stack([frame, frame // 2, frame // 3, frame // 4]).astype(np.int32)
    fits.PrimaryHDU(stack).writeto(tmp_path / "stack.fits")
    assert np.array_equal(read_image(tmp_path / "stack.fits"), frame.astype(np.float32))
    fits.PrimaryHDU(stack[:, None]).writeto(tmp_path / "stack4d.fits")  # (N, 1, H, W)
    assert np.array_equal(read_image(tmp_path / "stack4d.fits"), frame.astype(np.float32))
    rgb = np.dstack([frame, frame // 2, frame // 4]).astype(np.float32)  # (H, W, 3)
    fits.PrimaryHDU(rgb).writeto(tmp_path / "hw3.fits")
    expected = sum(w * rgb[..., k] for k, w in enumerate(REC709))
    assert np.allclose(read_image(tmp_path / "hw3.fits"), expected, rtol=1e-6)
    fits.PrimaryHDU(np.moveaxis(rgb, -1, 0)).writeto(tmp_path / "3hw.fits")
    assert np.allclose(read_image(tmp_path / "3hw.fits"), expected, rtol=1e-6)


@pytest.mark.parametrize("compression", ["RICE_1", "GZIP_2", "HCOMPRESS_1"])
def test_tile_compressed_fits(tmp_path, frame, compression):
    from astropy.io import fits

    hdus = [
        fits.PrimaryHDU(),
        fits.CompImageHDU(frame.astype(np.int32), compression_type=compression),
    ]
    fits.HDUList(hdus).writeto(tmp_path / "c.fits.fz")
    back = read_image(tmp_path / "c.fits.fz")
    assert back.shape == frame.shape
    assert np.array_equal(back, frame.astype(np.float32))  # integers: lossless


def test_16_bit_pgm_and_ppm_as_stored(tmp_path, frame):
    (tmp_path / "g16.pgm").write_bytes(_pnm(b"P5", frame, 65535, b"# THEMIS-like\n"))
    assert np.array_equal(read_image(tmp_path / "g16.pgm"), frame.astype(np.float32))
    # a 12-bit PGM (maxval 4095): stored values, not scaled to 16 bits
    twelve = frame >> 4
    (tmp_path / "g12.pgm").write_bytes(_pnm(b"P5", twelve, 4095))
    assert np.array_equal(read_image(tmp_path / "g12.pgm"), twelve.astype(np.float32))
    rgb = np.dstack([frame, frame // 2, frame // 4])
    (tmp_path / "c16.ppm").write_bytes(_pnm(b"P6", rgb, 65535))
    expected = sum(w * rgb[..., k].astype(np.float64) for k, w in enumerate(REC709))
    assert np.allclose(read_image(tmp_path / "c16.ppm"), expected, rtol=1e-6)
    # an 8-bit PGM still goes through Pillow
    from PIL import Image

    Image.fromarray((frame >> 8).astype(np.uint8)).save(tmp_path / "g8.pgm")
    assert np.array_equal(read_image(tmp_path / "g8.pgm"), (frame >> 8).astype(np.float32))


def test_gzip_compressed_images(tmp_path, frame):
    from PIL import Image

    (tmp_path / "a.pgm.gz").write_bytes(gzip.compress(_pnm(b"P5", frame, 65535)))
    assert np.array_equal(read_image(tmp_path / "a.pgm.gz"), frame.astype(np.float32))
    Image.fromarray(frame).save(tmp_path / "b.png")
    (tmp_path / "b.png.gz").write_bytes(gzip.compress((tmp_path / "b.png").read_bytes()))
    assert np.array_equal(read_image(tmp_path / "b.png.gz"), frame.astype(np.float32))
    from astropy.io import fits

    fits.PrimaryHDU(frame.astype(np.int32)).writeto(tmp_path / "c.fits")
    (tmp_path / "c.gz").write_bytes(gzip.compress((tmp_path / "c.fits").read_bytes()))
    assert np.array_equal(read_image(tmp_path / "c.gz"), frame.astype(np.float32))
    png = pytest.importorskip("png")
    rgb = np.dstack([frame, frame // 2, frame // 4])
    with open(tmp_path / "d.png", "wb") as fh:
        png.Writer(64, 48, greyscale=False, bitdepth=16).write(fh, rgb.reshape(48, -1))
    (tmp_path / "d.png.gz").write_bytes(gzip.compress((tmp_path / "d.png").read_bytes()))
    expected = sum(w * rgb[..., k].astype(np.float64) for k, w in enumerate(REC709))
    assert np.allclose(read_image(tmp_path / "d.png.gz"), expected, rtol=1e-6)
    assert {".pgm.gz", ".png.gz", ".fz", ".fits.gz"} <= set(readable_suffixes())


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("cut.pgm", b"P5\n64 48\n65535\n" + b"\x00" * 100, "truncated"),
        ("bad.pgm", b"P5\n64 x\n65535\n" + b"\x00" * 100, "cannot read"),
        ("cut.pgm.gz", gzip.compress(b"P5\n64 48\n65535\n" + b"\x00" * 10), "truncated"),
        ("broken.pgm.gz", gzip.compress(b"P5\n4 4\n65535\n" + b"\x00" * 32)[:-12], "gzip"),
        ("noise.gz", gzip.compress(b"hello" * 100), "not an image format"),
        ("void.gz", gzip.compress(b""), "empty gzip"),
    ],
)
def test_bad_compressed_and_pnm_files(tmp_path, name, content, match):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(ImageError, match=match) as info:
        read_image(tmp_path / name)
    assert "\n" not in str(info.value) and name in str(info.value)
