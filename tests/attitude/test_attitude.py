import numpy as np
import pytest

from starnav.attitude import refine_attitude, wahba
from starnav.camera import Camera
from starnav.geometry import ARCSEC_PER_RAD, angle_between, attitude_from_radec_roll
from starnav.simulate import project_catalog


@pytest.mark.parametrize("parity", [1, -1])
def test_wahba_exact(parity):
    rng = np.random.default_rng(0)
    R = attitude_from_radec_roll(123.0, -40.0, 77.0, parity)
    icrs = rng.normal(size=(6, 3))
    icrs /= np.linalg.norm(icrs, axis=1, keepdims=True)
    assert np.allclose(wahba(icrs @ R.T, icrs, parity=parity), R, atol=1e-12)


def _stars(hip, R, cam):
    rows, xy = project_catalog(hip, R, cam)
    return hip.vectors[rows], xy


def test_refine_recovers_attitude_and_focal(hip_1991):
    cam = Camera.from_fov(12.0, 512)
    R = attitude_from_radec_roll(200.0, 30.0, 15.0)
    icrs, xy = _stars(hip_1991, R, cam)
    R0 = attitude_from_radec_roll(200.02, 30.01, 15.1)
    wrong_focal = cam.with_focal(cam.focal_px * 1.004)
    fit = refine_attitude(R0, icrs, xy, wrong_focal, fit_focal=True)
    assert np.isclose(fit.camera.focal_px, cam.focal_px, rtol=1e-7)
    assert angle_between(fit.R_cam_from_icrs[2], R[2]) * ARCSEC_PER_RAD < 1e-3
    assert fit.rms_px < 1e-4


def test_uncertainty_matches_monte_carlo(hip_1991):
    """The reported 1-sigma of boresight and roll agree with the scatter of repeated fits."""
    cam = Camera.from_fov(12.0, 512)
    R = attitude_from_radec_roll(83.0, -1.0, 40.0)  # Orion: many stars
    icrs, xy = _stars(hip_1991, R, cam)
    rng = np.random.default_rng(11)
    errs, sig_b, sig_r = [], [], []
    for _ in range(300):
        fit = refine_attitude(R, icrs, xy + rng.normal(0, 0.5, xy.shape), cam)
        dR = fit.R_cam_from_icrs @ R.T
        errs.append([dR[2, 1], -dR[2, 0], dR[1, 0]])  # small rotation about x, y, z
        sig_b.append(fit.sigma_boresight_arcsec)
        sig_r.append(fit.sigma_roll_arcsec)
    errs = np.array(errs) * ARCSEC_PER_RAD
    mc_boresight = np.sqrt(np.mean(errs[:, 0] ** 2 + errs[:, 1] ** 2))
    mc_roll = np.sqrt(np.mean(errs[:, 2] ** 2))
    assert np.median(sig_b) == pytest.approx(mc_boresight, rel=0.2)
    assert np.median(sig_r) == pytest.approx(mc_roll, rel=0.2)


@pytest.mark.parametrize(
    ("k1", "k2", "fit_focal", "fit_distortion"),
    [(0.0, 0.0, False, False), (0.0, 0.0, True, False), (-0.1, 0.05, True, True)],
)
def test_analytic_jacobian_matches_finite_differences(k1, k2, fit_focal, fit_distortion):
    """The fit's Jacobian (the camera model's by the chain rule) in the rotation and the
    freed intrinsics against central differences of the residuals."""
    from starnav.attitude import kernels as k

    rng = np.random.default_rng(0)
    v = rng.normal(size=(6, 3))
    v[:, 2] = 5.0
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    xy = rng.uniform(0, 1000, (6, 2))
    cam = Camera(1000, 1000, 1500.0, k1=k1, k2=k2)
    free = np.array([fit_focal, fit_distortion, fit_distortion, False, False])  # N_INTRINSIC
    R0 = np.eye(3)

    def residuals(q):
        R = k.rotate_by(q[:3].copy(), R0)
        p = k.update(cam.model_code, cam.params, q[3:].copy(), free)
        return k.residuals_jacobian(R, v, xy, cam.model_code, p, free)[0]

    n_par = 3 + int(free.sum())
    J = k.residuals_jacobian(R0, v, xy, cam.model_code, cam.params, free)[1]
    h = 1e-6
    numeric = np.column_stack([(residuals(e) - residuals(-e)) / (2 * h) for e in np.eye(n_par) * h])
    assert J.shape == (12, n_par)
    assert np.abs(J - numeric).max() <= 1e-7 * np.abs(numeric).max()


@pytest.mark.slow
def test_one_free_focal_step_agrees_with_the_full_fit():
    from starnav.attitude.refine import free_focal_step
    from starnav.catalog import load_catalog

    cat = load_catalog(None, mag_limit=6.0)
    true = Camera.from_fov(12.0, 512)
    R = attitude_from_radec_roll(83.0, -1.0, 20.0)
    rows, xy = project_catalog(cat, R, true)
    xy = xy + np.random.default_rng(3).normal(0.0, 0.1, xy.shape)
    given = true.with_focal(true.focal_px * 1.01)
    held = refine_attitude(R, cat.vectors[rows], xy, given)
    full = refine_attitude(held.R_cam_from_icrs, cat.vectors[rows], xy, given, fit_focal=True)
    focal, sigma = free_focal_step(held.R_cam_from_icrs, cat.vectors[rows], xy, given)
    # the refusal compares with a 0.5 % tolerance: 1e-4 of the focal length is far inside
    assert focal == pytest.approx(full.camera.focal_px, rel=1e-4)
    assert sigma == pytest.approx(full.sigma_focal_px, rel=0.05)
