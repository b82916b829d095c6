"""FITS World Coordinate System (WCS) of a solved image, for DS9, astropy, Aladin and friends.

Pixel conventions: starnav's pixels have their origin at the top-left corner of the image (the
first pixel's centre is (0.5, 0.5), y down); FITS numbers pixels from 1 at the first pixel's
centre, so ``fits = ours + 0.5`` on both axes and astropy's 0-based pixel coordinates are
``ours - 0.5``. Row 0 of the numpy array is FITS y = 1: nothing is flipped, the WCS describes the
array as it is (a viewer that puts FITS y = 1 at the bottom shows it upside down compared with
a PNG of the same array, and the sky on it correctly).

Each lens model gets the zenithal projection whose radius is its own (its class's
``fits_projection``): pinhole TAN, equidistant ARC, stereographic STG, equisolid ZEA,
orthographic SIN, and Kannala-Brandt ARC with SIP polynomials. The reference point (CRVAL) is
the camera's z axis, the principal point is CRPIX, and the CD matrix maps pixel offsets to
intermediate world coordinates (x toward East, y toward North, degrees): a direction θ from
the axis lies at image radius f g(θ) and at R = (180/π) g(θ) degrees in its projection (TAN:
g = tan θ, ARC: θ, STG: 2 tan(θ/2), ZEA: 2 sin(θ/2), SIN: sin θ), so one CD matrix, (180/π)/f
deg/px times the camera's rotation on the sky, serves them all. A mirrored attitude
(determinant -1) simply gives a CD matrix of the other sign of determinant. A model with
distortion (the pinhole's ``k1``, ``k2``; Kannala-Brandt's ``k1``..``k4``) gets SIP
polynomials fitted by least squares over the image (within its image circle): A/B from
measured pixel offsets to those of the same camera with its coefficients at zero
(``undistorted``: TAN-SIP, ARC-SIP), AP/BP back (``fit_sip`` tells the fit error in pixels),
of at most its class's ``sip_max_order`` when ``choose_sip_order`` picks it. A new lens model
needs no entry here: its class declares both facts.
"""

from __future__ import annotations

import datetime as _dt
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.time import Time
from astropy.wcs import WCS

from starnav.camera import CameraModel
from starnav.errors import CameraError, ImageError, StarnavError, shown
from starnav.geometry import north_east, unit_to_radec

DEFAULT_SIP_ORDER = 4
MAX_SIP_ORDER = 9
SIP_GOOD_ENOUGH_PX = 0.01  # fit error choose_sip_order asks for
SIP_GRID_POINTS = 41  # per image axis: the grid the polynomials are fitted and checked on
_ROUND_TRIP_TOLERANCE_PX = 1e-3


@dataclass(frozen=True, eq=False)
class SipFit:
    """SIP polynomials for a camera's radial distortion (pixel offsets from the principal point).

    ``a``, ``b``: (order + 1, order + 1) arrays, ``a[p, q]`` the coefficient of u^p v^q in the
    correction from distorted to undistorted pixel offsets (terms of degree 2..order);
    ``ap``, ``bp``: the inverse (undistorted to distorted, degrees 1..order).
    ``max_error_px``: largest error of A/B over the image grid; ``max_inverse_error_px``: that
    of AP/BP; ``max_distortion_px``: largest displacement the model itself makes in the image.
    """

    order: int
    a: np.ndarray
    b: np.ndarray
    ap: np.ndarray
    bp: np.ndarray
    max_error_px: float
    max_inverse_error_px: float
    max_distortion_px: float


def _check_attitude(R_cam_from_icrs: np.ndarray) -> np.ndarray:
    R = np.asarray(R_cam_from_icrs, dtype=float)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise StarnavError(f"R_cam_from_icrs must be a finite 3x3 matrix, got shape {R.shape}")
    error = float(np.abs(R @ R.T - np.eye(3)).max())
    if error > 1e-6:
        raise StarnavError(
            f"R_cam_from_icrs must have orthonormal rows (a rotation, or a reflection for a "
            f"mirrored image); R R^T differs from the identity by {error:.2g}"
        )
    return R


def _terms(order: int, lowest: int) -> list[tuple[int, int]]:
    return [(p, n - p) for n in range(lowest, order + 1) for p in range(n, -1, -1)]


def _design(uv: np.ndarray, terms: list[tuple[int, int]], scale: float) -> np.ndarray:
    u, v = (uv / scale).T  # scaled so that the powers stay near 1 (conditioning)
    return np.column_stack([u**p * v**q for p, q in terms])


