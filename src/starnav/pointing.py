"""Three-star pointing: the boresight from three known stars (problem 1 of the 2019 contest).

For star unit vectors u_i and their image distances a_i from the principal point, the
boresight d satisfies u_i . d = cos(theta_i) = f / sqrt(a_i^2 + f^2). With the focal length f
known the three equations are linear in d (``U d = c``); |d| - 1 measures how consistent the
data are. With f unknown, |d(f)| = 1 is one equation in f, solved by bracketing every sign
change of |d(f)|^2 - 1 on a logarithmic grid and refining each with Brent's method, so all
solutions are found and none depends on a starting value.

Error propagation is analytic: d depends on the centroids through a_i; the Jacobian gives the
covariance of the unit boresight for a centroid noise sigma_px (per axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from scipy.optimize import brentq

from starnav.errors import StarnavError
from starnav.geometry import (
    ARCSEC_PER_RAD,
    attitude_from_radec_roll,
    radec_to_unit,
    unit_to_radec,
)

# a triple whose stars span less volume than this (|det U|) is "nearly collinear"
MIN_TRIPLE_PRODUCT = 1e-9
POOR_FOCAL_PER_PX = 0.01  # relative focal error per px of distance error called "poor"
MAX_INCONSISTENCY = 0.2  # | |d| - 1 | beyond this: the data cannot be one camera's view
_F_GRID = np.geomspace(1.0, 1e7, 4000)  # focal lengths (px) searched when f is unknown


class PointingError(StarnavError):
    """Three stars that cannot give a boresight (wrong count, identical, collinear, ...)."""


@dataclass(frozen=True)
class Pointing:
    """One boresight solution.

    ``ra_deg``/``dec_deg``: boresight; ``roll_deg``: position angle of image up (None without
    x,y); ``focal_px``: given or solved; ``consistency``: |d| - 1 of the linear solution
    (0 for exact data; with f solved it is 0 by construction); ``sigma_boresight_arcsec``:
    1-sigma boresight error from the analytic covariance (None without sigma_px);
    ``alternatives``: other (focal, boresight) solutions that fit as well, best first;
    ``fit_rms_px``: with f solved from x,y, how well the inter-star angles agree (px);
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


