"""solve-field's side files: the tables astrometry.net writes beside a solved image's WCS.

Each is a FITS file whose first extension is a binary table, with solve-field's column names,
formats and units (Debian's astrometry.net 0.93 as the reference: ``solver/solve-field.c``,
``augment-xylist.c``, ``util/xylist.c``, ``util/rdlist.c``, ``solver/matchfile.c``), so a
client that reads them by name reads ours:

* ``.axy`` (``write_axy``): the field's sources, X, Y (FITS pixels, 1-based), FLUX and
  BACKGROUND, with the image size (IMAGEW, IMAGEH) and ``ANRUN`` ("solve this field") in the
  primary header; the unaugmented ``--keep-xylist`` file has the same table without the
  solver's keywords (``write_xyls``);
* ``.rdls`` (``write_rdls``): RA, DEC (degrees) of the catalog stars inside the solved field;
  ``-indx.xyls`` (``write_xyls``): the same stars' X, Y in the image, same order;
* ``.corr`` (``write_corr``): one row per matched star: field_x, field_y, field_ra, field_dec,
  index_x, index_y, index_ra, index_dec, index_id (its row in the .rdls), field_id (its row in
  the .axy), match_weight, FLUX, BACKGROUND;
* ``.match`` (``write_match``): astrometry.net's MatchObj row, with the fields that have a
  meaning for starnav (the WCS's CRVAL, CRPIX and CD, the field's centre and radius, the
  counts NMATCH, NFIELD, NINDEX, NDISTRACT, NCONFLICT, LOGODDS, PARITY, TIMEUSED, ...); the
  quad fields of astrometry.net's hash match (QUAD, STARS, FIELDOBJS, CODEERR, QUADPIX, ...)
  have none and are left out (``MATCH_ABSENT``);
* ``.kmz`` (``write_kmz``): a KML ground overlay of the image for Google Earth's sky mode,
  zipped with the picture.

Pixels here are FITS pixels (1-based); callers convert from starnav's (FITS = ours + 0.5).
"""

from __future__ import annotations

import io
import warnings
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from astropy.io import fits

from starnav.errors import StarnavError

# MatchObj fields astrometry.net writes that describe its quad hash match: no meaning for
# starnav's identification, so not written
MATCH_ABSENT = (
    "QUAD", "DIMQUADS", "STARS", "FIELDOBJS", "IDS", "CODEERR", "QUADPDI", "QUADPIX",
    "QUADXYZ", "NAGREE", "HEALPIX", "HPNSIDE", "QTRIED", "QMATCHED", "QSCALEOK", "QPEERS",
    "NVERIFIED", "WORSTLOGODDS",
)  # fmt: skip


def _column(name: str, fmt: str, values, unit: str | None = None) -> fits.Column:
    return fits.Column(name=name, format=fmt, array=np.asarray(values), unit=unit)


def _write(path: str | Path, table: fits.BinTableHDU, primary: fits.Header | None = None):
    header = fits.Header() if primary is None else primary
    hdul = fits.HDUList([fits.PrimaryHDU(header=header), table])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", fits.verify.VerifyWarning)
            hdul.writeto(path, overwrite=True)
    except OSError as exc:
        raise StarnavError(f"cannot write {str(path)!r}: {exc}") from None


def _file_type(kind: str) -> fits.Header:
    header = fits.Header()
    header["AN_FILE"] = (kind, "Astrometry.net file type")
    return header


def _sources_table(x, y, flux, background, width: int, height: int) -> fits.BinTableHDU:
    n = len(x)
    flux = np.zeros(n) if flux is None else flux
    background = np.zeros(n) if background is None else background
    table = fits.BinTableHDU.from_columns(
        [
            _column("X", "E", x, "pix"),
            _column("Y", "E", y, "pix"),
            _column("FLUX", "E", flux, "unknown"),
            _column("BACKGROUND", "E", background, "unknown"),
        ]
    )
    table.header["EXTNAME"] = "SOURCES"
    table.header["IMAGEW"] = (int(width), "Input image width")
    table.header["IMAGEH"] = (int(height), "Input image height")
    table.header["COMMENT"] = (
        "The X and Y points are specified assuming 1,1 is the center of the first pixel "
        "of the image in accordance with the FITS standard."
    )
    return table


