"""Source lists of a real photograph as the programs that call a plate solver write them, for
the drop-in and service tests: the stars starnav detects in the GranaSAT Pleiades frame
(../shared/data/real, astrometry.net's reference in tests/data/real/reference.json), in
detection order (by y, as image2xy and SExtractor write them) or shuffled, with or without a
brightness column, as Siril's xylist (X, Y, FLUX, BACKGROUND; IMAGEW, IMAGEH) or
StellarSolver's (X_IMAGE, Y_IMAGE, MAG_AUTO). Pixels are FITS pixels (starnav's + 0.5)."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
from astropy.io import fits

from shared_data import DATA, REAL, shared_file

PLEIADES = "granasat_pleyades_05sec.jpg"  # 1280 x 960, 27°, a JPEG of a distorting lens
REAL_REFERENCE = json.loads((DATA / "real" / "reference.json").read_text())["images"]


def pleiades_path() -> Path:
    """The frame in ../shared/data/real (the calling test is skipped without it)."""
    return shared_file(REAL / PLEIADES)


@functools.lru_cache(maxsize=1)
def pleiades_sources() -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """FITS x, y and flux of the frame's detections in detection order (rows by y), and the
    image's width and height."""
    from starnav.detect.read import read_image
    from starnav.detect.stars import detect_stars

    pixels = read_image(pleiades_path())
    found = detect_stars(pixels)
    order = np.argsort(found.xy[:, 1], kind="stable")
    x, y = (found.xy[order, k] + 0.5 for k in (0, 1))
    height, width = pixels.shape
    return x, y, found.flux[order], width, height


def pleiades_fits(path: Path) -> Path:
    """The frame as a FITS image (the rows as starnav reads them: row 0 = FITS y = 1)."""
    from starnav.detect.read import read_image

    fits.PrimaryHDU(read_image(pleiades_path()).astype(np.float32)).writeto(path)
    return path


def siril_xylist(path: Path) -> Path:
    """Siril's xylist (``save_list_as_FITS_table``): X, Y, FLUX, BACKGROUND, IMAGEW, IMAGEH."""
    x, y, flux, width, height = pleiades_sources()
    columns = [fits.Column("X", "E", array=x), fits.Column("Y", "E", array=y),
               fits.Column("FLUX", "E", array=flux),
               fits.Column("BACKGROUND", "E", array=np.zeros_like(x))]  # fmt: skip
    table = fits.BinTableHDU.from_columns(columns)
    table.header["IMAGEW"], table.header["IMAGEH"] = width, height
    fits.HDUList([fits.PrimaryHDU(), table]).writeto(path)
    return path


def stellarsolver_xylist(path: Path) -> Path:
    """StellarSolver's xylist (``writeStarExtractorTable``): X_IMAGE, Y_IMAGE, MAG_AUTO in a
    table named SExtractor_File, no image size (the command line gives it)."""
    x, y, flux, _, _ = pleiades_sources()
    mag = -2.5 * np.log10(np.maximum(flux, 1e-6))
    columns = [fits.Column("X_IMAGE", "E", array=x), fits.Column("Y_IMAGE", "E", array=y),
               fits.Column("MAG_AUTO", "E", array=mag)]  # fmt: skip
    table = fits.BinTableHDU.from_columns(columns, name="SExtractor_File")
    fits.HDUList([fits.PrimaryHDU(), table]).writeto(path)
    return path


def plain_xylist(path: Path, order: np.ndarray | None = None) -> Path:
    """An xylist of X and Y only (no brightness), rows in ``order`` (None: detection order)."""
    x, y, _, width, height = pleiades_sources()
    rows = np.arange(len(x)) if order is None else order
    columns = [fits.Column("X", "D", array=x[rows]), fits.Column("Y", "D", array=y[rows])]
    table = fits.BinTableHDU.from_columns(columns)
    table.header["IMAGEW"], table.header["IMAGEH"] = width, height
    fits.HDUList([fits.PrimaryHDU(), table]).writeto(path)
    return path


def random_xylist(path: Path) -> Path:
    """An xylist of X and Y only, as many points as the frame's detections but placed at
    random over it (seed 3), in detection order: a list no solver can solve."""
    x, _, _, width, height = pleiades_sources()
    rng = np.random.default_rng(3)
    rx, ry = rng.uniform(0.5, width + 0.5, len(x)), np.sort(rng.uniform(0.5, height + 0.5, len(x)))
    columns = [fits.Column("X", "D", array=rx), fits.Column("Y", "D", array=ry)]
    table = fits.BinTableHDU.from_columns(columns)
    table.header["IMAGEW"], table.header["IMAGEH"] = width, height
    fits.HDUList([fits.PrimaryHDU(), table]).writeto(path)
    return path


def centre_offset_arcmin(ra_deg: float, dec_deg: float, name: str = PLEIADES) -> float:
    """Angle (arcmin) from astrometry.net's image centre of ``name`` to (ra, dec)."""
    ref = REAL_REFERENCE[name]
    r1, d1, r2, d2 = (math.radians(v) for v in (ra_deg, dec_deg, ref["ra_deg"], ref["dec_deg"]))
    c = math.sin(d1) * math.sin(d2) + math.cos(d1) * math.cos(d2) * math.cos(r1 - r2)
    return math.degrees(math.acos(min(1.0, max(-1.0, c)))) * 60.0
