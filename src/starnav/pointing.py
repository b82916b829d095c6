"""Three-star pointing: the boresight from three known stars (problem 1 of the 2019 contest).

For star unit vectors u_i and their image distances a_i from the principal point, the
boresight d satisfies u_i . d = cos(theta_i) = f / sqrt(a_i^2 + f^2). With the focal length f
known the three equations are linear in d (``U d = c``); |d| - 1 measures how consistent the
data are. With f unknown, |d(f)| = 1 is one equation in f, solved by bracketing every sign
change of |d(f)|^2 - 1 on a fine logarithmic grid (and around every turning point of the
curve) and refining each with Brent's method, so all solutions are found and none depends on
a starting value; with x,y the inter-star angles, which also depend on f, tell them apart.

Error propagation is analytic: d depends on the centroids through a_i; the Jacobian gives the
covariance of the unit boresight for a centroid noise sigma_px (per axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from itertools import combinations

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from starnav.errors import PointingError, shown
from starnav.geometry import (
    ARCSEC_PER_RAD,
    angle_between,
    attitude_from_radec_roll,
    radec_to_unit,
    unit_to_radec,
)

# flatness |det U| / (2 x longest chord^2): 0.43 for an equilateral triangle, 0 on a line;
# below this the triple is "nearly collinear" (the equations do not fix a direction)
MIN_FLATNESS = 1e-4
POOR_FOCAL_PER_PX = 0.01  # relative focal error per px of distance error called "poor"
MAX_INCONSISTENCY = 0.2  # | |d| - 1 | beyond this: the data cannot be one camera's view
FOCAL_RANGE_PX = (1.0, 1e7)  # focal lengths accepted and searched
MAX_OFF_AXIS_DEG = 89.5  # a camera cannot see a star farther than this from its boresight
MAX_BEST_TRIPLE_STARS = 40  # --select-best considers this many stars (9880 triples)
_F_GRID = np.geomspace(*FOCAL_RANGE_PX, 20000)  # grid on which roots in f are bracketed


@dataclass(frozen=True)
class Pointing:
    """One boresight solution.

    ``ra_deg``/``dec_deg``: boresight; ``roll_deg``: position angle of image up (None without
    x,y); ``focal_px``: given or solved; ``consistency``: |d| - 1 of the linear solution
    (0 for exact data; with f solved it is 0 by construction); ``sigma_boresight_arcsec``:
    1-sigma boresight error from the analytic covariance (None without sigma_px);
    ``alternatives``: other (focal, boresight) solutions that fit as well;
    ``fit_rms_px``: with x,y, rms difference (px) between the measured and the catalog
    inter-star angles; ``parity``: +1 / -1 (found from x,y when not
    given; None with distances only);
    ``sigma_focal_px``: 1-sigma of a solved focal length (None when given or without
    sigma_px). With f solved, ``sigma_boresight_arcsec`` includes its error.
    """

    ra_deg: float
    dec_deg: float
    roll_deg: float | None
    focal_px: float
    consistency: float
    sigma_boresight_arcsec: float | None
    boresight: np.ndarray = field(repr=False)
    alternatives: tuple[Pointing, ...] = ()
    note: str = ""
    fit_rms_px: float | None = None
    sigma_focal_px: float | None = None
    parity: int | None = None

    def to_dict(self) -> dict:
        keys = (
            "ra_deg",
            "dec_deg",
            "roll_deg",
            "focal_px",
            "consistency",
            "sigma_boresight_arcsec",
            "sigma_focal_px",
            "fit_rms_px",
            "parity",
        )
        out = {k: getattr(self, k) for k in keys}
        out["alternatives"] = [a.to_dict() for a in self.alternatives]
        out["note"] = self.note
        return out


def _cos_theta(a_px: np.ndarray, focal_px: float) -> np.ndarray:
    return focal_px / np.sqrt(a_px**2 + focal_px**2)


def linear_boresight(U: np.ndarray, a_px: np.ndarray, focal_px: float) -> np.ndarray:
    """d solving U d = cos(theta) (not normalised; |d| = 1 for consistent data)."""
    return np.linalg.solve(U, _cos_theta(a_px, focal_px))


def _jacobians(U: np.ndarray, a_px: np.ndarray, focal_px: float, focal_free: bool):
    """(d d_hat / d a (3x3), d f / d a (3,)) at a solution; with the focal length free it
    moves with the data so that |d| stays 1 (implicit function theorem)."""
    d = linear_boresight(U, a_px, focal_px)
    r3 = (a_px**2 + focal_px**2) ** 1.5
    dc_da = -focal_px * a_px / r3
    dc_df = a_px**2 / r3
    Uinv = np.linalg.inv(U)
    df_da = np.zeros(3)
    if focal_free:
        dg_da = 2.0 * (d @ Uinv) * dc_da  # g = |d|^2 - 1
        dg_df = 2.0 * d @ (Uinv @ dc_df)
        df_da = -dg_da / dg_df if dg_df != 0 else np.full(3, np.inf)
    J = Uinv @ (np.diag(dc_da) + np.outer(dc_df, df_da))
    norm = np.linalg.norm(d)
    d_hat = d / norm
    return (np.eye(3) - np.outer(d_hat, d_hat)) @ J / norm, df_da


def boresight_covariance(
    U: np.ndarray,
    a_px: np.ndarray,
    focal_px: float,
    sigma_a_px: np.ndarray,
    *,
    focal_free: bool = False,
) -> np.ndarray:
    """3x3 covariance of the unit boresight from independent errors of a_i (1-sigma, px).

    A centroid error of sigma per axis gives a radial error sigma on a_i (only the radial
    component changes a_i to first order). ``focal_free``: the focal length was solved from
    the same data, so its error adds to the boresight's.
    """
    J_hat, _ = _jacobians(U, a_px, focal_px, focal_free)
    return J_hat @ np.diag(np.asarray(sigma_a_px, dtype=float) ** 2) @ J_hat.T


def sigma_boresight_arcsec(
    U: np.ndarray, a_px: np.ndarray, focal_px: float, sigma_px: float, *, focal_free=False
) -> float:
    """1-sigma total boresight error (arcsec) for centroid noise ``sigma_px`` per axis."""
    cov = boresight_covariance(U, a_px, focal_px, np.full(3, sigma_px), focal_free=focal_free)
    return float(np.sqrt(np.trace(cov)) * ARCSEC_PER_RAD)


def sigma_focal_px(U: np.ndarray, a_px: np.ndarray, focal_px: float, sigma_px: float) -> float:
    """1-sigma of a focal length solved from three stars' distances (px)."""
    _, df_da = _jacobians(U, a_px, focal_px, True)
    return float(np.sqrt(np.sum(df_da**2)) * sigma_px)


