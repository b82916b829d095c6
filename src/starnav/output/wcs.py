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
from functools import cached_property
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


def fit_points(camera: CameraModel) -> np.ndarray:
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
    pixels of ``fit_points`` (a grid over the image, within its image circle). A radial model
    has odd terms only, so an even order fits as well as the odd order below it; the pinhole's
    inverse AP/BP is exact once order >= 3 (k1 only) or 5 (with k2).
    """
    order = _check_order(order)
    ideal = _undistorted(camera)
    grid = fit_points(camera)
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
    north, east = north_east(z)
    # intermediate world coordinates of a direction s at θ from the axis: R_θ (s.E, s.N) / sin θ
    # (toward East, North), R_θ = (180/π) g(θ); with c = R s and s = R^T c (R orthogonal,
    # either parity) that is (R E, R N).(c_x, c_y) / sin θ, and (c_x, c_y) / sin θ times f g(θ)
    # is the pixel offset of the undistorted camera.
    cd = np.degrees(1.0 / camera.focal_px) * np.array(
        [[R[0] @ east, R[1] @ east], [R[0] @ north, R[1] @ north]]
    )
    distorted = camera.distorted
    header = _celestial_header(
        code + ("-SIP" if distorted else ""),
        (float(camera.cx) + 0.5, float(camera.cy) + 0.5),
        z,
        cd,
        date_obs,
        ("principal point x (FITS: first pixel centre 1)", "RA of the camera z axis (deg)"),
    )
    if distorted:
        sip = fit_sip(camera, order=sip_order)
        _add_sip(header, sip.order, sip.a, sip.b, sip.ap, sip.bp)
    wcs = WCS(header)
    wcs.pixel_shape = (camera.width, camera.height)
    return wcs


def _celestial_header(
    ctype: str,
    crpix_fits: tuple[float, float],
    reference: np.ndarray,
    cd: np.ndarray,
    date_obs,
    notes: tuple[str, str] = ("reference pixel x (FITS: first pixel centre 1)", "RA (deg)"),
) -> fits.Header:
    """The cards of a zenithal celestial WCS: projection ``ctype`` ("TAN", "TAN-SIP", ...),
    CRPIX (FITS pixels), CRVAL the sky direction ``reference`` (unit vector), the CD matrix
    (deg/px), DATE-OBS / MJD-OBS when ``date_obs`` is given."""
    ra_rad, dec_rad = unit_to_radec(reference)
    header = fits.Header()
    header["WCSAXES"] = 2
    header["CTYPE1"] = f"RA---{ctype}"
    header["CTYPE2"] = f"DEC--{ctype}"
    header["CUNIT1"] = "deg"
    header["CUNIT2"] = "deg"
    header["CRPIX1"] = (float(crpix_fits[0]), notes[0])
    header["CRPIX2"] = (float(crpix_fits[1]), notes[0].split(" x")[0] + " y")
    header["CRVAL1"] = (float(np.degrees(ra_rad)), notes[1])
    header["CRVAL2"] = (float(np.degrees(dec_rad)), notes[1].replace("RA", "Dec", 1))
    for i in range(2):
        for j in range(2):
            header[f"CD{i + 1}_{j + 1}"] = float(cd[i, j])
    # 180 is the zenithal default except at Dec = +90 exactly, where the CD matrix (East and
    # North taken at RA = CRVAL1) still needs it; every projection here is zenithal
    header["LONPOLE"] = 180.0
    header["RADESYS"] = "ICRS"
    if date_obs is not None:
        when = _date_obs(date_obs)
        header["DATE-OBS"] = (when.isot, "UTC")
        header["MJD-OBS"] = float(when.mjd)
    return header


def _add_sip(header: fits.Header, order: int, a, b, ap, bp, inverse_order: int | None = None):
    polynomials = (("A", a, order), ("B", b, order))
    polynomials += (("AP", ap, inverse_order or order), ("BP", bp, inverse_order or order))
    for name, coef, n in polynomials:
        header[f"{name}_ORDER"] = n
        for p, q in zip(*np.nonzero(coef), strict=True):
            header[f"{name}_{p}_{q}"] = float(coef[p, q])  # absent terms are 0


@dataclass(frozen=True, eq=False)
class StarFitWcs:
    """A TAN or TAN-SIP WCS fitted to matched stars (``fit_wcs_to_stars``).

    ``order``: its polynomial order, 1 for a plain TAN (no SIP terms were measurable), 2..4
    for TAN-SIP; ``n_stars``: the stars fitted; ``residual_px``: (n, 2) each star's catalog
    position through the WCS (sky to pixel, the forward polynomials inverted by Newton's
    method) minus its measured one, starnav px; ``rms_px``: their rms length; ``p_values``:
    the F-test's p-value of each order tried beyond the one before it (order: p), the test
    that chose ``order``; ``crval_vector``: CRVAL (the sky at CRPIX) as an ICRS unit vector;
    ``cd``: the CD matrix (deg/px); ``a``, ``b``: SIP's A and B (px); ``crpix_px``: CRPIX,
    starnav px. Built when first asked for: ``wcs``, the WCS (astropy; ``pixel_shape``
    (width, height)), with ``inverse_order`` and ``max_inverse_error_px``, the order of AP/BP
    and their largest error over the image.
    """

    order: int
    n_stars: int
    residual_px: np.ndarray
    rms_px: float
    p_values: dict
    crval_vector: np.ndarray
    cd: np.ndarray
    a: np.ndarray
    b: np.ndarray
    crpix_px: np.ndarray
    shape: tuple[int, int]  # (width, height), px
    date_obs: str | _dt.datetime | Time | None = None

    @cached_property
    def _inverse(self) -> tuple[int, np.ndarray, np.ndarray, float]:
        if self.order < 2:
            return self.order, np.zeros_like(self.a), np.zeros_like(self.b), 0.0
        return _fit_inverse(self.a, self.b, self.order, self.crpix_px, *self.shape)

    @property
    def inverse_order(self) -> int:
        return self._inverse[0]

    @property
    def max_inverse_error_px(self) -> float:
        return self._inverse[3]

    @cached_property
    def wcs(self) -> WCS:
        ctype = "TAN-SIP" if self.order >= 2 else "TAN"
        header = _celestial_header(ctype, tuple(self.crpix_px + 0.5), self.crval_vector, self.cd,
                                   self.date_obs)  # fmt: skip
        if self.order >= 2:
            inverse_order, ap, bp, _ = self._inverse
            _add_sip(header, self.order, self.a, self.b, ap, bp, inverse_order)
        wcs = WCS(header)
        wcs.pixel_shape = tuple(int(n) for n in self.shape)
        return wcs

    def pixels(self, vectors_icrs: np.ndarray) -> np.ndarray:
        """Where the WCS puts ICRS unit vectors (n, 3): (n, 2) starnav px (A/B inverted by
        Newton's method, as the residuals are measured); NaN for a direction 90° or more from
        CRVAL."""
        vectors = np.asarray(vectors_icrs, float).reshape(-1, 3)
        return _sky_to_pixels(self.crval_vector, self.cd, self.a, self.b, self.crpix_px, vectors)

    def directions(self, xy_px: np.ndarray) -> np.ndarray:
        """The ICRS unit vectors (n, 3) the WCS gives pixels ``xy_px`` (n, 2), starnav px."""
        uv = np.asarray(xy_px, float).reshape(-1, 2) - self.crpix_px
        uv = uv + np.column_stack([_sip_eval(self.a, uv), _sip_eval(self.b, uv)])
        north, east = north_east(self.crval_vector)
        xi, eta = np.radians(uv @ self.cd.T).T
        v = self.crval_vector + xi[:, None] * east + eta[:, None] * north
        return v / np.linalg.norm(v, axis=1, keepdims=True)


STAR_FIT_MAX_ORDER = 4
STAR_FIT_P_VALUE = 0.001  # an order's extra terms are kept when chance would do as well this rarely
STAR_FIT_STARS_PER_TERM = 2  # stars per polynomial term of one axis, at least
_TANGENT_ITERATIONS = 8
# per image axis: the grid AP/BP are fitted on (441 points for at most 55 terms of order 9;
# the 41 x 41 grid of a lens model's fit took ~10 ms a least-squares solve here)
INVERSE_GRID_POINTS = 21


def _n_terms(order: int) -> int:
    """Terms of one axis's polynomial of degrees 0..order (the constant is CRVAL's)."""
    return (order + 1) * (order + 2) // 2


def _gnomonic_deg(vectors: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Intermediate world coordinates (n, 2), degrees toward East and North, of unit vectors
    in the TAN projection about ``reference``; NaN for a direction 90° or more away."""
    north, east = north_east(reference)
    depth = vectors @ reference
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.degrees(np.column_stack([vectors @ east, vectors @ north]) / depth[:, None])
    out[depth <= 0] = np.nan
    return out