def _check(ra_deg, dec_deg, xy, r_px, width, height) -> tuple[np.ndarray, np.ndarray]:
    ra = np.asarray(ra_deg, dtype=float).reshape(-1)
    dec = np.asarray(dec_deg, dtype=float).reshape(-1)
    if len(ra) != 3 or len(dec) != 3:
        raise PointingError(f"three-star pointing needs exactly 3 stars, got {len(ra)}")
    if not (np.isfinite(ra).all() and np.isfinite(dec).all()):
        raise PointingError("ra_deg/dec_deg must be finite numbers")
    if (np.abs(dec) > 90).any():
        raise PointingError(f"dec_deg must be within ±90, got {dec.tolist()}")
    if (xy is None) == (r_px is None):
        raise PointingError("give either xy (pixel positions) or r_px (distances), not both")
    U = radec_to_unit(np.radians(ra), np.radians(dec))
    for i, j in combinations(range(3), 2):
        if np.linalg.norm(U[i] - U[j]) < 1e-12:
            raise PointingError(f"stars {i + 1} and {j + 1} are the same star")
    volume = abs(np.linalg.det(U))
    if volume < MIN_TRIPLE_PRODUCT:
        raise PointingError(
            f"the three stars are (nearly) collinear on the sky (|det U| = {volume:.1e}): "
            "their boresight equations do not determine a direction"
        )
    return U, volume


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
    parity: int = 1,
) -> Pointing:
    """Boresight from exactly three stars at (``ra_deg``, ``dec_deg``) (degrees, ICRS).

    ``xy``: their pixel positions (3, 2; origin top-left; principal point (W/2, H/2), so
    ``width``/``height`` are needed) or ``r_px``: their distances from the principal point.
    ``focal_px``: known focal length; None solves for it (all solutions, best first).
    ``sigma_px``: centroid noise per axis, for the analytic 1-sigma boresight error.
    """
    U, _ = _check(ra_deg, dec_deg, xy, r_px, width, height)
    offsets = None
    if xy is not None:
        xy = np.asarray(xy, dtype=float)
        if xy.shape != (3, 2) or not np.isfinite(xy).all():
            raise PointingError(f"xy must be 3 finite (x, y) pairs, got shape {xy.shape}")
        if width is None or height is None:
            raise PointingError("with x,y give the image width and height (principal point)")
        offsets = xy - [width / 2.0, height / 2.0]
        a = np.hypot(*offsets.T)
    else:
        a = np.asarray(r_px, dtype=float).reshape(-1)
        if len(a) != 3 or not np.isfinite(a).all() or (a < 0).any():
            raise PointingError(f"r_px must be 3 distances >= 0, got {np.asarray(r_px).tolist()}")
    if width is not None and height is not None:
        half_diag = 0.5 * np.hypot(width, height)
        if (a > half_diag * (1 + 1e-9)).any():
            raise PointingError(
                f"a star is {a.max():.1f} px from the centre, beyond the "
                f"{width:g} x {height:g} image (half diagonal {half_diag:.1f} px)"
            )
    if sigma_px is not None and not (np.isfinite(sigma_px) and sigma_px >= 0):
        raise PointingError(f"sigma_px must be >= 0, got {sigma_px!r}")

    def solution(f: float, consistency: float | None = None) -> Pointing:
        focal_free = consistency is not None
        d = linear_boresight(U, a, f)
        norm = float(np.linalg.norm(d))
        d_hat = d / norm
        ra, dec = unit_to_radec(d_hat)
        return Pointing(
            ra_deg=float(np.degrees(ra)),
            dec_deg=float(np.degrees(dec)),
            roll_deg=None if offsets is None else _roll_deg(d_hat, U, offsets, f, parity),
            focal_px=float(f),
            consistency=norm - 1.0 if consistency is None else consistency,
            sigma_boresight_arcsec=None
            if sigma_px is None
            else sigma_boresight_arcsec(U, a, f, sigma_px, focal_free=focal_free),
            sigma_focal_px=None
            if sigma_px is None or not focal_free
            else sigma_focal_px(U, a, f, sigma_px),
            boresight=d_hat,
        )

    if focal_px is not None:
        if not (np.isfinite(focal_px) and focal_px > 0):
            raise PointingError(f"focal_px must be positive, got {focal_px!r}")
        known = solution(float(focal_px))
        if abs(known.consistency) > MAX_INCONSISTENCY:
            raise PointingError(
                f"the distances do not fit these stars at focal length {focal_px:g} px: the "
                f"boresight equations give |d| = {1 + known.consistency:.3f} (cosines beyond "
                "what the star separations allow); check the identification and focal length"
            )
        return known
    roots = focal_solutions(U, a)
    if not roots:
        raise PointingError(
            "no focal length makes these three stars consistent (|d(f)| never reaches 1): "
            "check the identification and the positions"
        )
    sols = [solution(f, 0.0) for f in roots]
    if offsets is not None:
        # the inter-star angles also depend on f: keep the solutions that reproduce them
        misfit = [_angle_misfit_px(U, offsets, s.focal_px) for s in sols]
        tol = 3.0 * (sigma_px or 0.0) + 1e-6 * max(width, height)
        order = np.argsort(misfit)
        sols = [_with(sols[k], fit_rms_px=misfit[k]) for k in order if misfit[k] <= tol] or [
            _with(sols[order[0]], fit_rms_px=misfit[order[0]])
        ]
    else:
        # rank: the solution whose boresight is least sensitive to the data first
        sens = [sigma_boresight_arcsec(U, a, s.focal_px, 1.0) for s in sols]
        sols = [sols[k] for k in np.argsort(sens)]
    notes = []
    if len(sols) > 1:
        notes.append(
            f"{len(sols)} focal lengths fit these three stars; best first"
            + ("" if offsets is not None else " (x,y would tell them apart)")
        )
    # how well this geometry fixes f, per px of error in the distances
    spread = sigma_focal_px(U, a, sols[0].focal_px, 1.0) / sols[0].focal_px
    if not np.isfinite(spread) or spread > POOR_FOCAL_PER_PX:
        notes.append(
            f"this geometry hardly determines the focal length: 1 px of error in the "
            f"distances moves it by {spread:.1%}"
        )
    return _with(sols[0], alternatives=tuple(sols[1:]), note="; ".join(notes))