def _project_offsets(d_hat, roll_deg, parity, U, focal_px) -> np.ndarray:
    """Pixel offsets from the principal point of the stars ``U`` at a given attitude."""
    ra, dec = unit_to_radec(d_hat)
    R = attitude_from_radec_roll(np.degrees(ra), np.degrees(dec), roll_deg, parity)
    c = U @ R.T
    return focal_px * c[:, :2] / c[:, 2:3]


def _roll_deg(d_hat, U, xy_offsets, focal_px, parity) -> float:
    """Roll that best turns the stars' predicted image offsets onto the measured ones."""
    p = _project_offsets(d_hat, 0.0, parity, U, focal_px)
    m = xy_offsets
    # image-plane rotation taking p to m (2-D Procrustes); roll turns the image one way or
    # the other depending on parity: keep the sign that reproduces the measurements
    phi = np.degrees(np.arctan2(np.sum(p[:, 0] * m[:, 1] - p[:, 1] * m[:, 0]), np.sum(p * m)))
    rolls = [phi % 360.0, -phi % 360.0]
    misfit = [np.sum((_project_offsets(d_hat, r, parity, U, focal_px) - m) ** 2) for r in rolls]
    return float(rolls[int(np.argmin(misfit))])


def flatness(U: np.ndarray) -> np.ndarray | float:
    """|det U| / (2 x longest chord^2) of star triples ``U`` (..., 3, 3): a scale-free shape
    measure, 0.43 for an equilateral triangle and 0 for stars on a great circle."""
    U = np.asarray(U, dtype=float)
    chords = np.linalg.norm(U[..., [0, 0, 1], :] - U[..., [1, 2, 2], :], axis=-1)
    shape = np.abs(np.linalg.det(U)) / (2.0 * chords.max(axis=-1) ** 2)
    return float(shape) if shape.ndim == 0 else shape