def _fit(
    uv: np.ndarray, target: np.ndarray, order: int, lowest: int, scale: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares polynomials (degrees lowest..order) for the two columns of ``target``:
    coefficient arrays in unscaled pixel units and the largest error (px) over the points."""
    terms = _terms(order, lowest)
    design = _design(uv, terms, scale)
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    error = float(np.max(np.linalg.norm(design @ coef - target, axis=1)))
    arrays = np.zeros((2, order + 1, order + 1))
    # terms that move no point by 1e-9 px are rounding noise (e.g. even terms of a radial model)
    coef[np.abs(coef) < 1e-9] = 0.0
    for (p, q), c in zip(terms, coef, strict=True):
        arrays[:, p, q] = c / scale ** (p + q)
    return arrays[0], arrays[1], error


def _check_order(order: int) -> int:
    if isinstance(order, bool) or not isinstance(order, int | np.integer):
        raise StarnavError(f"sip_order must be an integer, got {shown(order)}")
    if not 2 <= order <= MAX_SIP_ORDER:
        raise StarnavError(f"sip_order must be in 2..{MAX_SIP_ORDER}, got {order}")
    return int(order)


def projection(camera: CameraModel) -> str:
    """The FITS projection code (``TAN``, ``ARC``, ``STG``, ``ZEA``, ``SIN``) of the camera's
    lens model (its ``fits_projection``); SIP polynomials are added when it has distortion
    (``camera.distorted``)."""
    code = getattr(camera, "fits_projection", "")
    if not code:
        raise CameraError(f"no FITS projection for the {camera.model!r} lens model")
    return code


def _undistorted(camera: CameraModel) -> CameraModel:
    if not camera.coefficients:
        raise CameraError(f"the {camera.model} model has no distortion to fit SIP polynomials to")
    return camera.undistorted()


def _fit_points(camera: CameraModel) -> np.ndarray:
    """Pixels (n, 2) the SIP polynomials are fitted and checked on: a grid of
    ``SIP_GRID_POINTS`` x ``SIP_GRID_POINTS`` spanning the image (corners included), and for a
    lens with an image circle only its points inside the circle, with points on its rim."""
    gx, gy = np.meshgrid(
        np.linspace(0.0, camera.width, SIP_GRID_POINTS),
        np.linspace(0.0, camera.height, SIP_GRID_POINTS),
    )
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    circle_deg = getattr(camera, "image_circle_deg", None)
    if circle_deg is None:
        return grid
    theta = np.radians(0.5 * circle_deg)
    inside = camera.pixels_to_bearings(grid)[:, 2] >= np.cos(theta)
    phi = np.linspace(0.0, 2.0 * np.pi, 8 * SIP_GRID_POINTS, endpoint=False)
    rim_directions = np.column_stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.full_like(phi, np.cos(theta))]
    )
    rim = camera.bearings_to_pixels(rim_directions)
    return np.vstack([grid[inside], rim[camera.contains(rim)]])


def fit_sip(camera: CameraModel, *, order: int = DEFAULT_SIP_ORDER) -> SipFit:
    """SIP polynomials of degree ``order`` (2..9) for the distortion of a pinhole (``k1``,
    ``k2``: TAN-SIP) or Kannala-Brandt camera (``k1``..``k4``: ARC-SIP).

    They map the camera's pixel offsets from the principal point to those of the same camera
    without distortion (``camera.undistorted()``, its coefficients at zero; pinhole:
    ``r = f tan θ``, Kannala-Brandt: ``r = f θ``). Fitted on the
    pixels of ``_fit_points`` (a grid over the image, within its image circle). A radial model
    has odd terms only, so an even order fits as well as the odd order below it; the pinhole's
    inverse AP/BP is exact once order >= 3 (k1 only) or 5 (with k2).
    """
    order = _check_order(order)
    ideal = _undistorted(camera)
    grid = _fit_points(camera)
    bearings = camera.pixels_to_bearings(grid)
    distorted = camera.bearings_to_pixels(bearings)
    gap = float(np.max(np.linalg.norm(distorted - grid, axis=1)))
    if not gap <= _ROUND_TRIP_TOLERANCE_PX:
        coefficients = ", ".join(f"{k}={shown(getattr(camera, k))}" for k in camera.coefficients)
        raise CameraError(
            f"{camera.model} distortion {coefficients} cannot be inverted over the image "
            f"(pixels -> bearings -> pixels misses by {gap:.3g} px): no SIP fit"
        )
    centre = np.array([camera.cx, camera.cy])
    # exact pairs: distorted offsets recomputed from the bearings by the forward model
    d = distorted - centre
    u = ideal.bearings_to_pixels(bearings) - centre
    scale = float(np.max(np.abs(d))) or 1.0
    a, b, error = _fit(d, u - d, order, 2, scale)
    ap, bp, inverse_error = _fit(u, d - u, order, 1, scale)
    return SipFit(
        order=order,
        a=a,
        b=b,
        ap=ap,
        bp=bp,
        max_error_px=error,
        max_inverse_error_px=inverse_error,
        max_distortion_px=float(np.max(np.linalg.norm(u - d, axis=1))),
    )


def choose_sip_order(
    camera: CameraModel,
    *,
    max_error_px: float = SIP_GOOD_ENOUGH_PX,
    highest: int | None = None,
) -> int:
    """The lowest SIP order from ``DEFAULT_SIP_ORDER`` up whose fit of the camera's
    distortion is good to ``max_error_px`` over the image (wide fields need more), at most
    ``highest`` (None: its model's ``sip_max_order``, 7 for a pinhole, 9 for
    Kannala-Brandt); ``DEFAULT_SIP_ORDER`` for a camera without distortion."""
    if highest is None:
        highest = camera.sip_max_order
    order = DEFAULT_SIP_ORDER
    while camera.distorted and order < highest:
        if fit_sip(camera, order=order).max_error_px <= max_error_px:
            break
        order += 1
    return order


def _date_obs(date_obs: str | _dt.datetime | Time) -> Time:
    try:
        return Time(date_obs, scale="utc")
    except ValueError as exc:
        raise StarnavError(f"date_obs {date_obs!r} is not a date and time: {exc}") from None


def wcs_from_attitude(
    R_cam_from_icrs: np.ndarray,
    camera: CameraModel,
    *,
    sip_order: int = DEFAULT_SIP_ORDER,
    date_obs: str | _dt.datetime | Time | None = None,
) -> WCS:
    """Celestial WCS (ICRS, degrees) of an image taken by ``camera`` at ``R_cam_from_icrs``.

    The projection of the camera's lens model (``projection``: pinhole TAN, equidistant ARC,
    stereographic STG, equisolid ZEA, orthographic SIN, Kannala-Brandt ARC-SIP; all exact but
    the SIP polynomials), with SIP of degree ``sip_order`` when the camera has distortion (see
    ``fit_sip`` for the fit error; ``choose_sip_order`` picks one). ``date_obs``: UTC time of
    the exposure (ISO string, datetime or astropy Time), written as DATE-OBS and MJD-OBS. The
    WCS's ``pixel_shape`` is (width, height). With astropy's 0-based pixel methods, pixel =
    starnav pixel - 0.5.
    """
    R = _check_attitude(R_cam_from_icrs)
    _check_order(sip_order)
    code = projection(camera)
    z = R[2]
    ra_rad, dec_rad = unit_to_radec(z)
    north, east = north_east(z)
    # intermediate world coordinates of a direction s at θ from the axis: R_θ (s.E, s.N) / sin θ
    # (toward East, North), R_θ = (180/π) g(θ); with c = R s and s = R^T c (R orthogonal,
    # either parity) that is (R E, R N).(c_x, c_y) / sin θ, and (c_x, c_y) / sin θ times f g(θ)
    # is the pixel offset of the undistorted camera.
    cd = np.degrees(1.0 / camera.focal_px) * np.array(
        [[R[0] @ east, R[1] @ east], [R[0] @ north, R[1] @ north]]
    )
    distorted = camera.distorted
    suffix = "-SIP" if distorted else ""
    header = fits.Header()
    header["WCSAXES"] = 2
    header["CTYPE1"] = f"RA---{code}{suffix}"
    header["CTYPE2"] = f"DEC--{code}{suffix}"
    header["CUNIT1"] = "deg"
    header["CUNIT2"] = "deg"
    header["CRPIX1"] = (float(camera.cx) + 0.5, "principal point x (FITS: first pixel centre 1)")
    header["CRPIX2"] = (float(camera.cy) + 0.5, "principal point y")
    header["CRVAL1"] = (float(np.degrees(ra_rad)), "RA of the camera z axis (deg)")
    header["CRVAL2"] = (float(np.degrees(dec_rad)), "Dec of the camera z axis (deg)")
    for i in range(2):
        for j in range(2):
            header[f"CD{i + 1}_{j + 1}"] = float(cd[i, j])
    # 180 is the zenithal default except at Dec = +90 exactly, where the CD matrix above
    # (East and North taken at RA = CRVAL1) still needs it; every projection here is zenithal
    header["LONPOLE"] = 180.0
    header["RADESYS"] = "ICRS"
    if date_obs is not None:
        when = _date_obs(date_obs)
        header["DATE-OBS"] = (when.isot, "UTC")
        header["MJD-OBS"] = float(when.mjd)
    if distorted:
        sip = fit_sip(camera, order=sip_order)
        polynomials = (("A", sip.a), ("B", sip.b), ("AP", sip.ap), ("BP", sip.bp))
        for name, coef in polynomials:
            header[f"{name}_ORDER"] = sip.order
            for p, q in zip(*np.nonzero(coef), strict=True):
                header[f"{name}_{p}_{q}"] = float(coef[p, q])  # absent terms are 0
    wcs = WCS(header)
    wcs.pixel_shape = (camera.width, camera.height)
    return wcs


def _fits_image(image: np.ndarray, wcs: WCS) -> np.ndarray:
    data = np.asarray(image)
    if data.ndim != 2:
        raise ImageError(f"image for the FITS file must be 2-D (height, width), got {data.shape}")
    if wcs.pixel_shape is not None and data.shape[::-1] != tuple(wcs.pixel_shape):
        width, height = wcs.pixel_shape
        raise ImageError(
            f"image shape {data.shape} does not match the WCS image size "
            f"(height {height}, width {width})"
        )
    if data.dtype == bool:
        return data.astype(np.uint8)
    if data.dtype.kind not in "uif":
        raise ImageError(f"image must hold numbers, got dtype {data.dtype}")
    if data.dtype == np.float16:
        return data.astype(np.float32)
    return data


# cards of an image's own header that the WCS written replaces, or that the data written
# sets (its structure and scaling)
_REPLACED = re.compile(
    r"^(SIMPLE|BITPIX|NAXIS\d*|EXTEND|BSCALE|BZERO|BLANK|PCOUNT|GCOUNT|XTENSION|WCSAXES|"
    r"CRPIX\d|CRVAL\d|CDELT\d|CTYPE\d|CUNIT\d|CROTA\d|CD\d_\d|PC\d_\d|LONPOLE|LATPOLE|"
    r"RADESYS|RADECSYS|EQUINOX|EPOCH|IMAGEW|IMAGEH|(A|B|AP|BP)_(ORDER|\d+_\d+|DMAX)|"
    r"PV\d_\d+|MJDREF|DATEREF)$"
)


def write_wcs(
    path: str | Path,
    wcs: WCS,
    *,
    image: np.ndarray | None = None,
    extra_header: fits.Header | None = None,
) -> None:
    """Write the WCS as a FITS file (overwriting ``path``).

    Without ``image``: a header-only file like astrometry.net's ``wcs.fits`` (with IMAGEW and
    IMAGEH, the image size in pixels). With ``image`` (2-D numpy array, row 0 = FITS y = 1):
    the image as the primary data unit under the same header. ``extra_header``: the image's
    own header, whose cards (but its WCS, structure and scaling) are kept after the WCS.
    """
    header = wcs.to_header(relax=True)
    if wcs.wcs.has_cd() and "PC1_1" in header:
        # astropy writes PCi_j with CDELT = 1; CDi_j is what astrometry.net and older readers use
        cdelt = np.array([header.pop(f"CDELT{i}", 1.0) for i in (1, 2)])
        for i in range(2):
            for j in range(2):
                header[f"CD{i + 1}_{j + 1}"] = cdelt[i] * header.pop(
                    f"PC{i + 1}_{j + 1}", float(i == j)
                )
    if header.get("RADESYS") == "ICRS" and "EQUINOX" not in header:
        # meaningless for ICRS (WCSLIB drops it) but read by tools that predate RADESYS
        header.insert(
            "RADESYS", ("EQUINOX", 2000.0, "ICRS axes, J2000 for old readers"), after=True
        )
    if wcs.pixel_shape is not None:
        header["IMAGEW"] = (int(wcs.pixel_shape[0]), "image width (px)")
        header["IMAGEH"] = (int(wcs.pixel_shape[1]), "image height (px)")
    for card in extra_header.cards if extra_header is not None else ():
        if card.keyword in ("HISTORY", "COMMENT", ""):
            header.append(card)
        elif not _REPLACED.match(card.keyword) and card.keyword not in header:
            header.append(card)
    header["HISTORY"] = "WCS written by starnav"
    data = None if image is None else _fits_image(image, wcs)
    hdu = fits.PrimaryHDU(data=data, header=header)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", fits.verify.VerifyWarning)  # long SIP comments
            hdu.writeto(path, overwrite=True)
    except OSError as exc:
        raise StarnavError(f"cannot write WCS file {str(path)!r}: {exc}") from None
