"""Small files claiming huge images, for the size limits of ``starnav.detect.read``: a whole
gzip-compressed FITS image of zeros (gzip members of zeros repeated: ~1 kB a 1 MB of pixels),
PNG, JPEG and TIFF files whose headers claim a size their few bytes of data do not hold, a
tile-compressed FITS whose ZNAXISn were raised, and a real 16-bit RGB PNG of zeros (pypng
reads it slowly, its rows Paeth-filtered far more slowly: a genuinely slow read)."""

from __future__ import annotations

import gzip
import io
import struct
import zlib
from pathlib import Path

import numpy as np
from astropy.io import fits
from PIL import Image

FITS_BLOCK = 2880
_ZEROS_MEMBER = gzip.compress(bytes(1 << 24), compresslevel=9)  # 16 MiB of zeros, ~16 kB


def gzip_fits(path: Path, shape: tuple[int, ...], bitpix: int) -> Path:
    """A gzip-compressed FITS file of one image of zeros, ``shape`` (numpy order), its data
    all there (padded to a FITS block): the header a member, the zeros members of 16 MiB."""
    header = fits.Header()
    header["SIMPLE"], header["BITPIX"], header["NAXIS"] = True, bitpix, len(shape)
    for k, n in enumerate(reversed(shape), 1):
        header[f"NAXIS{k}"] = n
    nbytes = int(np.prod(shape, dtype=np.int64)) * abs(bitpix) // 8
    nbytes += -nbytes % FITS_BLOCK
    with path.open("wb") as fh:
        fh.write(gzip.compress(header.tostring().encode("ascii")))
        whole, rest = divmod(nbytes, 1 << 24)
        for _ in range(whole):
            fh.write(_ZEROS_MEMBER)
        fh.write(gzip.compress(bytes(rest)))
    return path


def compressed_fits(path: Path, width: int, height: int, *, gzipped: bool = False) -> Path:
    """A tile-compressed FITS image whose header claims ``width`` x ``height`` px (its
    ZNAXISn edited; the tiles are a 64 x 64 image's)."""
    hdul = fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(np.zeros((64, 64), np.int16))])
    buf = io.BytesIO()
    hdul.writeto(buf)
    raw = buf.getvalue()
    for key, value in (("ZNAXIS1", width), ("ZNAXIS2", height)):
        card = f"{key:8s}= {64:>20d}".encode()
        assert card in raw, key
        raw = raw.replace(card, f"{key:8s}= {value:>20d}".encode(), 1)
    path.write_bytes(gzip.compress(raw) if gzipped else raw)
    return path


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def png_claiming(path: Path, width: int, height: int, *, bit_depth=16, colour_type=2) -> Path:
    """A PNG whose header (IHDR) claims ``width`` x ``height`` px (colour type 2: RGB) and
    whose data is one row of zeros."""
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    idat = zlib.compress(bytes(1 + width * 6))
    png = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat)
    path.write_bytes(png + _chunk(b"IEND", b""))
    return path


def zero_png16(path: Path, width: int, height: int, *, paeth: bool = False) -> Path:
    """A whole 16-bit RGB PNG of zeros (every row there, compressed to ~6 kB a megapixel),
    its rows filtered by nothing or, ``paeth``, by the Paeth predictor (which pypng undoes a
    byte at a time in Python: a far slower read)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    packer = zlib.compressobj(9)
    row = (b"\x04" if paeth else b"\x00") + bytes(width * 6)
    idat = b"".join(packer.compress(row) for _ in range(height)) + packer.flush()
    png = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat)
    path.write_bytes(png + _chunk(b"IEND", b""))
    return path


def jpeg_claiming(path: Path, width: int, height: int) -> Path:
    """A JPEG whose frame header (SOF0) claims ``width`` x ``height`` px (at most 65535)."""
    buf = io.BytesIO()
    Image.new("L", (16, 16)).save(buf, "JPEG")
    raw = bytearray(buf.getvalue())
    sof = raw.index(b"\xff\xc0")
    raw[sof + 5 : sof + 9] = struct.pack(">HH", height, width)
    path.write_bytes(bytes(raw))
    return path


def tiff_claiming(path: Path, width: int, height: int, dtype="float32", planar=True) -> Path:
    """A TIFF of 3 samples a pixel (float: a format Pillow does not open), planar or not,
    whose tags claim ``width`` x ``height`` px (its 16 x 16 data unchanged)."""
    import tifffile

    shape = (3, 16, 16) if planar else (16, 16, 3)
    tifffile.imwrite(path, np.zeros(shape, dtype), photometric="rgb",
                     planarconfig="separate" if planar else "contig")  # fmt: skip
    raw = bytearray(path.read_bytes())
    with tifffile.TiffFile(path) as tif:
        tags = tif.pages.first.tags
        for name, value in (("ImageWidth", width), ("ImageLength", height)):
            tag = tags[name]
            fmt = "<I" if tag.dtype == 4 else "<H"
            raw[tag.valueoffset : tag.valueoffset + struct.calcsize(fmt)] = struct.pack(fmt, value)
    path.write_bytes(bytes(raw))
    return path