def _check_stars(ra_deg, dec_deg) -> np.ndarray:
    """Unit vectors (3, 3) of three distinct, not collinear stars."""
    ra = np.asarray(ra_deg, dtype=float).reshape(-1)
    dec = np.asarray(dec_deg, dtype=float).reshape(-1)
    if len(ra) != 3 or len(dec) != 3:
        raise PointingError(f"three-star pointing needs exactly 3 stars, got {len(ra)}")
    if not (np.isfinite(ra).all() and np.isfinite(dec).all()):
        raise PointingError("ra_deg/dec_deg must be finite numbers")
    if (np.abs(dec) > 90).any():
        raise PointingError(f"dec_deg must be within ±90, got {dec.tolist()}")
    U = radec_to_unit(np.radians(ra), np.radians(dec))
    chords = [np.linalg.norm(U[i] - U[j]) for i, j in combinations(range(3), 2)]
    for (i, j), chord in zip(combinations(range(3), 2), chords, strict=True):
        if chord < 1e-12:
            raise PointingError(f"stars {i + 1} and {j + 1} are the same star")
    shape = flatness(U)
    if shape < MIN_FLATNESS:
        raise PointingError(
            f"the three stars are (nearly) collinear on the sky (flatness {shape:.1e}, "
            "equilateral 0.43): their boresight equations do not determine a direction"
        )
    return U