def write_xyls(
    path: str | Path,
    x_fits: np.ndarray,
    y_fits: np.ndarray,
    width: int,
    height: int,
    *,
    flux: np.ndarray | None = None,
    background: np.ndarray | None = None,
) -> None:
    """An xylist: X, Y (FITS px) with FLUX and BACKGROUND when given (``--keep-xylist``),
    else X, Y only (solve-field's ``-indx.xyls``, ``AN_FILE = XYLS``)."""
    if flux is None and background is None:
        table = fits.BinTableHDU.from_columns(
            [_column("X", "D", x_fits, "pix"), _column("Y", "D", y_fits, "pix")]
        )
        table.header["IMAGEW"] = (int(width), "Input image width")
        table.header["IMAGEH"] = (int(height), "Input image height")
        _write(path, table, _file_type("XYLS"))
        return
    _write(path, _sources_table(x_fits, y_fits, flux, background, width, height))


def write_axy(
    path: str | Path,
    x_fits: np.ndarray,
    y_fits: np.ndarray,
    width: int,
    height: int,
    *,
    flux: np.ndarray | None = None,
    background: np.ndarray | None = None,
    keywords: Mapping[str, tuple] | None = None,
) -> None:
    """The augmented xylist (``.axy``): the sources as ``write_xyls`` writes them with FLUX
    and BACKGROUND (zeros when not known), and in the primary header IMAGEW, IMAGEH, ANRUN and
    the solver's keywords of ``keywords`` (name: (value, comment); e.g. ANCRPIXC, ANTWEAK,
    ANTWEAKO, ANAPPL1 / ANAPPU1, ANWCS, ANCORR, ...)."""
    primary = fits.Header()
    primary["IMAGEW"] = (int(width), "image width")
    primary["IMAGEH"] = (int(height), "image height")
    primary["ANRUN"] = (True, "Solve this field!")
    for name, card in (keywords or {}).items():
        primary[name] = card
    table = _sources_table(x_fits, y_fits, flux, background, width, height)
    _write(path, table, primary)


def write_rdls(path: str | Path, ra_deg: np.ndarray, dec_deg: np.ndarray) -> None:
    """The catalog stars inside the solved field (``.rdls``): RA, DEC in degrees."""
    table = fits.BinTableHDU.from_columns(
        [_column("RA", "D", ra_deg, "deg"), _column("DEC", "D", dec_deg, "deg")]
    )
    primary = _file_type("RDLS")
    primary["HISTORY"] = "This file contains the RA/DEC of catalog stars inside a solved field."
    _write(path, table, primary)


CORR_COLUMNS = (
    ("field_x", "D", "pixels"),
    ("field_y", "D", "pixels"),
    ("field_ra", "D", "degrees"),
    ("field_dec", "D", "degrees"),
    ("index_x", "D", "pixels"),
    ("index_y", "D", "pixels"),
    ("index_ra", "D", "degrees"),
    ("index_dec", "D", "degrees"),
    ("index_id", "J", "none"),
    ("field_id", "J", "none"),
    ("match_weight", "D", "none"),
    ("FLUX", "E", "unknown"),
    ("BACKGROUND", "E", "unknown"),
)


