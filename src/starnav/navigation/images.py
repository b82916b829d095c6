"""What an observation's image file gives a camera: its detected stars, and the time it was taken.

Stars: the image is read and its stars detected exactly as ``starnav solve IMAGE`` does
(``starnav.detect``: the same threshold and number of stars), brightest first, saturated stars
first; the centroids then go the way of a camera's ``stars`` list.

Time, from the file's own metadata:

- FITS: ``DATE-OBS`` of the first header that has one (the primary, then the extensions), ISO
  8601; a date alone takes its time from ``TIME-OBS``. It is UTC unless ``TIMESYS`` names
  another astropy time scale (TT, TAI, ...), which is then converted.
- other formats (JPEG, PNG, TIFF, through Pillow): EXIF ``DateTimeOriginal`` (tag 36867 in
  the EXIF IFD 0x8769, ``YYYY:MM:DD HH:MM:SS``, fractions from ``SubSecTimeOriginal``, 37521).
  It is the camera clock's local time: the observation must give ``utc_offset_hours`` (local
  minus UTC) to turn it into UTC.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from astropy.time import Time

from starnav.detect.read import read_image
from starnav.detect.stars import Detections
from starnav.errors import ImageError, StarnavError
from starnav.image import detect_image

_FITS_MAGIC = b"SIMPLE  ="
_FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fits.gz", ".fit.gz", ".fts.gz", ".fz")
_EXIF_IFD = 0x8769
_DATE_TIME_ORIGINAL = 36867
_SUBSEC_TIME_ORIGINAL = 37521
_TIME_SCALES = ("utc", "tt", "tai", "tcg", "tcb", "tdb", "ut1")


@dataclass(frozen=True)
class ImageTime:
    """A time an image file records: ``text`` as written, ``source`` (which header or tag),
    and whether it is ``local`` (EXIF: the camera clock's zone) or already a time scale
    astropy converts to UTC (FITS). ``time``: the astropy ``Time`` (for a local time, taken as
    if it were UTC: the offset is applied by the caller)."""

    text: str
    source: str
    local: bool
    time: Time


def image_stars(path: str | Path, lens: str = "pinhole") -> Detections:
    """The stars detected in an image file as ``starnav solve IMAGE`` detects them through a
    ``lens`` model (``ImageError`` for a missing or unreadable file)."""
    return detect_image(read_image(path), lens=lens)


def image_time(path: str | Path) -> ImageTime | None:
    """The time recorded in an image file's metadata, None when it records none;
    ``StarnavError`` (one line) for a time that cannot be read."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            head = fh.read(len(_FITS_MAGIC))
    except OSError as exc:
        raise ImageError(f"cannot read image file {str(path)!r}: {exc.strerror or exc}") from None
    if head == _FITS_MAGIC or path.name.lower().endswith(_FITS_SUFFIXES):
        return _fits_time(path)
    return _exif_time(path)


def _fits_time(path: Path) -> ImageTime | None:
    from astropy.io import fits

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with fits.open(path, memmap=False) as hdul:
                headers = [hdu.header for hdu in hdul]
    except (OSError, ValueError, TypeError, IndexError, KeyError) as exc:
        raise ImageError(f"cannot read FITS file {str(path)!r}: {exc}") from None
    header = next((h for h in headers if "DATE-OBS" in h), None)
    if header is None:
        return None
    date = str(header["DATE-OBS"]).strip()
    source = "FITS DATE-OBS"
    if "T" not in date:
        if "TIME-OBS" not in header:
            raise StarnavError(
                f"{str(path)!r}: FITS DATE-OBS {date!r} is a date without a time and there is "
                "no TIME-OBS: give 'utc' in the observation"
            )
        date = f"{date}T{str(header['TIME-OBS']).strip()}"
        source = "FITS DATE-OBS + TIME-OBS"
    scale = str(header.get("TIMESYS", "UTC")).strip().lower()
    if scale not in _TIME_SCALES:
        raise StarnavError(
            f"{str(path)!r}: TIMESYS {header['TIMESYS']!r} is not a time scale starnav converts "
            f"({', '.join(s.upper() for s in _TIME_SCALES)})"
        )
    if scale != "utc":
        source += f" ({scale.upper()})"
    try:
        t = Time(date.removesuffix("Z"), format="isot", scale=scale).utc
    except ValueError:
        raise StarnavError(f"{str(path)!r}: {source} {date!r} is not an ISO 8601 time") from None
    return ImageTime(date, source, False, t)


def _exif_time(path: Path) -> ImageTime | None:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as img:
            exif = img.getexif().get_ifd(_EXIF_IFD)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError):
        # its pixels were read (16-bit colour TIFF / PNG go past Pillow): it records no
        # time that Pillow can see
        return None
    text = exif.get(_DATE_TIME_ORIGINAL)
    if text is None:
        return None
    text = str(text).strip().rstrip("\x00")
    subsec = str(exif.get(_SUBSEC_TIME_ORIGINAL, "")).strip().rstrip("\x00")
    date, _, clock = text.partition(" ")
    iso = f"{date.replace(':', '-')}T{clock}" + (f".{subsec}" if subsec.isdigit() else "")
    try:
        t = Time(iso, format="isot", scale="utc")
    except ValueError:
        raise StarnavError(
            f"{str(path)!r}: EXIF DateTimeOriginal {text!r} is not a time (YYYY:MM:DD HH:MM:SS)"
        ) from None
    return ImageTime(text, "EXIF DateTimeOriginal", True, t)