def _check_image(xy, r_px, width, height) -> tuple[np.ndarray | None, np.ndarray]:
    """(offsets from the principal point or None, distances a_i) from xy or r_px."""
    if (xy is None) == (r_px is None):
        raise PointingError("give either xy (pixel positions) or r_px (distances), not both")
    for name, value in (("width", width), ("height", height)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise PointingError(f"{name} must be a positive number of pixels, got {shown(value)}")
    offsets = None
    if xy is not None:
        xy = np.asarray(xy, dtype=float)
        if xy.shape != (3, 2) or not np.isfinite(xy).all():
            raise PointingError(f"xy must be 3 finite (x, y) pairs, got shape {xy.shape}")
        if width is None:
            raise PointingError("with x,y give the image width (and height, default width)")
        height = width if height is None else height
        offsets = xy - [width / 2.0, height / 2.0]
        a = np.hypot(*offsets.T)
    else:
        a = np.asarray(r_px, dtype=float).reshape(-1)
        if len(a) != 3 or not np.isfinite(a).all() or (a < 0).any():
            raise PointingError(f"r_px must be 3 distances >= 0, got {np.asarray(r_px).tolist()}")
    if width is not None:
        height = width if height is None else height
        half_diag = 0.5 * np.hypot(width, height)
        if (a > half_diag * (1 + 1e-9)).any():
            raise PointingError(
                f"a star is {a.max():.1f} px from the centre, beyond the "
                f"{width:g} x {height:g} image (half diagonal {half_diag:.1f} px)"
            )
    return offsets, a


def three_star(
    ra_deg,
    dec_deg,
    *,
    xy=None,
    r_px=None,
    focal_px: float | None = None,
    width: float | None = None,
    height: float | None = None,
    sigma_px: float | None = None,
    parity: int | None = None,
) -> Pointing:
    """Boresight from exactly three stars at (``ra_deg``, ``dec_deg``) (degrees, ICRS).

    ``xy``: their pixel positions (3, 2; origin top-left; principal point (W/2, H/2), so
    ``width`` is needed, ``height`` defaults to it) or ``r_px``: their distances from the
    principal point. ``focal_px``: known focal length; None solves for it (all solutions).
    ``sigma_px``: centroid noise per axis, for the analytic 1-sigma errors. ``parity``: +1
    (sky as seen) or -1 (mirrored); None finds it from x,y.

    With x,y the inter-star angles must agree with the catalog's (rms misfit within
    max(5 sigma_px, 2 px), 3 px without sigma_px), otherwise ``PointingError``.
    """
    U = _check_stars(ra_deg, dec_deg)
    offsets, a = _check_image(xy, r_px, width, height)
    if sigma_px is not None and not (np.isfinite(sigma_px) and sigma_px >= 0):
        raise PointingError(f"sigma_px must be >= 0, got {shown(sigma_px)}")
    if parity not in (None, 1, -1):
        raise PointingError(f"parity must be +1, -1 or None, got {shown(parity)}")
    misfit_tol = 3.0 if sigma_px is None else max(5.0 * sigma_px, 2.0)
    if focal_px is not None:
        lo, hi = FOCAL_RANGE_PX
        if not (np.isfinite(focal_px) and lo <= focal_px <= hi):
            raise PointingError(
                f"focal_px must be between {lo:g} and {hi:g}, got {shown(focal_px)}"
            )
        return _with_known_focal(U, a, offsets, float(focal_px), sigma_px, parity, misfit_tol)
    return _with_focal_solved(U, a, offsets, sigma_px, parity, misfit_tol)


def _solution(
    U: np.ndarray,
    a: np.ndarray,
    offsets: np.ndarray | None,
    f: float,
    focal_free: bool,
    sigma_px: float | None,
    parity: int | None,
) -> Pointing:
    """The pointing of stars ``U`` at distances ``a`` (and ``offsets`` from the principal
    point, or None) at focal length ``f`` (``focal_free``: solved from the same data)."""
    d = linear_boresight(U, a, f)
    norm = float(np.linalg.norm(d))
    d_hat = d / norm
    ra, dec = unit_to_radec(d_hat)
    roll, par, misfit = None, parity, None
    if offsets is not None:
        roll, par = _roll_parity(d_hat, U, offsets, f, parity)
        misfit = _angle_misfit_px(U, offsets, f)
    return Pointing(
        ra_deg=float(np.degrees(ra)),
        dec_deg=float(np.degrees(dec)),
        roll_deg=roll,
        focal_px=float(f),
        consistency=norm - 1.0,
        sigma_boresight_arcsec=None
        if sigma_px is None
        else sigma_boresight_arcsec(U, a, f, sigma_px, focal_free=focal_free),
        sigma_focal_px=None
        if sigma_px is None or not focal_free
        else sigma_focal_px(U, a, f, sigma_px),
        boresight=d_hat,
        parity=par,
        fit_rms_px=misfit,
    )


def _misfit_error(p: Pointing, misfit_tol: float) -> PointingError:
    return PointingError(
        f"the pixel positions do not match the star separations: rms angle misfit "
        f"{p.fit_rms_px:.1f} px at focal length {p.focal_px:.1f} px (tolerance "
        f"{misfit_tol:g} px); check the identification and the focal length"
    )


def _with_known_focal(
    U: np.ndarray,
    a: np.ndarray,
    offsets: np.ndarray | None,
    focal_px: float,
    sigma_px: float | None,
    parity: int | None,
    misfit_tol: float,
) -> Pointing:
    """The pointing at a given focal length; ``PointingError`` when the data do not fit it."""
    known = _solution(U, a, offsets, focal_px, False, sigma_px, parity)
    if abs(known.consistency) > MAX_INCONSISTENCY:
        raise PointingError(
            f"the distances do not fit these stars at focal length {focal_px:g} px: the "
            f"boresight equations give |d| = {1 + known.consistency:.3f} (cosines beyond "
            "what the star separations allow); check the identification and focal length"
        )
    if known.fit_rms_px is not None and known.fit_rms_px > misfit_tol:
        raise _misfit_error(known, misfit_tol)
    return known


def _with_focal_solved(
    U: np.ndarray,
    a: np.ndarray,
    offsets: np.ndarray | None,
    sigma_px: float | None,
    parity: int | None,
    misfit_tol: float,
) -> Pointing:
    """The best pointing over every focal length that fits, the others as its alternatives,
    with notes on ambiguity and on how poorly the geometry fixes the focal length."""
    f_min = a.max() / np.tan(np.radians(MAX_OFF_AXIS_DEG))
    roots = [f for f in focal_solutions(U, a) if f >= f_min]
    if not roots:
        raise PointingError(
            "no focal length makes these three stars consistent (|d(f)| never reaches 1): "
            "check the identification and the positions"
        )
    sols = [_solution(U, a, offsets, f, True, sigma_px, parity) for f in roots]
    notes = []
    if offsets is not None:
        # the inter-star angles depend on f too: keep the solutions that reproduce them
        sols.sort(key=lambda p: p.fit_rms_px)
        if sols[0].fit_rms_px > misfit_tol:
            raise _misfit_error(sols[0], misfit_tol)
        sols = [p for p in sols if p.fit_rms_px <= misfit_tol]
        if len(sols) > 1:
            notes.append(f"{len(sols)} focal lengths fit these stars; best fit first")
    else:
        # nothing tells the exact solutions apart: best-conditioned first
        sols.sort(key=lambda p: sigma_boresight_arcsec(U, a, p.focal_px, 1.0, focal_free=True))
        if len(sols) > 1:
            notes.append(
                f"ambiguous: {len(sols)} focal lengths fit the distances exactly and nothing "
                "in them says which is true (x,y would); best-conditioned first"
            )
    # how well this geometry fixes f, per px of error in the distances
    spread = sigma_focal_px(U, a, sols[0].focal_px, 1.0) / sols[0].focal_px
    if not np.isfinite(spread) or spread > POOR_FOCAL_PER_PX:
        notes.append(
            f"this geometry hardly determines the focal length: 1 px of error in the "
            f"distances moves it by {spread:.1%}"
        )
    return replace(sols[0], alternatives=tuple(sols[1:]), note="; ".join(notes))


def _roll_parity(d_hat, U, offsets, focal_px, parity) -> tuple[float, int]:
    """(roll_deg, parity) that best map the stars onto the measured offsets; both parities
    are tried when ``parity`` is None."""
    best = None
    for par in (1, -1) if parity is None else (parity,):
        roll = _roll_deg(d_hat, U, offsets, focal_px, par)
        predicted = _project_offsets(d_hat, roll, par, U, focal_px)
        misfit = float(np.sum((predicted - offsets) ** 2))
        if best is None or misfit < best[2]:
            best = (roll, par, misfit)
    return best[0], best[1]


def _angle_misfit_px(U: np.ndarray, offsets: np.ndarray, focal_px: float) -> float:
    """RMS (px at the focal length) of measured minus catalog inter-star angles: how well
    the pixel positions agree with the star separations, whatever the solve."""
    b = np.column_stack([offsets, np.full(3, focal_px)])
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    i, j = np.array([0, 0, 1]), np.array([1, 2, 2])
    measured = angle_between(b[i], b[j])
    catalog = angle_between(U[i], U[j])
    return float(np.sqrt(np.mean((measured - catalog) ** 2)) * focal_px)


def focal_solutions(U: np.ndarray, a_px: np.ndarray) -> list[float]:
    """All focal lengths f (px, within ``FOCAL_RANGE_PX``) with |d(f)| = 1.

    Sign changes of |d(f)|^2 - 1 on a fine logarithmic grid are bracketed and refined with
    Brent's method; where the curve turns back without changing sign between grid points
    (two close roots, or one where it only touches zero), the turning point is located and
    the roots on either side of it bracketed too.
    """
    Uinv = np.linalg.inv(U)

    def g(f):
        f = np.asarray(f, dtype=float)
        cos = f[..., None] / np.sqrt(a_px**2 + f[..., None] ** 2)
        return np.sum((cos @ Uinv.T) ** 2, axis=-1) - 1.0

    grid = _F_GRID
    v = g(grid)
    # <= 0: a root that falls on a grid point (g = 0 there, or a rounding-sized value of
    # either sign) must not slip between two brackets
    brackets = [(grid[k], grid[k + 1]) for k in np.flatnonzero(v[:-1] * v[1:] <= 0)]
    roots = []
    # turning points: a local minimum above zero or maximum below it may hide two roots
    turn = (
        np.flatnonzero(
            ((v[1:-1] < v[:-2]) & (v[1:-1] <= v[2:]) & (v[1:-1] > 0))
            | ((v[1:-1] > v[:-2]) & (v[1:-1] >= v[2:]) & (v[1:-1] < 0))
        )
        + 1
    )
    for k in turn:
        sign = 1.0 if v[k] > 0 else -1.0
        opt = minimize_scalar(
            lambda f, s=sign: s * float(g(f)),
            bounds=(grid[k - 1], grid[k + 1]),
            method="bounded",
            options={"xatol": 1e-10 * grid[k]},
        )
        extreme = float(g(opt.x))
        if extreme * v[k] < 0:  # crosses zero: a root either side of the turning point
            brackets += [(grid[k - 1], opt.x), (opt.x, grid[k + 1])]
        elif abs(extreme) < 1e-12:  # touches zero: a double root
            roots.append(float(opt.x))
    for lo, hi in brackets:
        g_lo, g_hi = float(g(lo)), float(g(hi))
        if g_lo * g_hi < 0:
            roots.append(brentq(lambda f: float(g(f)), lo, hi, xtol=1e-12, rtol=1e-14))
        elif min(abs(g_lo), abs(g_hi)) < 1e-12:  # the root is the bracket's end point
            roots.append(lo if abs(g_lo) <= abs(g_hi) else hi)
    roots.sort()
    return [f for k, f in enumerate(roots) if k == 0 or f - roots[k - 1] > 1e-9 * f]


def predicted_errors_arcsec(
    U: np.ndarray, a_px: np.ndarray, focal_px: float, sigma_px: float
) -> dict[tuple[int, int, int], float]:
    """Analytic 1-sigma boresight error (arcsec) of every triple of N stars, computed for
    all triples at once. ``U`` (N, 3): star unit vectors; ``a_px`` (N,): distances from the
    principal point. Nearly collinear triples are left out."""
    triples = np.array(list(combinations(range(len(U)), 3)), dtype=np.intp).reshape(-1, 3)
    Ut = U[triples]  # (T, 3, 3)
    at = a_px[triples]
    keep = flatness(Ut) >= MIN_FLATNESS
    Ut, at, triples = Ut[keep], at[keep], triples[keep]
    r2 = at**2 + focal_px**2
    cos = focal_px / np.sqrt(r2)
    d = np.linalg.solve(Ut, cos[..., None])[..., 0]  # (T, 3)
    dc_da = -focal_px * at / r2**1.5
    J = np.linalg.solve(Ut, dc_da[:, None, :] * np.eye(3))  # U^-1 diag(dc/da)
    norm = np.linalg.norm(d, axis=1)
    d_hat = d / norm[:, None]
    P = np.eye(3) - d_hat[:, :, None] * d_hat[:, None, :]
    J_hat = P @ J / norm[:, None, None]
    sigma = np.sqrt(np.sum(J_hat**2, axis=(1, 2))) * sigma_px * ARCSEC_PER_RAD
    return {tuple(int(i) for i in t): float(e) for t, e in zip(triples, sigma, strict=True)}


def best_triple(
    ra_deg, dec_deg, xy, *, focal_px: float, width: float, height: float | None = None
) -> tuple[int, int, int]:
    """Indices of the three stars whose boresight has the smallest predicted error.

    The ranking does not depend on the noise level (every error scales with it). Only the
    first ``MAX_BEST_TRIPLE_STARS`` stars (e.g. the brightest) are considered.
    """
    ra = np.asarray(ra_deg, dtype=float).reshape(-1)
    dec = np.asarray(dec_deg, dtype=float).reshape(-1)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if not len(ra) == len(dec) == len(xy) or len(ra) < 3:
        raise PointingError(f"need at least 3 stars with ra, dec, x, y; got {len(ra)}")
    if not (np.isfinite(focal_px) and focal_px > 0):
        raise PointingError(f"focal_px must be positive, got {shown(focal_px)}")
    n = min(len(ra), MAX_BEST_TRIPLE_STARS)
    height = width if height is None else height
    U = radec_to_unit(np.radians(ra[:n]), np.radians(dec[:n]))
    a = np.hypot(xy[:n, 0] - width / 2.0, xy[:n, 1] - height / 2.0)
    errors = predicted_errors_arcsec(U, a, focal_px, 1.0)
    if not errors:
        raise PointingError("every triple of these stars is (nearly) collinear")
    return min(errors, key=errors.get)
