"""Non-linear least squares of the attitude (and optionally focal length and distortion) on
pixel residuals, through the camera model's projection and Jacobians.

The attitude is perturbed by a small rotation ``omega`` about the camera axes,
``R = exp([omega]) R0``; residuals are projected catalog star minus measured centroid, in px.
The 1-sigma uncertainties come from the Jacobian at the solution, scaled by the a-posteriori
variance of the residuals. The arithmetic is the kernel ``attitude.kernels.fit``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.camera import CameraModel


def kernels():
    """The attitude kernels (imported on first use: numba takes ~0.2 s to load)."""
    from starnav.attitude import kernels

    return kernels


@dataclass(frozen=True, eq=False)
class Refinement:
    """Result of the least-squares refinement.

    ``residuals_px`` (n, 2): projected minus measured; ``rms_px``: root mean square of the
    residual length; ``sigma_boresight_arcsec``: 1-sigma total angular error of the boresight
    (both cross-axes combined); ``sigma_roll_arcsec``: 1-sigma of the rotation about it;
    ``sigma_focal_px``: 1-sigma of the focal length (0 when it was held fixed);
    ``rotation_cov_rad2`` (3, 3): covariance of the small rotation about the camera axes
    (radians squared) that took the a-posteriori variance ``variance_px2`` (px squared) per
    coordinate (a solve told the centroid sigma takes at least its square:
    ``attitude.kernels.at_least_sigma``); ``leverage`` (n, 2, 2): each star's block of the
    hat matrix.
    """

    R_cam_from_icrs: np.ndarray
    camera: CameraModel
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
        return kernels().studentized(self.residuals_px, self.leverage, float(sigma_px))


def rotate_by(omega: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """exp([omega]x) @ R0 (Rodrigues' formula)."""
    return kernels().rotate_by(
        np.ascontiguousarray(omega, dtype=np.float64), np.ascontiguousarray(R0, dtype=np.float64)
    )


def refine_attitude(
    R0: np.ndarray,
    icrs_vectors: np.ndarray,
    xy: np.ndarray,
    camera: CameraModel,
    *,
    fit_focal: bool = False,
    fit_distortion: bool = False,
) -> Refinement:
    """Refine ``R0`` (and the focal length when ``fit_focal``, and the distortion
    coefficients with the focal length when ``fit_distortion``) on matched stars.

    ``icrs_vectors`` (n, 3) are the catalog stars of the centroids ``xy`` (n, 2, px), n >= 2.
    The focal length is only freed with at least 4 stars, the distortion with at least
    ``attitude.kernels.MIN_DISTORTION_STARS``. The covariance comes from the derivatives at
    the solution.
    """
    f = kernels().fit(
        np.ascontiguousarray(R0, dtype=np.float64),
        np.ascontiguousarray(icrs_vectors, dtype=np.float64),
        np.ascontiguousarray(xy, dtype=np.float64),
        camera.model_code,
        camera.params,
        bool(fit_focal),
        bool(fit_distortion),
    )
    return refinement(f, camera)


def refinement(f, camera: CameraModel) -> Refinement:
    """The ``Refinement`` of a kernel ``Fit`` of ``camera`` (``camera`` itself when the fit
    kept its parameters)."""
    kept = bool((f.params == camera.params).all())  # the kernel's params have p0's length
    return Refinement(
        R_cam_from_icrs=f.R,
        camera=camera if kept else type(camera).from_params(camera.width, camera.height, f.params),
        residuals_px=f.residuals,
        rms_px=float(f.rms_px),
        sigma_boresight_arcsec=float(f.sigma_boresight_arcsec),
        sigma_roll_arcsec=float(f.sigma_roll_arcsec),
        sigma_focal_px=float(f.sigma_focal_px),
        rotation_cov_rad2=f.rotation_cov,
        variance_px2=float(f.variance_px2),
        leverage=f.leverage,
    )


def free_focal_step(
    R: np.ndarray, icrs_vectors: np.ndarray, xy: np.ndarray, camera: CameraModel
) -> tuple[float, float]:
    """The focal length (px) the stars fit, and its 1-sigma, by one Gauss-Newton step with
    the focal length freed from a fit that held it at ``camera.focal_px`` (``R`` that fit's
    attitude): at that fit's optimum one step is the joint solution to first order."""
    f, sigma = kernels().free_focal_step(
        np.ascontiguousarray(R, dtype=np.float64),
        np.ascontiguousarray(icrs_vectors, dtype=np.float64),
        np.ascontiguousarray(xy, dtype=np.float64),
        camera.model_code,
        camera.params,
    )
    return float(f), float(sigma)