def _moved(reference: np.ndarray, offset_deg: np.ndarray) -> np.ndarray:
    """The direction at TAN coordinates ``offset_deg`` (East, North) about ``reference``."""
    north, east = north_east(reference)
    xi, eta = np.radians(offset_deg)
    v = reference + xi * east + eta * north
    return v / np.linalg.norm(v)


def _star_poly(uv: np.ndarray, world: np.ndarray, order: int, scale: float, vectors, reference):
    """Least squares of world (TAN, deg) on pixel offsets, degrees 0..order, the tangent point
    moved until the constant term vanishes: (reference, coefficients (terms, 2) of degrees
    1..order in scaled units, residual sum of squares in deg²)."""
    terms = _terms(order, 1)
    design = _design(uv, terms, scale)
    with_constant = np.column_stack([np.ones(len(uv)), design])
    for _ in range(_TANGENT_ITERATIONS):
        coef, *_ = np.linalg.lstsq(with_constant, world, rcond=None)
        if np.max(np.abs(coef[0])) < 1e-12:
            break
        reference = _moved(reference, coef[0])
        world = _gnomonic_deg(vectors, reference)
    coef, *_ = np.linalg.lstsq(design, world, rcond=None)
    rss = float(np.sum((design @ coef - world) ** 2))
    return reference, coef, rss


