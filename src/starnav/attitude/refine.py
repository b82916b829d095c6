"""Non-linear least squares of the attitude (and optionally focal length) on pixel residuals.

The attitude is perturbed by a small rotation ``omega`` about the camera axes,
``R = exp([omega]) R0``; residuals are projected catalog star minus measured centroid, in px.
The 1-sigma uncertainties come from the Jacobian at the solution, scaled by the a-posteriori
variance of the residuals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from starnav.camera import Camera
from starnav.geometry import ARCSEC_PER_RAD

_MAX_STEPS = 10
_STEP_TOL_RAD = 1e-9  # about 2e-6 px at f = 2500 px
MIN_DISTORTION_STARS = 12  # k1, k2 are only fitted with at least this many stars


@dataclass(frozen=True, eq=False)
class Refinement:
    """Result of the least-squares refinement.

    ``residuals_px`` (n, 2): projected minus measured; ``rms_px``: root mean square of the
    residual length; ``sigma_boresight_arcsec``: 1-sigma total angular error of the boresight
    (both cross-axes combined); ``sigma_roll_arcsec``: 1-sigma of the rotation about it;
    ``sigma_focal_px``: 1-sigma of the focal length (0 when it was held fixed);
    ``rotation_cov_rad2`` (3, 3): covariance of the small rotation about the camera axes
    (radians squared) that took the a-posteriori variance ``variance_px2`` (px squared) per
    coordinate; ``leverage`` (n, 2, 2): each star's block of the hat matrix.
    """

    R_cam_from_icrs: np.ndarray
    camera: Camera
    residuals_px: np.ndarray
    rms_px: float
    sigma_boresight_arcsec: float
    sigma_roll_arcsec: float
    sigma_focal_px: float
    rotation_cov_rad2: np.ndarray
    variance_px2: float
    leverage: np.ndarray

    def studentized(self, sigma_px: float) -> np.ndarray:
        """Each star's residual over its own expected spread when the centroid error is
        ``sigma_px``: r^T (I - H_ii)^-1 r / sigma^2, chi-square with 2 degrees of freedom for
        a right match (``H_ii`` the star's 2x2 block of the hat matrix: a star far from the
        others pulls the fit to itself, and its small residual still hides a large error)."""
        spread = np.eye(2)[None] * (1.0 + 1e-9) - self.leverage
        if not np.all(np.isfinite(spread)):
            return np.zeros(len(self.residuals_px))  # the fit fixes nothing: no test
        r = self.residuals_px
        return np.einsum("ni,nij,nj->n", r, np.linalg.inv(spread), r) / sigma_px**2


def rotate_by(omega: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """exp([omega]x) @ R0 (Rodrigues' formula; scipy's Rotation costs 30 µs a call here)."""
    angle = float(np.sqrt(omega @ omega))
    if angle < 1e-300:
        return R0
    k = omega / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return (np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)) @ R0


def _updated(camera: Camera, params: np.ndarray, fit_focal: bool, fit_distortion: bool) -> Camera:
    """The camera after a step: focal length scaled by exp(p3), k1, k2 moved by p4, p5."""
    if not fit_focal:
        return camera
    focal = camera.focal_px * float(np.exp(params[3]))
    k1, k2 = camera.k1, camera.k2
    if fit_distortion:
        k1, k2 = k1 + float(params[4]), k2 + float(params[5])
    return Camera(camera.width, camera.height, focal, camera.cx, camera.cy, k1, k2)


def _residuals_and_jacobian(params, R0, icrs, xy, camera, fit_focal, fit_distortion=False):
    cam = _updated(camera, params, fit_focal, fit_distortion)
    focal = cam.focal_px
    c = icrs @ rotate_by(params[:3], R0).T
    inv_z = 1.0 / c[:, 2]
    u, v = c[:, 0] * inv_z, c[:, 1] * inv_z
    # c' = c + omega x c moves u = cx/cz and v = cy/cz by these (per omega_x, _y, _z)
    uv = u * v
    ju = np.column_stack([-uv, 1.0 + u * u, -v])
    jv = np.column_stack([-1.0 - v * v, uv, u])
    distorted = fit_distortion or cam.k1 or cam.k2
    if distorted:
        r2 = u * u + v * v
        d = 1.0 + cam.k1 * r2 + cam.k2 * r2 * r2  # radial factor
        dd = cam.k1 + 2.0 * cam.k2 * r2  # its derivative in r^2
        # the distorted (u d, v d) moved by the undistorted (u, v)
        ju, jv = (
            (d + 2.0 * u * u * dd)[:, None] * ju + (2.0 * uv * dd)[:, None] * jv,
            (2.0 * uv * dd)[:, None] * ju + (d + 2.0 * v * v * dd)[:, None] * jv,
        )
        u, v = u * d, v * d
    res = np.concatenate([cam.cx + focal * u - xy[:, 0], cam.cy + focal * v - xy[:, 1]])
    jac = focal * np.vstack([ju, jv])
    if fit_focal:
        jac = np.column_stack([jac, np.concatenate([focal * u, focal * v])])
    if fit_distortion:
        jac = np.column_stack(
            [
                jac,
                np.concatenate([focal * u * r2 / d, focal * v * r2 / d]),
                np.concatenate([focal * u * r2 * r2 / d, focal * v * r2 * r2 / d]),
            ]
        )
    return res, jac, cam


def refine_attitude(
    R0: np.ndarray,
    icrs_vectors: np.ndarray,
    xy: np.ndarray,
    camera: Camera,
    *,
    fit_focal: bool = False,
    fit_distortion: bool = False,
) -> Refinement:
    """Refine ``R0`` (and the focal length when ``fit_focal``, and the radial distortion
    k1, k2 with the focal length when ``fit_distortion``) on matched stars.

    ``icrs_vectors`` (n, 3) are the catalog stars of the centroids ``xy`` (n, 2, px), n >= 2.
    The focal length is only freed with at least 4 stars, the distortion with at least
    ``MIN_DISTORTION_STARS``. The covariance comes from the derivatives at the solution.
    """
    xy = np.asarray(xy, dtype=float)
    icrs = np.asarray(icrs_vectors, dtype=float)
    fit_distortion = fit_distortion and len(xy) >= MIN_DISTORTION_STARS
    fit_focal = (fit_focal or fit_distortion) and len(xy) >= 4
    n_params = 3 + int(fit_focal) + 2 * int(fit_distortion)

    # Gauss-Newton, relinearised about the current attitude at every step (the derivatives
    # are exact there); from a start within a pixel or so it converges in 2-4 steps, where
    # a general optimiser spends ~20 evaluations on the tolerance tests of a near-zero cost
    R, cam = R0, camera
    zero = np.zeros(n_params)
    cost0 = None
    for _ in range(_MAX_STEPS):
        res, J, _ = _residuals_and_jacobian(zero, R, icrs, xy, cam, fit_focal, fit_distortion)
        cost = float(res @ res)
        if cost0 is None:
            cost0 = cost
        step = np.linalg.lstsq(J, -res, rcond=None)[0]
        R = rotate_by(step[:3], R)
        cam = _updated(cam, step, fit_focal, fit_distortion)
        if np.max(np.abs(step[:4])) < _STEP_TOL_RAD and (
            not fit_distortion or np.max(np.abs(step[4:])) < _STEP_TOL_RAD
        ):
            break
    res_end = _residuals_and_jacobian(zero, R, icrs, xy, cam, fit_focal, fit_distortion)[0]
    if not np.isfinite(res_end).all() or float(res_end @ res_end) > cost0:
        # a start too far off for Gauss-Newton: let Levenberg-Marquardt find its way
        def fun(p):
            return _residuals_and_jacobian(p, R0, icrs, xy, camera, fit_focal, fit_distortion)[0]

        def jac(p):
            return _residuals_and_jacobian(p, R0, icrs, xy, camera, fit_focal, fit_distortion)[1]

        fit = least_squares(fun, zero, jac=jac, method="lm", x_scale="jac")
        R = rotate_by(fit.x[:3], R0)
        cam = _updated(camera, fit.x, fit_focal, fit_distortion)
    # the Jacobian above is exact at omega = 0: linearise again about the solution for the
    # covariance
    zero = np.zeros(n_params)
    res, J, cam = _residuals_and_jacobian(zero, R, icrs, xy, cam, fit_focal, fit_distortion)
    focal = cam.focal_px
    residuals = np.column_stack([res[: len(xy)], res[len(xy) :]])
    dof = max(2 * len(xy) - n_params, 1)
    s2 = float(res @ res) / dof
    n = len(xy)
    try:
        normal_inv = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        normal_inv = np.full((n_params, n_params), np.inf)
    cov = s2 * normal_inv
    J_star = np.stack([J[:n], J[n:]], axis=1)  # (n, 2, params): star i's two rows
    leverage = np.einsum("nip,pq,njq->nij", J_star, normal_inv, J_star)
    sigma_boresight = np.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)) * ARCSEC_PER_RAD
    sigma_roll = np.sqrt(max(cov[2, 2], 0.0)) * ARCSEC_PER_RAD
    # focal = f0 exp(p3): sigma_f = f sigma_p3
    sigma_focal = focal * np.sqrt(max(cov[3, 3], 0.0)) if fit_focal else 0.0
    return Refinement(
        R_cam_from_icrs=R,
        camera=cam,
        residuals_px=residuals,
        rms_px=float(np.sqrt(np.mean(np.sum(residuals**2, axis=1)))),
        sigma_boresight_arcsec=float(sigma_boresight),
        sigma_roll_arcsec=float(sigma_roll),
        sigma_focal_px=float(sigma_focal),
        rotation_cov_rad2=cov[:3, :3],
        variance_px2=s2,
        leverage=leverage,
    )


def free_focal_step(
    R: np.ndarray, icrs_vectors: np.ndarray, xy: np.ndarray, camera: Camera
) -> tuple[float, float]:
    """The focal length (px) the stars fit, and its 1-sigma, by one Gauss-Newton step with
    the focal length freed from a fit that held it at ``camera.focal_px`` (``R`` that fit's
    attitude): at that fit's optimum one step is the joint solution to first order, at a
    fifth of the cost of ``refine_attitude(..., fit_focal=True)``."""
    xy = np.asarray(xy, dtype=float)
    res, J, _ = _residuals_and_jacobian(
        np.zeros(4), R, np.asarray(icrs_vectors, dtype=float), xy, camera, True
    )
    step = np.linalg.lstsq(J, -res, rcond=None)[0]
    left = res + J @ step
    s2 = float(left @ left) / max(len(res) - 4, 1)
    try:
        var = s2 * np.linalg.inv(J.T @ J)[3, 3]
    except np.linalg.LinAlgError:
        var = np.inf
    focal = camera.focal_px * float(np.exp(step[3]))
    return focal, focal * float(np.sqrt(max(var, 0.0)))