def write_corr(path: str | Path, columns: Mapping[str, np.ndarray]) -> None:
    """The correspondences (``.corr``), one row per matched star: ``columns`` holds every
    name of ``CORR_COLUMNS`` (field_*: the measured source, its sky position through the
    WCS; index_*: the catalog star and its pixel through the WCS; FITS px, degrees)."""
    missing = [name for name, _, _ in CORR_COLUMNS if name not in columns]
    if missing:
        raise StarnavError(f"corr columns missing: {', '.join(missing)}")
    table = fits.BinTableHDU.from_columns(
        [_column(name, fmt, columns[name], unit) for name, fmt, unit in CORR_COLUMNS]
    )
    _write(path, table)


def write_match(path: str | Path, fields: Mapping[str, object]) -> None:
    """astrometry.net's MatchObj (``.match``), one row: ``fields`` by MatchObj name. Known
    names with their formats: CENTERXYZ (3 floats), RADIUS (deg), NMATCH, NDISTRACT,
    NCONFLICT, NFIELD, NINDEX, CRVAL (2), CRPIX (2), CD (4, row-major), WCS_VALID, FIELDNUM,
    FIELDID, INDEXID, FIELDNAME, PARITY, TIMEUSED (s), LOGODDS; others are refused."""
    formats = {
        "CENTERXYZ": ("3D", None), "RADIUS": ("D", "DEG"), "NMATCH": ("J", None),
        "NDISTRACT": ("J", None), "NCONFLICT": ("J", None), "NFIELD": ("J", None),
        "NINDEX": ("J", None), "CRVAL": ("2D", None), "CRPIX": ("2D", None),
        "CD": ("4D", None), "WCS_VALID": ("L", None), "FIELDNUM": ("J", None),
        "FIELDID": ("J", None), "INDEXID": ("I", None), "FIELDNAME": ("31A", None),
        "PARITY": ("L", None), "TIMEUSED": ("E", "s"), "LOGODDS": ("E", None),
    }  # fmt: skip
    unknown = [name for name in fields if name not in formats]
    if unknown:
        raise StarnavError(f"unknown MatchObj fields: {', '.join(unknown)}")
    columns = []
    for name, (fmt, unit) in formats.items():
        if name in fields:
            value = fields[name]
            array = np.array([value]) if np.ndim(value) == 0 else np.array([value], dtype=float)
            columns.append(_column(name, fmt, array, unit))
    _write(path, fits.BinTableHDU.from_columns(columns), _file_type("MATCH"))


def kml_document(corners_radec_deg: np.ndarray, name: str, image_href: str) -> str:
    """A KML ground overlay for Google Earth's sky mode (``hint="target=sky"``: longitude
    = RA - 180°, latitude = Dec) putting ``image_href`` on the sky by its four corners
    (``gx:LatLonQuad``: the image's bottom-left, bottom-right, top-right, top-left as shown,
    i.e. (0, H), (W, H), (W, 0), (0, 0) in starnav px)."""
    points = " ".join(f"{ra % 360.0 - 180.0:.8f},{dec:.8f}" for ra, dec in corners_radec_deg)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:gx="http://www.google.com/kml/ext/2.2" \
hint="target=sky">
<GroundOverlay>
  <name>{_xml_text(name)}</name>
  <Icon><href>{_xml_text(image_href)}</href></Icon>
  <gx:LatLonQuad><coordinates>{points}</coordinates></gx:LatLonQuad>
</GroundOverlay>
</kml>
"""


def _xml_text(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def write_kmz(path: str | Path, corners_radec_deg: np.ndarray, png: bytes, name: str) -> None:
    """A KMZ (zip) of ``doc.kml`` (``kml_document``) and the picture ``image.png``, as
    astrometry.net's ``kml_file`` serves it (there: the image warped by wcs2kml onto an
    RA/Dec box; here the picture as it is, placed by its corners)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as kmz:
        kmz.writestr("doc.kml", kml_document(corners_radec_deg, name, "image.png"))
        kmz.writestr("image.png", png)
    try:
        Path(path).write_bytes(buffer.getvalue())
    except OSError as exc:
        raise StarnavError(f"cannot write {str(path)!r}: {exc}") from None