def _sip_arrays(coef: np.ndarray, terms, order: int, scale: float, cd_inv: np.ndarray):
    """SIP A, B arrays (order + 1, order + 1) from the world polynomial's terms of degree 2
    and up (scaled units): CD^-1 times them, in pixels."""
    a = np.zeros((2, order + 1, order + 1))
    for (p, q), c in zip(terms, coef, strict=True):
        if p + q >= 2:
            a[:, p, q] = cd_inv @ c / scale ** (p + q)
    return a[0], a[1]


def _sip_eval(a: np.ndarray, uv: np.ndarray) -> np.ndarray:
    u, v = uv[:, 0], uv[:, 1]
    n = a.shape[0]
    return sum(a[p, q] * u**p * v**q for p in range(n) for q in range(n - p) if a[p, q])


def _sip_jacobian(a: np.ndarray, b: np.ndarray, uv: np.ndarray) -> np.ndarray:
    u, v = uv[:, 0], uv[:, 1]
    jac = np.zeros((len(uv), 2, 2))
    jac[:, 0, 0] = jac[:, 1, 1] = 1.0
    n = a.shape[0]
    for p in range(n):
        for q in range(n - p):
            du = p * u ** max(p - 1, 0) * v**q
            dv = q * u**p * v ** max(q - 1, 0)
            jac[:, 0, 0] += a[p, q] * du
            jac[:, 0, 1] += a[p, q] * dv
            jac[:, 1, 0] += b[p, q] * du
            jac[:, 1, 1] += b[p, q] * dv
    return jac


def _sky_to_pixels(reference, cd, a, b, crpix, vectors, start_px=None) -> np.ndarray:
    """Starnav px (n, 2) of ICRS unit vectors (n, 3) through TAN about ``reference`` with
    ``cd`` and SIP's ``a``, ``b`` about ``crpix``, A/B inverted by Newton's method from
    ``start_px`` (None: the plain TAN's pixels); NaN for a direction 90° or more away."""
    target = (np.linalg.inv(cd) @ _gnomonic_deg(vectors, reference).T).T
    out = np.full_like(target, np.nan)
    ok = np.isfinite(target).all(axis=1)
    if ok.any():
        start = target[ok] if start_px is None else start_px[ok] - crpix
        out[ok] = _invert_sip(a, b, target[ok], start) + crpix
    return out


