"""Kernels of the attitude stage (numba; plain Python under ``NUMBA_DISABLE_JIT=1``): least
squares on pixel residuals through any camera model (``camera.kernels``), with its
Levenberg-Marquardt branch, covariance, leverage and studentized residuals; the rotations
are in ``attitude.rotation``.

The attitude is perturbed by a small rotation ``omega`` about the camera axes,
``R = exp([omega]x) R0``: a camera-frame direction c moves by ``omega x c = -[c]x omega``, so
the pixel Jacobian in omega is ``J_c @ -[c]x`` (``J_c`` the model's Jacobian in the
direction), and in the intrinsics the model's own ``J_p`` (chain rule, no projection here).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from starnav.attitude.rotation import rotate_by
from starnav.camera.kernels import N_INTRINSIC, n_coefficients, project, update
from starnav.geometry import ARCSEC_PER_RAD
from starnav.runtime.caching import njit

MAX_STEPS = 10  # Gauss-Newton steps
STEP_TOL_RAD = 1e-9  # about 2e-6 px at f = 2500 px
MAX_LM_STEPS = 200  # Levenberg-Marquardt steps, when Gauss-Newton does not reduce the cost
MIN_FOCAL_STARS = 4  # the focal length is only freed with at least this many stars
MIN_DISTORTION_STARS = 12  # the distortion coefficients with at least this many

Fit = namedtuple(
    "Fit",
    "R params residuals rotation_cov variance_px2 leverage rms_px sigma_boresight_arcsec "
    "sigma_roll_arcsec sigma_focal_px",
)


@njit(cache=True)
def residuals_jacobian(R, icrs, xy, model, p, free):
    """Residuals (2n,: x of every star, then y; projected minus measured, px) and their
    Jacobian (2n, 3 + free intrinsics) in the rotation and the ``free`` intrinsic columns."""
    n = len(xy)
    n_free = 0
    for k in range(N_INTRINSIC):
        n_free += free[k]
    res = np.empty(2 * n)
    J = np.empty((2 * n, 3 + n_free))
    J_c = np.empty((2, 3))
    J_p = np.empty((2, N_INTRINSIC))
    for s in range(n):
        c0 = R[0, 0] * icrs[s, 0] + R[0, 1] * icrs[s, 1] + R[0, 2] * icrs[s, 2]
        c1 = R[1, 0] * icrs[s, 0] + R[1, 1] * icrs[s, 1] + R[1, 2] * icrs[s, 2]
        c2 = R[2, 0] * icrs[s, 0] + R[2, 1] * icrs[s, 1] + R[2, 2] * icrs[s, 2]
        x, y = project(model, p, c0, c1, c2, J_c, J_p)
        res[s], res[n + s] = x - xy[s, 0], y - xy[s, 1]
        for a in range(2):
            row = s + a * n
            # J_c @ -[c]x, with -[c]x = [[0, c2, -c1], [-c2, 0, c0], [c1, -c0, 0]]
            J[row, 0] = -J_c[a, 1] * c2 + J_c[a, 2] * c1
            J[row, 1] = J_c[a, 0] * c2 - J_c[a, 2] * c0
            J[row, 2] = -J_c[a, 0] * c1 + J_c[a, 1] * c0
            col = 3
            for k in range(N_INTRINSIC):
                if free[k]:
                    J[row, col] = J_p[a, k]
                    col += 1
    return res, J


@njit(cache=True)
def cholesky(N):
    """Lower-triangular L with L L^T = N (a few parameters), and whether N was positive
    definite."""
    p = len(N)
    L = np.zeros((p, p))
    for i in range(p):
        for j in range(i + 1):
            s = N[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return L, False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return L, True


@njit(cache=True)
def cholesky_solve(L, g):
    """x with L L^T x = g."""
    p = len(g)
    y = np.empty(p)
    for i in range(p):
        s = g[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.empty(p)
    for i in range(p - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, p):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x


@njit(cache=True)
def _cost_at(R, icrs, xy, model, p, free):
    res, _ = residuals_jacobian(R, icrs, xy, model, p, free)
    return res @ res


@njit(cache=True)
def _levenberg_marquardt(R0, icrs, xy, model, p0, free):
    """Levenberg-Marquardt from (R0, p0) with Marquardt's scaling: the branch for starts too
    far off for Gauss-Newton."""
    R, p = R0.copy(), p0.copy()
    res, J = residuals_jacobian(R, icrs, xy, model, p, free)
    cost = res @ res
    N = J.T @ J
    lam = 1e-3 * np.max(np.diag(N))
    for _ in range(MAX_LM_STEPS):
        damped = N.copy()
        for i in range(len(N)):
            damped[i, i] += lam * max(N[i, i], 1e-300)
        L, definite = cholesky(damped)
        if not definite:
            lam *= 10.0
            continue
        step = cholesky_solve(L, -(J.T @ res))
        R_try = rotate_by(step[:3], R)
        p_try = update(model, p, step[3:], free)
        cost_try = _cost_at(R_try, icrs, xy, model, p_try, free)
        if np.isfinite(cost_try) and cost_try < cost:
            R, p, cost = R_try, p_try, cost_try
            res, J = residuals_jacobian(R, icrs, xy, model, p, free)
            N = J.T @ J
            lam = max(lam / 10.0, 1e-12)
            if np.max(np.abs(step)) < STEP_TOL_RAD:
                break
        else:
            lam *= 10.0
            if lam > 1e16:
                break
    return R, p


@njit(cache=True)
def free_columns(n_stars, fit_focal, fit_distortion, model):
    """The intrinsic columns the fit frees for ``n_stars`` matched stars (the distortion
    coefficients the ``model`` has)."""
    free = np.zeros(N_INTRINSIC, dtype=np.bool_)
    distortion = fit_distortion and n_stars >= MIN_DISTORTION_STARS
    free[0] = (fit_focal or distortion) and n_stars >= MIN_FOCAL_STARS
    for k in range(1, n_coefficients(model) + 1):
        free[k] = distortion and free[0]
    return free


@njit(cache=True)
def fit(R0, icrs, xy, model, p0, fit_focal, fit_distortion):
    """Least squares of the attitude (and the focal length / distortion when asked and
    enough stars allow) on the pixel residuals of ``icrs`` (n, 3) matched to ``xy`` (n, 2).
    Gauss-Newton, relinearised at every step (2-4 steps from a start within a pixel or so);
    when it does not reduce the cost, Levenberg-Marquardt from the start. The covariance
    comes from the Jacobian at the solution and the a-posteriori variance."""
    n = len(xy)
    free = free_columns(n, fit_focal, fit_distortion, model)
    R, p = R0.copy(), p0.copy()
    cost0 = -1.0
    for _ in range(MAX_STEPS):
        res, J = residuals_jacobian(R, icrs, xy, model, p, free)
        if cost0 < 0:
            cost0 = res @ res
        L, definite = cholesky(J.T @ J)
        if not definite:
            break
        step = cholesky_solve(L, -(J.T @ res))
        R = rotate_by(step[:3], R)
        p = update(model, p, step[3:], free)
        if np.max(np.abs(step)) < STEP_TOL_RAD:
            break
    res, J = residuals_jacobian(R, icrs, xy, model, p, free)
    cost = res @ res
    if not (np.isfinite(cost) and cost <= cost0):
        R, p = _levenberg_marquardt(R0, icrs, xy, model, p0, free)
        res, J = residuals_jacobian(R, icrs, xy, model, p, free)
    return _spread(R, p, free, res, J)


@njit(cache=True)
def _spread(R, p, free, res, J):
    """The ``Fit`` at (R, p) from its residuals ``res`` and Jacobian ``J`` there: residuals,
    covariance (a-posteriori variance), leverage."""
    n = len(res) // 2
    n_par = J.shape[1]
    cost = res @ res
    residuals = np.empty((n, 2))
    residuals[:, 0] = res[:n]
    residuals[:, 1] = res[n:]
    s2 = cost / max(2 * n - n_par, 1)
    L, definite = cholesky(J.T @ J)
    N_inv = np.full((n_par, n_par), np.inf)
    if definite:
        for i in range(n_par):
            unit = np.zeros(n_par)
            unit[i] = 1.0
            N_inv[:, i] = cholesky_solve(L, unit)
    cov = s2 * N_inv
    leverage = np.empty((n, 2, 2))
    for s in range(n):  # J_i N^-1 J_j^T of the star's two rows, in loops: no temporaries
        for i in range(2):
            for j in range(2):
                h = 0.0
                for a in range(n_par):
                    t = 0.0
                    for b in range(n_par):
                        t += N_inv[a, b] * J[s + j * n, b]
                    h += J[s + i * n, a] * t
                leverage[s, i, j] = h
    sigma_b = math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)) * ARCSEC_PER_RAD
    sigma_r = math.sqrt(max(cov[2, 2], 0.0)) * ARCSEC_PER_RAD
    sigma_f = p[0] * math.sqrt(max(cov[3, 3], 0.0)) if free[0] else 0.0  # f = f0 exp(q)
    return Fit(R, p, residuals, cov[:3, :3].copy(), s2, leverage, math.sqrt(cost / n), sigma_b,
               sigma_r, sigma_f)  # fmt: skip


@njit(cache=True)
def variance_scale(variance_px2, sigma_px):
    """The factor that puts a fit's covariance (at its a-posteriori ``variance_px2``) at the
    larger of that and ``sigma_px``² (1 when the residuals are exactly 0)."""
    return max(1.0, sigma_px**2 / variance_px2) if variance_px2 > 0 else 1.0


@njit(cache=True)
def at_least_sigma(f, sigma_px):
    """``f`` with its covariance and 1-sigmas at the larger of its a-posteriori variance and
    the known centroid ``sigma_px``² (``variance_scale``; the residuals and the variance
    itself kept): a fit of few stars estimates its variance from few residuals (2n - 3
    degrees of freedom: of 5 stars' fits one in twenty puts the sigma 44 % or more low), and
    a low estimate claims a precision the centroids do not have."""
    scale = variance_scale(f.variance_px2, sigma_px)
    root = math.sqrt(scale)
    return Fit(f.R, f.params, f.residuals, f.rotation_cov * scale, f.variance_px2, f.leverage,
               f.rms_px, f.sigma_boresight_arcsec * root, f.sigma_roll_arcsec * root,
               f.sigma_focal_px * root)  # fmt: skip


@njit(cache=True)
def studentized(residuals, leverage, sigma_px):
    """Each star's residual over its own expected spread when the centroid error is
    ``sigma_px``: r^T (I - H_ii)^-1 r / sigma^2, chi-square with 2 degrees of freedom for a
    right match (``H_ii`` its 2x2 block of the hat matrix). Zeros when the fit fixes nothing."""
    n = len(residuals)
    t = np.zeros(n)
    for s in range(n):
        a = 1.0 + 1e-9 - leverage[s, 0, 0]
        b = -leverage[s, 0, 1]
        c = -leverage[s, 1, 0]
        d = 1.0 + 1e-9 - leverage[s, 1, 1]
        if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(c) and np.isfinite(d)):
            return np.zeros(n)
        det = a * d - b * c
        x, y = residuals[s, 0], residuals[s, 1]
        t[s] = (x * (d * x - b * y) + y * (-c * x + a * y)) / det / sigma_px**2
    return t


@njit(cache=True)
def focal_system(R, icrs, xy, model, p):
    """The linearised problem of the attitude with the focal length freed, at ``R`` and the
    camera ``p``: residuals, Jacobian (rotation, log focal length) and the normal equations
    ``J^T J``, ``J^T res`` (``focal_step`` solves it, whole or a star left out)."""
    free = np.zeros(N_INTRINSIC, dtype=np.bool_)
    free[0] = True
    res, J = residuals_jacobian(R, icrs, xy, model, p, free)
    return res, J, J.T @ J, J.T @ res


@njit(cache=True)
def focal_step(res, J, N, g, f0, sigma_px=0.0, skip=-1):
    """(focal length px, its 1-sigma) of one Gauss-Newton step of ``focal_system`` from the
    focal length ``f0``, star ``skip`` left out (its two rows taken off the normal
    equations; -1: none). The 1-sigma is at the a-posteriori variance, at least
    ``sigma_px``² (``variance_scale``; 0: no floor)."""
    n = len(res) // 2
    if skip >= 0:
        N, g = N.copy(), g.copy()
        for r in (skip, skip + n):
            for a in range(4):
                g[a] -= J[r, a] * res[r]
                for b in range(4):
                    N[a, b] -= J[r, a] * J[r, b]
    L, definite = cholesky(N)
    if not definite:
        return f0, np.inf
    step = cholesky_solve(L, -g)
    left = 0.0  # the residuals after the step, of the stars kept
    for r in range(2 * n):
        if skip >= 0 and (r == skip or r == skip + n):
            continue
        e = res[r]
        for a in range(4):
            e += J[r, a] * step[a]
        left += e * e
    s2 = left / max(2 * n - (2 if skip >= 0 else 0) - 4, 1)
    if sigma_px > 0:
        s2 *= variance_scale(s2, sigma_px)
    var = s2 / L[3, 3] ** 2  # (J^T J)^-1 [3, 3]
    f = f0 * math.exp(step[3])
    return f, f * math.sqrt(max(var, 0.0))


@njit(cache=True)
def free_focal_step(R, icrs, xy, model, p, sigma_px=0.0):
    """(focal length px, its 1-sigma) the stars fit, by one Gauss-Newton step with the focal
    length freed from the attitude ``R`` at the camera ``p`` (``R`` of a fit that held the
    focal length, or of one that freed it, as the scale test on a free fit's pairs passes).
    The 1-sigma is at the a-posteriori variance, at least ``sigma_px``² (``variance_scale``;
    0: no floor)."""
    res, J, N, g = focal_system(R, icrs, xy, model, p)
    return focal_step(res, J, N, g, p[0], sigma_px)
