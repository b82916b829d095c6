"""What an image file says besides its pixels: the time it was taken, and (FITS) hints for
the solve.

Time (``image_time``), from the file's own metadata:

- FITS: ``DATE-OBS`` of the first header that has one (the primary, then the extensions), ISO
  8601; a date alone takes its time from ``TIME-OBS``. It is UTC unless ``TIMESYS`` names
  another astropy time scale (TT, TAI, ...), which is then converted.
- other formats (JPEG, PNG, TIFF, through Pillow): EXIF ``DateTimeOriginal`` (tag 36867 in
  the EXIF IFD 0x8769, ``YYYY:MM:DD HH:MM:SS``, fractions from ``SubSecTimeOriginal``, 37521).
  It is the camera clock's local time: the observation must give ``utc_offset_hours`` (local
  minus UTC) to turn it into UTC.

Hints (``fits_hints``), from the first FITS header holding each, used by ``starnav solve``
unless its own options say otherwise:

- position: ``RA``/``DEC`` (degrees), else ``OBJCTRA``/``OBJCTDEC`` (sexagesimal hours and
  degrees), else ``CRVAL1``/``CRVAL2`` of an equatorial WCS (``CTYPE1`` starting ``RA--``);
- field of view (horizontal, degrees): from a WCS's pixel scale (``CD1_1``.. or ``CDELT1``),
  else ``PIXSCALE``/``SCALE``/``SECPIX`` (arcsec per px), else ``FOCALLEN`` (mm) with
  ``XPIXSZ`` (µm, per binned pixel as N.I.N.A. and SharpCap write it), times ``NAXIS1``;
- epoch (decimal year, for the catalog's proper motion): from the time above;
- pixel aspect (a pixel's height over its width): ``YPIXSZ``/``XPIXSZ``, else
  ``PIXSIZE2``/``PIXSIZE1`` (µm), when they differ by more than ``SQUARE_TOLERANCE``: a CCD
  such as the SX Lodestar's (8.6 x 8.3 µm) is solved in square pixels, its answers given in
  the file's (``pipeline.image``).

A keyword that is present but unreadable is ignored (a hint only narrows the search: a bad
one costs time, never a wrong answer, since the search then runs without it).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from starnav.detect.read import FITS_MAGIC, FITS_SUFFIXES
from starnav.errors import ImageError, StarnavError

if TYPE_CHECKING:  # astropy.time (0.25 s) is imported where a time is read: a solve reads none
    from astropy.time import Time

_EXIF_IFD = 0x8769
_DATE_TIME_ORIGINAL = 36867
_SUBSEC_TIME_ORIGINAL = 37521
_TIME_SCALES = ("utc", "tt", "tai", "tcg", "tcb", "tdb", "ut1")
# pixels whose sides differ by less than this share are square: 0.1 px at 500 px from the
# centre; the Lodestar's 3.5 % is 17 px there
SQUARE_TOLERANCE = 2e-4
PIXEL_ASPECT_RANGE = (0.5, 2.0)  # sizes further apart are taken as unreadable (CCDs: 0.51-1)
_PIXEL_SIZE_KEYS = (("XPIXSZ", "YPIXSZ"), ("PIXSIZE1", "PIXSIZE2"))


def is_fits(path: str | Path) -> bool:
    """Whether ``path`` is a FITS file (by its first bytes or its name)."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            head = fh.read(len(FITS_MAGIC))
    except OSError as exc:
        raise ImageError(f"cannot read image file {str(path)!r}: {exc.strerror or exc}") from None
    return head == FITS_MAGIC or path.name.lower().endswith(FITS_SUFFIXES)


def fits_headers(path: Path) -> list:
    """Every header of a FITS file (primary first), or a one-line ``ImageError``."""
    from astropy.io import fits

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with fits.open(path, memmap=False) as hdul:
                return [hdu.header.copy() for hdu in hdul]
    except (OSError, ValueError, TypeError, IndexError, KeyError) as exc:
        raise ImageError(f"cannot read FITS file {str(path)!r}: {exc}") from None


@dataclass(frozen=True)
class ImageHints:
    """What a FITS header says of its image: the boresight ``ra_deg``/``dec_deg`` (degrees;
    None when not given), the horizontal ``fov_deg``, the ``epoch_year`` of the catalog, the
    time ``utc`` (ISO 8601, UTC), the ``site`` (latitude, longitude degrees, height m) and
    ``sources``: the keywords each came from."""

    ra_deg: float | None = None
    dec_deg: float | None = None
    fov_deg: float | None = None
    epoch_year: float | None = None
    sources: tuple[str, ...] = ()
    utc: str | None = None
    site: tuple[float, float, float] | None = None
    pixel_aspect: float = 1.0

    def to_dict(self) -> dict:
        """The JSON form (``sources`` as a list)."""
        return {
            "ra_deg": self.ra_deg,
            "dec_deg": self.dec_deg,
            "fov_deg": self.fov_deg,
            "epoch_year": self.epoch_year,
            "utc": self.utc,
            "site": None if self.site is None else list(self.site),
            "pixel_aspect": self.pixel_aspect,
            "sources": list(self.sources),
        }


def fits_hints(path: str | Path) -> ImageHints:
    """The hints of a FITS file's headers (``ImageHints()``, all None, for another format)."""
    path = Path(path)
    if not is_fits(path):
        return ImageHints()
    headers = fits_headers(path)
    sources: list[str] = []
    ra, dec = _position(headers, sources)
    fov = _fov(headers, sources)
    epoch = utc = None
    try:
        found = _fits_time(path, headers)
    except StarnavError:
        found = None
    if found is not None:
        epoch = float(found.time.jyear)
        utc = found.time.utc.isot
        sources.append(found.source)
    site = _site(headers, sources)
    aspect = _pixel_aspect(headers, sources)
    return ImageHints(ra, dec, fov, epoch, tuple(sources), utc, site, aspect)


