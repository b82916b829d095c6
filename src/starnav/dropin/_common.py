"""What the two drop-ins share: a parser that reports a mistake in one line, the image size,
and the local TAN projection both tools' readers expect."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from astropy.wcs import WCS

EXIT_BAD_INPUT = 2  # argparse's status for a usage mistake; both drop-ins use it for bad input


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage mistake in one line (exit 2), without the usage dump.
    (``starnav.cli.common.Parser`` is the same three lines; the layers keep the drop-ins below
    the CLI, so they cannot share it.)"""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


def image_size(path: str | Path) -> tuple[int, int]:
    """(width, height) in px of an image file as ``starnav.detect.read.read_image`` reads it
    (``ImageError`` for a file it cannot read)."""
    from starnav.detect.read import read_image

    height, width = read_image(path).shape
    return width, height


def tan_at_centre(wcs: WCS, width: int, height: int, *, grid: int = 9) -> WCS:
    """A TAN WCS with its reference pixel at the image centre (FITS ((W+1)/2, (H+1)/2)) and
    CRVAL the sky there, its CD matrix (degrees per pixel) fitted by least squares in the
    tangent plane to ``wcs`` over a ``grid`` x ``grid`` set of points spanning the image. The
    same as ``wcs`` for an undistorted solution whose reference pixel is the centre; for a
    distorted one (TAN-SIP), the linear camera that best matches it over the whole image,
    which is what ASTAP writes and what readers of a plain CD matrix assume."""
    crpix = np.array([(width + 1) / 2.0, (height + 1) / 2.0])
    ra0, dec0 = (float(v) for v in wcs.all_pix2world([crpix], 1)[0])
    xs = np.linspace(1.0, float(width), grid)
    ys = np.linspace(1.0, float(height), grid)
    px = np.array([(x, y) for y in ys for x in xs])
    sky = np.radians(wcs.all_pix2world(px, 1))
    ra, dec = sky[:, 0], sky[:, 1]
    a0, d0 = math.radians(ra0), math.radians(dec0)
    cos_c = np.sin(d0) * np.sin(dec) + np.cos(d0) * np.cos(dec) * np.cos(ra - a0)
    xi = np.cos(dec) * np.sin(ra - a0) / cos_c  # gnomonic standard coordinates, radians
    eta = (np.cos(d0) * np.sin(dec) - np.sin(d0) * np.cos(dec) * np.cos(ra - a0)) / cos_c
    offsets = px - crpix
    cd, *_ = np.linalg.lstsq(offsets, np.degrees(np.column_stack([xi, eta])), rcond=None)
    out = WCS(naxis=2)
    out.wcs.ctype = ["RA---TAN", "DEC--TAN"]
    out.wcs.crpix = crpix
    out.wcs.crval = [ra0 % 360.0, dec0]
    out.wcs.cd = cd.T
    out.wcs.radesys = "ICRS"
    out.wcs.set()
    out.pixel_shape = (width, height)
    return out