def _invert_sip(a, b, target: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Pixel offsets uv with uv + (A, B)(uv) = ``target`` (Newton from ``start``)."""
    uv = start.astype(float).copy()
    for _ in range(50):
        gap = uv + np.column_stack([_sip_eval(a, uv), _sip_eval(b, uv)]) - target
        step = np.linalg.solve(_sip_jacobian(a, b, uv), gap[..., None])[..., 0]
        uv -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return uv


def fit_wcs_to_stars(
    xy_px: np.ndarray,
    vectors_icrs: np.ndarray,
    width: int,
    height: int,
    *,
    crpix_px: tuple[float, float] | None = None,
    start: np.ndarray | None = None,
    max_order: int = STAR_FIT_MAX_ORDER,
    date_obs: str | _dt.datetime | Time | None = None,
) -> StarFitWcs:
    """A TAN or TAN-SIP WCS fitted to matched stars, as astrometry.net's tweak does.

    ``xy_px``: (n, 2) measured positions (starnav px: origin at the top-left corner);
    ``vectors_icrs``: (n, 3) the catalog unit vectors of the same stars; ``width``,
    ``height``: the image (px); ``crpix_px``: the reference pixel (starnav px; None: the
    image centre); ``start``: a unit vector near the field (None: the stars' mean).

    The stars' TAN coordinates about CRVAL are fitted by polynomials in their pixel offsets
    from CRPIX (least squares, pixel offsets scaled to ~1), CRVAL moved until the constant term
    vanishes (it is the sky at CRPIX): the linear terms are the CD matrix, the higher ones CD
    times SIP's A and B. The order (1 = plain TAN, up to ``max_order``) is chosen by F-tests on
    the residual sums of squares: an order is tried when there are at least
    ``STAR_FIT_STARS_PER_TERM`` stars per term of one axis, and kept when its extra terms
    lower the residuals more than chance would with p < ``STAR_FIT_P_VALUE`` against the order
    kept before it. AP/BP (the inverse, order + 1, or more until good to 0.01 px, at most
    ``MAX_SIP_ORDER``) are fitted on a grid over the whole image, corners included. At least
    3 stars not on a line are needed (``StarnavError``).
    """
    xy = np.asarray(xy_px, dtype=float).reshape(-1, 2)
    vectors = np.asarray(vectors_icrs, dtype=float).reshape(-1, 3)
    if len(xy) != len(vectors):
        raise StarnavError(f"{len(xy)} star positions but {len(vectors)} catalog vectors")
    if len(xy) < 3 or not (np.isfinite(xy).all() and np.isfinite(vectors).all()):
        raise StarnavError(f"a WCS fit needs at least 3 stars with finite positions, got {len(xy)}")
    vectors = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    crpix = np.array((width / 2.0, height / 2.0) if crpix_px is None else crpix_px, dtype=float)
    uv = xy - crpix
    scale = max(width, height) / 2.0
    reference = vectors.mean(axis=0) if start is None else np.asarray(start, dtype=float)
    reference = reference / np.linalg.norm(reference)
    world = _gnomonic_deg(vectors, reference)
    if not np.isfinite(world).all():
        raise StarnavError("the stars of a WCS fit must lie within 90° of the field centre")
    n = len(xy)
    from scipy.special import fdtrc  # survival function of the F distribution

    order = 1
    best = _star_poly(uv, world, 1, scale, vectors, reference)
    p_values: dict[int, float] = {}
    for candidate in range(2, max_order + 1):
        if n < STAR_FIT_STARS_PER_TERM * _n_terms(candidate):
            break
        trial = _star_poly(uv, world, candidate, scale, vectors, best[0])
        extra = 2 * (_n_terms(candidate) - _n_terms(order))
        dof = 2 * (n - _n_terms(candidate))
        if trial[2] <= 0.0:
            p = 0.0
        else:
            statistic = ((best[2] - trial[2]) / extra) / (trial[2] / dof)
            p = float(fdtrc(extra, dof, statistic))
        p_values[candidate] = p
        if p < STAR_FIT_P_VALUE:
            order, best = candidate, trial
    reference, coef, _ = best
    terms = _terms(order, 1)
    cd = (coef[:2] / scale).T  # rows: world axes; columns: u, v
    if not abs(np.linalg.det(cd)) > 1e-6 * np.sum(cd**2):
        raise StarnavError("the stars of a WCS fit lie on a line: no CD matrix follows")
    a, b = _sip_arrays(coef, terms, order, scale, np.linalg.inv(cd))
    # the residuals as a reader of the file sees them: sky -> pixel, A/B inverted exactly
    try:
        fitted = _sky_to_pixels(reference, cd, a, b, crpix, vectors, start_px=xy)
    except np.linalg.LinAlgError:
        raise StarnavError("the fitted SIP polynomials cannot be inverted at the stars") from None
    residual = fitted - xy
    rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    return StarFitWcs(order, n, residual, rms, p_values, reference, cd, a, b, crpix,
                      (int(width), int(height)), date_obs)  # fmt: skip


def _fit_inverse(a, b, order: int, crpix: np.ndarray, width: int, height: int):
    """AP/BP for A/B over a grid on the image (corners included): the lowest order from
    order + 1 whose largest error is under ``SIP_GOOD_ENOUGH_PX`` (at most ``MAX_SIP_ORDER``):
    (order, ap, bp, largest error px)."""
    gx, gy = np.meshgrid(
        np.linspace(0.0, width, INVERSE_GRID_POINTS), np.linspace(0.0, height, INVERSE_GRID_POINTS)
    )
    uv = np.column_stack([gx.ravel(), gy.ravel()]) - crpix
    undistorted = uv + np.column_stack([_sip_eval(a, uv), _sip_eval(b, uv)])
    scale = float(np.max(np.abs(undistorted))) or 1.0
    best = None
    for inverse_order in range(min(order + 1, MAX_SIP_ORDER), MAX_SIP_ORDER + 1):
        ap, bp, error = _fit(undistorted, uv - undistorted, inverse_order, 1, scale)
        if best is None or error < best[3]:
            best = (inverse_order, ap, bp, error)
        if error <= SIP_GOOD_ENOUGH_PX:
            break
    return best


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