def _pixel_aspect(headers, sources: list[str]) -> float:
    """A pixel's height over its width, from the first header giving both sizes (1 when
    none does, or they agree within ``SQUARE_TOLERANCE``; sizes whose ratio is outside
    ``PIXEL_ASPECT_RANGE`` are passed over as unreadable)."""
    for h in headers:
        for x_key, y_key in _PIXEL_SIZE_KEYS:
            width, height = _number(h, x_key), _number(h, y_key)
            if width and height and width > 0 and height > 0:
                aspect = height / width
                if abs(aspect - 1.0) <= SQUARE_TOLERANCE:
                    return 1.0
                if PIXEL_ASPECT_RANGE[0] <= aspect <= PIXEL_ASPECT_RANGE[1]:
                    sources.append(f"{x_key}/{y_key}")
                    return aspect
    return 1.0


# the keywords of a site: latitude, longitude (east positive), height (m)
_SITE_KEYS = (
    ("SITELAT", "SITELONG", "SITEELEV"),  # MaxIm DL, N.I.N.A., SharpCap, indi-allsky
    ("OBSGEO-B", "OBSGEO-L", "OBSGEO-H"),  # the FITS standard's
    ("LAT-OBS", "LONG-OBS", "ALT-OBS"),  # ESO's and others'
)


def _site(headers, sources: list[str]) -> tuple[float, float, float] | None:
    """(latitude, longitude degrees, height m) of the first header naming a site (degrees or
    sexagesimal degrees); None when none does, or when its values are unreadable."""
    from astropy.coordinates import Angle

    for h in headers:
        for lat_key, lon_key, height_key in _SITE_KEYS:
            if lat_key not in h or lon_key not in h:
                continue
            try:
                lat = float(Angle(h[lat_key], unit="deg").deg)
                lon = float(Angle(h[lon_key], unit="deg").deg)
            except (ValueError, TypeError):
                continue
            height = _number(h, height_key) or 0.0
            if abs(lat) <= 90.0 and math.isfinite(lon):
                sources.append(f"FITS {lat_key}/{lon_key}")
                return lat, lon, height
    return None


def _number(header, key: str) -> float | None:
    try:
        value = float(header[key])
    except (KeyError, TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _position(headers, sources: list[str]) -> tuple[float | None, float | None]:
    from astropy.coordinates import Angle

    for h in headers:
        ra, dec = _number(h, "RA"), _number(h, "DEC")
        if ra is not None and dec is not None and 0 <= ra < 360 and -90 <= dec <= 90:
            sources.append("RA/DEC")
            return ra, dec
        if "OBJCTRA" in h and "OBJCTDEC" in h:
            try:
                ra = Angle(str(h["OBJCTRA"]).strip(), unit="hourangle").degree
                dec = Angle(str(h["OBJCTDEC"]).strip(), unit="deg").degree
            except ValueError:
                continue
            if -90 <= dec <= 90:
                sources.append("OBJCTRA/OBJCTDEC")
                return float(ra) % 360.0, float(dec)
        if str(h.get("CTYPE1", "")).startswith("RA--"):
            ra, dec = _number(h, "CRVAL1"), _number(h, "CRVAL2")
            if ra is not None and dec is not None and -90 <= dec <= 90:
                sources.append("CRVAL1/CRVAL2")
                return ra % 360.0, dec
    return None, None


def _fov(headers, sources: list[str]) -> float | None:
    for h in headers:
        width = _number(h, "NAXIS1")
        if not width or _number(h, "NAXIS") not in (2.0, 3.0):
            continue
        scale_deg, source = _scale_deg(h)
        if scale_deg is not None and 0 < scale_deg * width < 180:
            sources.append(source)  # a pinhole whose central pixel spans scale_deg
            return math.degrees(2.0 * math.atan(0.5 * width * math.radians(scale_deg)))
    return None


def _scale_deg(h) -> tuple[float | None, str]:
    """Degrees per pixel along x, and the keywords it came from."""
    cd11, cd21 = _number(h, "CD1_1"), _number(h, "CD2_1")
    if cd11 is not None or cd21 is not None:
        return math.hypot(cd11 or 0.0, cd21 or 0.0), "CD1_1/CD2_1"
    cdelt = _number(h, "CDELT1")
    if cdelt:
        return abs(cdelt), "CDELT1"
    for key in ("PIXSCALE", "SCALE", "SECPIX"):
        arcsec = _number(h, key)
        if arcsec and arcsec > 0:
            return arcsec / 3600.0, key
    focal_mm, pixel_um = _number(h, "FOCALLEN"), _number(h, "XPIXSZ")
    if focal_mm and pixel_um and focal_mm > 0 and pixel_um > 0:
        return math.degrees(pixel_um * 1e-3 / focal_mm), "FOCALLEN/XPIXSZ"
    return None, ""


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


def image_time(path: str | Path) -> ImageTime | None:
    """The time recorded in an image file's metadata, None when it records none;
    ``StarnavError`` (one line) for a time that cannot be read."""
    path = Path(path)
    if is_fits(path):
        return _fits_time(path, fits_headers(path))
    return _exif_time(path)


def _fits_time(path: Path, headers: list) -> ImageTime | None:
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
    from astropy.time import Time

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
    from astropy.time import Time

    try:
        t = Time(iso, format="isot", scale="utc")
    except ValueError:
        raise StarnavError(
            f"{str(path)!r}: EXIF DateTimeOriginal {text!r} is not a time (YYYY:MM:DD HH:MM:SS)"
        ) from None
    return ImageTime(text, "EXIF DateTimeOriginal", True, t)
