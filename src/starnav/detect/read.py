"""Image files to one 2-D float32 luminance array, row 0 at the top of the picture.

Formats: FITS (astropy: the first HDU holding an image, also a tile-compressed one, ``.fz``,
and gzip-compressed files, ``.fits.gz``), and through Pillow PNG, JPEG, TIFF and whatever else
Pillow opens (8/16-bit grey, 32-bit integer and float grey, colour). Pillow 13 reduces
16-bit-per-channel colour to 8 bits, so such TIFFs are read with ``tifffile`` and such PNGs
with ``pypng`` (pure Python: ~1.5 s per megapixel); binary PGM / PPM with more than 8 bits
(THEMIS and other auroral imagers write 16-bit PGM) are read here, as stored (Pillow scales a
12-bit PGM's values by 65535 / 4095 and cuts 16-bit PPM colour to 8 bits). A gzip-compressed
file of any of these formats (``frame.pgm.gz``) is read as the file it holds.

FITS cubes: the axes of length 1 are dropped; 3 planes, either axis order ((3, H, W) or
(H, W, 3)), are a colour image: its luminance; 4 planes (H, W, 4): RGBA, the alpha dropped;
any other stack of N planes (N, H, W) is a series of frames (a time series moves with the
sky, and a sum would trail its stars): the first frame is read.
Colour becomes luminance with the Rec. 709 weights (0.2126 R + 0.7152 G + 0.0722 B) on the
stored values (no gamma decoding); an alpha channel is dropped. An EXIF orientation tag is
applied, so row 0 is the top of the picture as viewers show it.

FITS row order: astropy's ``data[0]`` is the first row stored (FITS y = 1), and we take it as
row 0, the top of the picture. That is what a FITS written from a PNG holds (``simulate.render.
write_image`` writes that way), while FITS viewers such as DS9 draw y = 1 at the bottom, i.e.
show such an image upside down; a FITS file from an astronomical camera may be stored either
way. Only the mirror parity of the solution depends on it, and the solver reports the parity.

Values are stored values (BSCALE/BZERO applied for FITS); non-finite values come back as NaN
(``starnav.detect.stars`` masks them).

Size limits, checked from each format's header before its pixels are decoded (a small file can
claim a huge image: 190 kB of gzip-compressed FITS hold 14000 x 14000 px): at most
``max_pixels`` (width x height; default ``MAX_PIXELS``, 200 MP, the largest real sensors), and
at most ``MAX_BYTES_PER_PIXEL`` bytes a pixel decoded (samples x bytes a sample, every plane of
a cube counted: a 200 MP 16-bit RGB image fits, a 200 MP float64 one does not). A gzip-compressed
FITS file's header is read from the gzip stream, before astropy inflates it.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
import warnings
from pathlib import Path

import numpy as np

from starnav.errors import ImageError
from starnav.runtime.limits import MAX_BYTES_PER_PIXEL, MAX_PIXELS

REC709 = np.array([0.2126, 0.7152, 0.0722])
FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fits.gz", ".fit.gz", ".fts.gz", ".fz")
FITS_MAGIC = b"SIMPLE  ="  # the first bytes of a FITS file
GZIP_MAGIC = b"\x1f\x8b"  # of a gzip file
PNM_MAGICS = (b"P5", b"P6")  # binary PGM and PPM
FITS_BLOCK = 2880  # bytes of a FITS header block
MAX_FITS_HEADER_BLOCKS = 1000  # a header longer than this (2.9 MB, 36000 cards) is refused
TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # TIFF and BigTIFF
# formats Pillow opens that ``read_image`` does not read as pictures: MPEG (no decoder), EPS
# (needs Ghostscript), IPTC (metadata); Pillow's stubs (BUFR, GRIB, HDF5, WMF) are left out by
# their class
_PILLOW_NOT_READ = ("MPEG", "EPS", "IPTC")
_COLOUR_MODES = (
    "RGB",
    "RGBA",
    "RGBX",
    "RGBa",
    "LA",
    "La",
    "PA",
    "P",
    "CMYK",
    "YCbCr",
    "LAB",
    "HSV",
)


def read_image(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """The picture in ``path`` as a 2-D float32 array (luminance for colour), C order, native
    byte order, row 0 = top of the picture. ``ImageError`` (one line, naming the file) for a
    missing, unreadable or corrupt file, an empty or 1-D image, one with no finite pixel, or
    one larger than ``max_pixels`` (width x height) or ``max_pixels`` x
    ``MAX_BYTES_PER_PIXEL`` bytes decoded (checked from the header, before decoding)."""
    path = Path(path)
    name = str(path)
    check_max_pixels(max_pixels)
    if not path.exists():
        raise ImageError(f"image file {name!r} does not exist")
    if not path.is_file():
        raise ImageError(f"image file {name!r} is not a file")
    try:
        with path.open("rb") as fh:
            head = fh.read(80)
    except OSError as exc:
        raise ImageError(f"cannot read image file {name!r}: {exc.strerror or exc}") from None
    if not head:
        raise ImageError(f"image file {name!r} is empty (0 bytes)")
    fits_name = path.name.lower().endswith(FITS_SUFFIXES)
    if head.startswith(FITS_MAGIC) or (fits_name and head.startswith(GZIP_MAGIC)):
        data = _read_fits(path, name, max_pixels)
    elif fits_name:
        raise ImageError(f"cannot read image file {name!r}: not a FITS file (no SIMPLE card)")
    elif head.startswith(GZIP_MAGIC):
        data = _read_gzipped(path, name, max_pixels)
    elif head.startswith(PNM_MAGICS) and _pnm_maxval(head) > 255:
        with path.open("rb") as fh:
            data = _read_deep_pnm(fh, name, max_pixels)
    else:
        data = _read_pillow(path, name, max_pixels)
    return _finish(data, name)


def check_max_pixels(max_pixels: object) -> int:
    """``max_pixels`` if it is a positive whole number, else a one-line ``ImageError``."""
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, int) or max_pixels <= 0:
        raise ImageError(f"max_pixels must be a positive whole number, got {max_pixels!r}")
    return max_pixels


def check_size(name: str, width: int, height: int, nbytes: int, max_pixels: int) -> None:
    """A one-line ``ImageError`` when an image of ``width`` x ``height`` px, ``nbytes`` bytes
    decoded (every sample and plane), passes the limits (the module's docstring)."""
    pixels = width * height
    if pixels > max_pixels:
        raise ImageError(
            f"image file {name!r} is {width} x {height} px ({pixels / 1e6:.4g} MP), over the "
            f"limit of {max_pixels / 1e6:g} MP"
        )
    limit = max_pixels * MAX_BYTES_PER_PIXEL
    if nbytes > limit:
        raise ImageError(
            f"image file {name!r} decodes to {nbytes / 1e6:.0f} MB ({width} x {height} px, "
            f"{nbytes / max(pixels, 1):.3g} bytes a pixel), over the limit of "
            f"{limit / 1e6:.0f} MB ({MAX_BYTES_PER_PIXEL} bytes a pixel of "
            f"{max_pixels / 1e6:g} MP)"
        )


def _check_shape(name: str, shape: tuple[int, ...], itemsize: int, max_pixels: int) -> None:
    """``check_size`` of an array shape: the two longest axes are the picture (a cube's
    planes and a stack's frames counted in its bytes)."""
    dims = [int(n) for n in shape]
    longest = sorted(sorted(range(len(dims)), key=lambda k: -dims[k])[:2])  # in numpy order
    height, width = ([1, 1] + [dims[k] for k in longest])[-2:]
    check_size(name, width, height, math.prod(dims) * itemsize, max_pixels)


def _read_gzipped(path: Path, name: str, max_pixels: int) -> np.ndarray:
    """The picture in a gzip-compressed file of any format read here (FITS, PGM, PNG, ...),
    its size checked before it is inflated whole."""
    import gzip
    import io
    import zlib

    limit = max_pixels * MAX_BYTES_PER_PIXEL
    try:
        with gzip.open(path, "rb") as fh:
            head = fh.read(80)
            if head.startswith(FITS_MAGIC):
                raw = None
            elif head.startswith(PNM_MAGICS) and _pnm_maxval(head) > 255:
                fh.seek(0)
                return _read_deep_pnm(fh, name, max_pixels)
            else:  # a picture Pillow reads: its header is checked once it is opened
                raw = head + fh.read(limit + 1 - len(head))
    except (OSError, EOFError, zlib.error) as exc:
        raise ImageError(f"cannot read gzip file {name!r}: {_one_line(exc)}") from None
    if raw is None:
        return _read_fits(path, name, max_pixels)
    if len(raw) > limit:
        raise ImageError(
            f"image file {name!r} unpacks to more than {limit / 1e6:.0f} MB, the limit "
            f"({MAX_BYTES_PER_PIXEL} bytes a pixel of {max_pixels / 1e6:g} MP)"
        )
    if not raw:
        raise ImageError(f"image file {name!r} holds an empty gzip stream")
    return _read_pillow(io.BytesIO(raw), name, max_pixels)


def _pnm_header(raw: bytes) -> tuple[list[int], int] | None:
    """(width, height, maxval) of a binary PGM / PPM and the offset of its pixels, None when
    the header is incomplete or malformed."""
    fields: list[int] = []
    pos = 2
    while len(fields) < 3:
        while pos < len(raw) and raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":  # a comment, to the end of its line
            end = raw.find(b"\n", pos)
            if end < 0:
                return None
            pos = end + 1
            continue
        start = pos
        while pos < len(raw) and raw[pos : pos + 1].isdigit():
            pos += 1
        if pos == start:
            return None
        fields.append(int(raw[start:pos]))
    if pos >= len(raw) or not raw[pos : pos + 1].isspace():
        return None
    return fields, pos + 1  # one whitespace byte ends the header


def _pnm_maxval(head: bytes) -> int:
    """A binary PGM / PPM's maxval from its first bytes (0 when not found there)."""
    parsed = _pnm_header(head)
    return parsed[0][2] if parsed else 0


def _read_deep_pnm(fh, name: str, max_pixels: int) -> np.ndarray:
    """A binary PGM / PPM of more than 8 bits (two big-endian bytes a sample), as stored,
    from the file object ``fh`` at its start (its size checked before its pixels are read)."""
    head = fh.read(1024)
    parsed = _pnm_header(head)
    if parsed is None:
        raise ImageError(f"cannot read PNM file {name!r}: malformed header")
    (width, height, maxval), offset = parsed
    planes = 3 if head.startswith(b"P6") else 1
    if not (0 < width and 0 < height and maxval < 65536):
        raise ImageError(
            f"cannot read PNM file {name!r}: bad header ({width} x {height}, maxval {maxval})"
        )
    need = width * height * planes * 2
    check_size(name, width, height, need, max_pixels)
    raw = head + fh.read(offset + need - len(head))
    if len(raw) - offset < need:
        raise ImageError(
            f"cannot read PNM file {name!r}: truncated ({len(raw) - offset} bytes of pixels, "
            f"{need} needed for {width} x {height} px)"
        )
    data = np.frombuffer(raw, dtype=">u2", count=need // 2, offset=offset)
    if planes == 3:
        return luminance(data.reshape(height, width, 3))
    return data.reshape(height, width)


@functools.cache
def readable_suffixes() -> tuple[str, ...]:
    """The file-name endings (lower case) of the formats ``read_image`` reads: FITS's and
    those of every format Pillow opens and decodes (PNG, JPEG, TIFF, BMP, GIF, WebP, PNM,
    JPEG 2000, ...), and the gzip-compressed PGM, PPM, PNM, PNG and TIFF files auroral imagers
    archive (``.pgm.gz``). A directory given to ``starnav solve`` is listed by them."""
    from PIL import Image, ImageFile

    Image.init()
    pillow = {
        ext.lower()
        for ext, fmt in Image.registered_extensions().items()
        if fmt in Image.OPEN
        and fmt not in _PILLOW_NOT_READ
        and not _is_stub(Image.OPEN[fmt][0], ImageFile.StubImageFile)
    }
    gzipped = {ext + ".gz" for ext in pillow if ext in (".pgm", ".ppm", ".pnm", ".png", ".tif")}
    return tuple(sorted(pillow | gzipped | set(FITS_SUFFIXES)))


def _is_stub(factory: object, stub: type) -> bool:
    """Whether a Pillow format's factory (a class, or a function for JPEG) is a stub."""
    return isinstance(factory, type) and issubclass(factory, stub)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of colour pixels (..., 3) on the stored values, float32."""
    rgb = np.asarray(rgb)
    out = np.zeros(rgb.shape[:-1], dtype=np.float32)
    for k in range(3):
        out += np.float32(REC709[k]) * rgb[..., k].astype(np.float32)
    return out


def _read_fits(source: Path, name: str, max_pixels: int) -> np.ndarray:
    """The first image of a FITS file (also gzip-compressed): a 2-D image, a colour cube's
    luminance or a stack's first frame (the module's docstring). Each image's size is checked
    from its header before its data is read."""
    from astropy.io import fits

    with source.open("rb") as fh:
        gzipped = fh.read(2) == GZIP_MAGIC
    if gzipped:
        _check_gzipped_fits(source, name, max_pixels)
    shapes = []
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # non-standard cards are common; the pixels matter
            with fits.open(source, memmap=False) as hdul:
                for hdu in hdul:
                    if not hdu.is_image or not hdu.shape:  # tables, empty primaries
                        continue
                    bitpix = abs(int(hdu.header.get("BITPIX", 8)))
                    _check_shape(name, hdu.shape, max(bitpix // 8, 1), max_pixels)
                    if hdu.data is None:
                        continue
                    data = np.asarray(hdu.data)
                    image = _cube_image(data.reshape([n for n in data.shape if n != 1] or [1]))
                    if image is not None:
                        return image
                    shapes.append(data.shape)
    except ImageError:
        raise
    except (OSError, ValueError, TypeError, IndexError, KeyError, EOFError) as exc:
        raise ImageError(f"cannot read FITS file {name!r}: {_one_line(exc)}") from None
    if shapes:
        raise ImageError(
            f"FITS file {name!r} holds no 2-D image or cube of them (data shapes: "
            f"{', '.join(str(s) for s in shapes)})"
        )
    raise ImageError(f"FITS file {name!r} holds no image data")


def _check_gzipped_fits(path: Path, name: str, max_pixels: int) -> None:
    """The size of a gzip-compressed FITS file's first image, from its header read off the
    gzip stream (astropy inflates the whole stream when it opens one): headers without data
    are passed, the first with data is checked if it is an image (plain or tile-compressed;
    astropy's reader checks an image after a table)."""
    import gzip
    import zlib

    try:
        with gzip.open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            header = _next_fits_header(fh, name)
            while header is not None and int(header.get("NAXIS", 0)) == 0:
                header = _next_fits_header(fh, name)  # no data: the next header follows
    except (OSError, EOFError, zlib.error, ValueError) as exc:
        raise ImageError(f"cannot read FITS file {name!r}: {_one_line(exc)}") from None
    if header is None:
        return
    prefix = "Z" if header.get("ZIMAGE") else ""  # a tile-compressed image: its own axes
    if not prefix and str(header.get("XTENSION", "IMAGE")).strip() != "IMAGE":
        return
    try:
        naxis = int(header.get(f"{prefix}NAXIS", 0))
        shape = tuple(int(header.get(f"{prefix}NAXIS{k}", 0)) for k in range(naxis, 0, -1))
        bitpix = abs(int(header.get(f"{prefix}BITPIX", 8)))
    except (TypeError, ValueError):
        raise ImageError(f"cannot read FITS file {name!r}: malformed NAXIS or BITPIX") from None
    _check_shape(name, shape, max(bitpix // 8, 1), max_pixels)


def primary_fits_header(path: str | Path):
    """The primary header (an astropy ``Header``) of a FITS file, plain or gzip-compressed,
    read off the stream (astropy's open inflates a whole gzip stream first); None when the
    file starts with no FITS header."""
    import gzip
    import zlib

    path = Path(path)
    try:
        with path.open("rb") as fh:
            gzipped = fh.read(2) == GZIP_MAGIC
        with (gzip.open if gzipped else open)(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if fh.read(len(FITS_MAGIC)) != FITS_MAGIC:
                return None
            fh.seek(0)
            return _next_fits_header(fh, str(path))
    except (OSError, EOFError, zlib.error, ValueError, ImageError):
        return None


def _next_fits_header(fh, name: str):
    """The next FITS header of the stream ``fh`` (an astropy ``Header``; None at its end)."""
    from astropy.io import fits

    blocks = []
    for _ in range(MAX_FITS_HEADER_BLOCKS):
        block = fh.read(FITS_BLOCK)
        if not block.strip(b"\0 "):
            return None
        blocks.append(block)
        if any(block[k : k + 8] == b"END     " for k in range(0, len(block), 80)):
            return fits.Header.fromstring(b"".join(blocks).decode("ascii", "replace"))
    raise ImageError(
        f"cannot read FITS file {name!r}: no END card in its first {MAX_FITS_HEADER_BLOCKS} "
        "header blocks"
    )


def _cube_image(data: np.ndarray) -> np.ndarray | None:
    """The 2-D picture of a FITS HDU's data with its length-1 axes dropped: itself (2-D), a
    colour cube's luminance ((3, H, W) or (H, W, 3); (H, W, 4): RGBA), a stack's first frame
    ((N, H, W)); None for other shapes."""
    if data.ndim == 2:
        return data
    if data.ndim != 3:
        return None
    if data.shape[0] == 3:
        return luminance(np.moveaxis(data, 0, -1))
    if data.shape[-1] in (3, 4) and min(data.shape[:2]) > 4:
        return luminance(data[..., :3])
    return data[0]


_PILLOW_LIMIT = threading.Lock()  # guards Pillow's global pixel limit while one opens


def _pillow_open(path):
    """Pillow's lazy open (the header only) without Pillow's own pixel limit, a global that
    would refuse images of 179-200 MP: ours is checked from the size it reads."""
    from PIL import Image

    with _PILLOW_LIMIT:
        saved, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            return Image.open(path)
        finally:
            Image.MAX_IMAGE_PIXELS = saved


def _check_pillow_size(img, name: str, max_pixels: int) -> None:
    """``check_size`` of an opened (not yet decoded) Pillow image: its size, bands and bytes
    a sample (2 for colour of more than 8 bits, read by pypng or tifffile)."""
    from PIL import ImageMode

    width, height = img.size
    mode = ImageMode.getmode(img.mode)
    sample = 2 if _deeper_than_pillow(img) else max(int(mode.typestr[-1]), 1)
    check_size(name, width, height, width * height * len(mode.bands) * sample, max_pixels)


def _read_pillow(path, name: str, max_pixels: int) -> np.ndarray:
    """The picture Pillow reads from ``path`` (a path or a file object)."""
    from PIL import Image, ImageOps, UnidentifiedImageError

    try:
        with _pillow_open(path) as img, warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            _check_pillow_size(img, name, max_pixels)
            if _deeper_than_pillow(img):
                return _read_deep_colour(path, img.format, name, max_pixels)
            img.load()
            return _pillow_to_array(ImageOps.exif_transpose(img))
    except UnidentifiedImageError:
        if _is_tiff(path):  # a TIFF that Pillow does not decode (e.g. float colour)
            return _read_deep_colour(path, "TIFF", name, max_pixels)
        raise ImageError(
            f"cannot read image file {name!r}: not an image format we read "
            "(FITS, PNG, JPEG, TIFF, ...)"
        ) from None
    except ImageError:
        raise
    except Image.DecompressionBombError:
        raise ImageError(f"image file {name!r} is too large to decode safely") from None
    except (OSError, ValueError, SyntaxError, EOFError, KeyError, IndexError) as exc:
        raise ImageError(f"cannot read image file {name!r}: {_one_line(exc)}") from None


def _pillow_to_array(img) -> np.ndarray:
    mode = img.mode
    if mode in ("P", "PA"):
        img = img.convert("RGBA" if "transparency" in img.info or mode == "PA" else "RGB")
    elif mode in ("CMYK", "YCbCr", "LAB", "HSV"):
        img = img.convert("RGB")
    elif mode == "1":
        img = img.convert("L")
    data = np.asarray(img)
    if data.ndim == 3:
        if data.shape[-1] in (3, 4):
            return luminance(data[..., :3])
        return data[..., 0]  # grey + alpha
    return data


def _deeper_than_pillow(img) -> bool:
    """True for colour images with more than 8 bits per channel, which Pillow truncates."""
    if img.mode not in _COLOUR_MODES:
        return False
    if img.format == "TIFF":
        bits = img.tag_v2.get(258, (8,))
        return max(bits if isinstance(bits, tuple) else (bits,)) > 8
    if img.format == "PNG":
        return any(";16" in str(tile.args) for tile in img.tile)
    return False


def _read_deep_colour(path, fmt: str | None, name: str, max_pixels: int) -> np.ndarray:
    """A colour PNG or TIFF of more than 8 bits a channel (``path``: a path or a file object;
    a PNG's size is checked by the caller, a TIFF's here from its first page's header)."""
    if hasattr(path, "seek"):
        path.seek(0)
    if fmt == "PNG":
        try:
            import png
        except ImportError:
            raise ImageError(
                f"cannot read {name!r}: 16-bit colour PNG needs the 'pypng' package"
            ) from None
        try:
            reader = png.Reader(file=path) if hasattr(path, "read") else png.Reader(filename=name)
            width, height, rows, info = reader.asDirect()
            data = np.vstack([np.asarray(row, dtype=np.uint16) for row in rows])
        except (png.Error, OSError, ValueError) as exc:
            raise ImageError(f"cannot read PNG file {name!r}: {_one_line(exc)}") from None
        data = data.reshape(height, width, info["planes"])
    else:
        try:
            import tifffile
        except ImportError:
            raise ImageError(
                f"cannot read {name!r}: colour TIFF with more than 8 bits per channel needs the "
                "'tifffile' package"
            ) from None
        # tifffile logs what it finds amiss in a file; the reason is our one line
        logging.getLogger("tifffile").setLevel(logging.ERROR)
        try:
            with tifffile.TiffFile(path) as tif:
                page = tif.pages.first
                _check_shape(name, page.shape, np.dtype(page.dtype).itemsize, max_pixels)
                data = np.asarray(page.asarray())
        except ImageError:
            raise
        except Exception as exc:  # tifffile raises many types (incl. a missing codec)
            raise ImageError(f"cannot read TIFF file {name!r}: {_one_line(exc)}") from None
        if data.ndim == 3 and data.shape[0] in (3, 4) and data.shape[-1] not in (3, 4):
            data = np.moveaxis(data, 0, -1)  # planar configuration
    if data.ndim == 3 and data.shape[-1] >= 3:
        return luminance(data[..., :3])
    if data.ndim == 3:
        return data[..., 0]  # grey + alpha
    return data


def _is_tiff(path) -> bool:
    """Whether the file (a path or a file object) starts as a TIFF does."""
    if hasattr(path, "read"):
        path.seek(0)
        return path.read(4) in TIFF_MAGICS
    with Path(path).open("rb") as fh:
        return fh.read(4) in TIFF_MAGICS


def _finish(data: np.ndarray, name: str) -> np.ndarray:
    data = np.asarray(data)
    if data.size == 0:
        raise ImageError(f"image file {name!r} holds an empty image (shape {data.shape})")
    if data.ndim != 2:
        raise ImageError(f"image file {name!r} holds {data.ndim}-D data, not a 2-D image")
    if data.dtype.kind not in "uifb":
        raise ImageError(f"image file {name!r} holds {data.dtype} pixels, not numbers")
    out = np.ascontiguousarray(data, dtype=np.float32)  # also native byte order
    if not out.flags.writeable:
        out = out.copy()
    finite = np.isfinite(out)
    if not finite.all():
        if not finite.any():
            raise ImageError(f"image file {name!r} has no finite pixel (all NaN or infinite)")
        out[~finite] = np.nan
    return out


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return " ".join(text.split())