def _angle_misfit_px(U: np.ndarray, offsets: np.ndarray, focal_px: float) -> float:
    """RMS (in px at the focal length) of measured minus catalog inter-star angles."""
    b = np.column_stack([offsets, np.full(3, focal_px)])
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    i, j = np.array([0, 0, 1]), np.array([1, 2, 2])
    measured = np.arccos(np.clip(np.sum(b[i] * b[j], axis=1), -1, 1))
    catalog = np.arccos(np.clip(np.sum(U[i] * U[j], axis=1), -1, 1))
    return float(np.sqrt(np.mean((measured - catalog) ** 2)) * focal_px)


def _with(p: Pointing, **changes) -> Pointing:
    from dataclasses import replace

    return replace(p, **changes)


def focal_solutions(U: np.ndarray, a_px: np.ndarray) -> list[float]:
    """All focal lengths f (px) with |d(f)| = 1, by bracketing sign changes on a log grid."""
    Uinv = np.linalg.inv(U)

    def g(f):
        return float(np.sum((Uinv @ _cos_theta(a_px, f)) ** 2) - 1.0)

    cos_grid = _F_GRID[:, None] / np.sqrt(a_px[None, :] ** 2 + _F_GRID[:, None] ** 2)
    values = np.sum((cos_grid @ Uinv.T) ** 2, axis=1) - 1.0
    roots = []
    for k in np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0):
        roots.append(brentq(g, _F_GRID[k], _F_GRID[k + 1], xtol=1e-12, rtol=1e-14))
    return roots


def predicted_errors_arcsec(
    U: np.ndarray, a_px: np.ndarray, focal_px: float, sigma_px: float
) -> dict[tuple[int, int, int], float]:
    """Analytic 1-sigma boresight error (arcsec) of every triple of N stars.

    ``U`` (N, 3): star unit vectors; ``a_px`` (N,): distances from the principal point.
    Nearly collinear triples are left out.
    """
    errors = {}
    for triple in combinations(range(len(U)), 3):
        sub = U[list(triple)]
        if abs(np.linalg.det(sub)) < MIN_TRIPLE_PRODUCT:
            continue
        errors[triple] = sigma_boresight_arcsec(sub, a_px[list(triple)], focal_px, sigma_px)
    return errors


def best_triple(
    ra_deg, dec_deg, xy, *, focal_px: float, width: float, height: float, sigma_px: float = 1.0
) -> tuple[int, int, int]:
    """Indices of the three stars whose boresight has the smallest predicted error."""
    ra = np.asarray(ra_deg, dtype=float).reshape(-1)
    dec = np.asarray(dec_deg, dtype=float).reshape(-1)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if not len(ra) == len(dec) == len(xy) or len(ra) < 3:
        raise PointingError(f"need at least 3 stars with ra, dec, x, y; got {len(ra)}")
    U = radec_to_unit(np.radians(ra), np.radians(dec))
    a = np.hypot(xy[:, 0] - width / 2.0, xy[:, 1] - height / 2.0)
    errors = predicted_errors_arcsec(U, a, focal_px, sigma_px)
    if not errors:
        raise PointingError("every triple of these stars is (nearly) collinear")
    return min(errors, key=errors.get)
