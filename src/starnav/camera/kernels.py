"""Projection kernels of the lens models (numba; plain Python under ``NUMBA_DISABLE_JIT=1``).

The one place a projection is written. A model is a code (``PINHOLE``, ...) and a parameter
vector ``p``; ``project`` and ``unproject`` dispatch on the code, so the attitude fit, the
verification and the Python camera classes all call the same arithmetic. Intrinsic
parameters the fit can free are the model's columns of ``J_p``: log focal length, then the
model's coefficients (``N_COEFFICIENTS`` of them; the pinhole's k1, k2, Kannala-Brandt's
k1..k4, none for the ideal fisheyes).

Pinhole: ``p = [focal_px, cx, cy, k1, k2]``, r = f tan(θ) (1 + k1 tan²θ + k2 tan⁴θ).
Radial (fisheye) models: ``p = [focal_px, cx, cy, k1, k2, k3, k4, theta_limit_rad]``,
r = f g(θ) with g(θ) = θ (equidistant), 2 sin(θ/2) (equisolid), 2 tan(θ/2)
(stereographic), sin θ (orthographic), θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)
(Kannala-Brandt, OpenCV's fisheye model); θ, the angle from the optical axis, may pass 90°
(directions behind the image plane); ``theta_limit_rad`` is the half-angle of the lens's
image circle (π: the whole image).

Pixels: x right, y down, origin at the top-left corner; camera frame x right, y down, z out
along the boresight.
"""

from __future__ import annotations

import math

import numpy as np

from starnav.runtime.caching import njit

PINHOLE = 0
EQUIDISTANT = 1
EQUISOLID = 2
STEREOGRAPHIC = 3
ORTHOGRAPHIC = 4
KANNALA_BRANDT = 5
N_INTRINSIC = 5  # columns of J_p: d/d(log focal), then up to 4 coefficients
THETA_LIMIT = 7  # index of the radial models' image-circle half-angle in ``p``
_ON_AXIS = 1e-15  # |(c0, c1)| below which a direction is on the optical axis
MARGIN_RAD = 0.01  # directions this far beyond the corner angle are still projected
_UNDISTORT_STEPS = 20


@njit(cache=True)
def _pinhole_project(p, c0, c1, c2, J_c, J_p):
    f, cx, cy, k1, k2 = p[0], p[1], p[2], p[3], p[4]
    inv = 1.0 / c2
    u, v = c0 * inv, c1 * inv
    r2 = u * u + v * v
    d = 1.0 + k1 * r2 + k2 * r2 * r2  # radial factor
    dd = k1 + 2.0 * k2 * r2  # its derivative in r^2
    # the distorted (u d, v d) moved by the undistorted (u, v)
    xu, xv = f * (d + 2.0 * u * u * dd), f * (2.0 * u * v * dd)
    yu, yv = xv, f * (d + 2.0 * v * v * dd)
    # u = c0 / c2, v = c1 / c2
    J_c[0, 0], J_c[0, 1], J_c[0, 2] = xu * inv, xv * inv, -(xu * u + xv * v) * inv
    J_c[1, 0], J_c[1, 1], J_c[1, 2] = yu * inv, yv * inv, -(yu * u + yv * v) * inv
    x, y = cx + f * u * d, cy + f * v * d
    J_p[0, 0], J_p[1, 0] = f * u * d, f * v * d  # focal = f0 exp(q): d/dq = f d/df
    J_p[0, 1], J_p[1, 1] = f * u * r2, f * v * r2
    J_p[0, 2], J_p[1, 2] = f * u * r2 * r2, f * v * r2 * r2
    J_p[0, 3], J_p[1, 3], J_p[0, 4], J_p[1, 4] = 0.0, 0.0, 0.0, 0.0
    return x, y


@njit(cache=True)
def n_coefficients(model):
    """How many distortion coefficients the model has (columns 1.. of ``J_p``)."""
    if model == PINHOLE:
        return 2
    if model == KANNALA_BRANDT:
        return 4
    return 0


@njit(cache=True)
def radial_g(model, p, theta):
    """(g(θ), dg/dθ): the image radius over the focal length at θ (rad) from the axis, and
    its slope (the pinhole's with its distortion)."""
    if model == PINHOLE:
        u = math.tan(theta)
        u2 = u * u
        d = 1.0 + p[3] * u2 + p[4] * u2 * u2
        dd = p[3] + 2.0 * p[4] * u2
        return u * d, (d + 2.0 * u2 * dd) * (1.0 + u2)
    if model == EQUIDISTANT:
        return theta, 1.0
    if model == EQUISOLID:
        return 2.0 * math.sin(0.5 * theta), math.cos(0.5 * theta)
    if model == STEREOGRAPHIC:
        c = math.cos(0.5 * theta)
        return 2.0 * math.tan(0.5 * theta), 1.0 / (c * c)
    if model == ORTHOGRAPHIC:
        return math.sin(theta), math.cos(theta)
    if model == KANNALA_BRANDT:
        t2 = theta * theta
        k1, k2, k3, k4 = p[3], p[4], p[5], p[6]
        poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
        slope = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
        return theta * poly, slope
    raise ValueError("unknown camera model code")


@njit(cache=True)
def model_theta_max(model):
    """The largest angle from the axis (rad) a radial model maps before its radius stops
    growing (Kannala-Brandt: π; its coefficients are checked where the camera is made)."""
    if model == ORTHOGRAPHIC:
        return 0.5 * math.pi
    if model == STEREOGRAPHIC:
        return 0.99 * math.pi
    return math.pi


@njit(cache=True)
def radial_theta(model, p, rho):
    """The angle θ (rad) whose g(θ) is ``rho`` (image radius over focal length), clamped
    to the model's range."""
    top = model_theta_max(model)
    if model == EQUIDISTANT:
        return min(rho, top)
    if model == EQUISOLID:
        return 2.0 * math.asin(min(0.5 * rho, 1.0))
    if model == STEREOGRAPHIC:
        return min(2.0 * math.atan(0.5 * rho), top)
    if model == ORTHOGRAPHIC:
        return math.asin(min(rho, 1.0))
    # Kannala-Brandt: Newton from θ = rho, kept in [0, π]
    theta = min(rho, top)
    for _ in range(_UNDISTORT_STEPS):
        g, slope = radial_g(model, p, theta)
        if slope <= 0.0:
            break
        step = (g - rho) / slope
        theta = min(max(theta - step, 0.0), top)
        if abs(step) < 1e-15:
            break
    return theta


@njit(cache=True)
def _radial_project(model, p, c0, c1, c2, J_c, J_p):
    f, cx, cy = p[0], p[1], p[2]
    s = math.hypot(c0, c1)
    n2 = s * s + c2 * c2
    for i in range(2):
        for k in range(N_INTRINSIC):
            J_p[i, k] = 0.0
    if s < _ON_AXIS * math.sqrt(n2):  # on the axis: x = cx + f c0 / c2 to first order
        scale = f / c2 if c2 > 0.0 else 0.0
        J_c[0, 0], J_c[0, 1], J_c[0, 2] = scale, 0.0, 0.0
        J_c[1, 0], J_c[1, 1], J_c[1, 2] = 0.0, scale, 0.0
        return cx + scale * c0, cy + scale * c1
    theta = math.atan2(s, c2)
    g, slope = radial_g(model, p, theta)
    h = g / s  # pixel offset over f, per unit of (c0, c1)
    # d(theta)/dc_j = c2 c_j / (s n2) for j = 0, 1 and -s / n2 for j = 2
    a = slope * c2 / (n2 * s * s) - g / (s * s * s)  # dh/dc_j = a c_j (j = 0, 1)
    b = -slope / n2  # dh/dc2
    J_c[0, 0], J_c[0, 1], J_c[0, 2] = f * (h + a * c0 * c0), f * a * c0 * c1, f * b * c0
    J_c[1, 0], J_c[1, 1], J_c[1, 2] = f * a * c0 * c1, f * (h + a * c1 * c1), f * b * c1
    dx, dy = f * h * c0, f * h * c1
    J_p[0, 0], J_p[1, 0] = dx, dy
    if model == KANNALA_BRANDT:
        power = theta
        t2 = theta * theta
        for k in range(1, 5):
            power *= t2  # theta^(2k + 1)
            J_p[0, k], J_p[1, k] = f * power * c0 / s, f * power * c1 / s
    return cx + dx, cy + dy


@njit(cache=True)
def project(model, p, c0, c1, c2, J_c, J_p):
    """Pixel (x, y) of the camera-frame direction (c0, c1, c2) (c2 > 0 for the pinhole),
    with d(x, y)/dc written to ``J_c`` (2, 3) and d(x, y)/d(intrinsics) to ``J_p``
    (2, ``N_INTRINSIC``)."""
    if model == PINHOLE:
        return _pinhole_project(p, c0, c1, c2, J_c, J_p)
    return _radial_project(model, p, c0, c1, c2, J_c, J_p)


@njit(cache=True)
def unproject(model, p, x, y, out):
    """The unit camera-frame direction of pixel (x, y), written to ``out`` (3,)."""
    if model != PINHOLE:
        dx, dy = (x - p[1]) / p[0], (y - p[2]) / p[0]
        rho = math.hypot(dx, dy)
        theta = radial_theta(model, p, rho)
        if rho > 0.0:
            sin_t = math.sin(theta) / rho
            out[0], out[1] = dx * sin_t, dy * sin_t
        else:
            out[0], out[1] = 0.0, 0.0
        out[2] = math.cos(theta)
        return
    f, cx, cy, k1, k2 = p[0], p[1], p[2], p[3], p[4]
    ud, vd = (x - cx) / f, (y - cy) / f
    u, v = ud, vd
    if k1 != 0.0 or k2 != 0.0:
        # invert the radial model by fixed-point iteration (converges for mild distortion)
        for _ in range(_UNDISTORT_STEPS):
            r2 = u * u + v * v
            factor = 1.0 + k1 * r2 + k2 * r2 * r2
            u, v = ud / factor, vd / factor
    norm = math.sqrt(u * u + v * v + 1.0)
    out[0], out[1], out[2] = u / norm, v / norm, 1.0 / norm


@njit(cache=True)
def half_diagonal(model, p, width, height):
    """Largest angle (rad) between the boresight and a corner of the image (for a radial
    model, within its image circle)."""
    f, cx, cy = p[0], p[1], p[2]
    corner = math.hypot(max(cx, width - cx), max(cy, height - cy)) / f
    if model == PINHOLE:
        return math.atan(corner)
    return min(radial_theta(model, p, corner), p[THETA_LIMIT])


@njit(cache=True)
def field_cos(model, p, width, height):
    """Cosine of the cone about the boresight outside which nothing is in the image."""
    half = half_diagonal(model, p, width, height)
    if model == PINHOLE:
        return math.cos(half + MARGIN_RAD)
    # not past the image circle, nor where the model folds back (orthographic: 90°)
    return math.cos(min(half + MARGIN_RAD, model_theta_max(model), p[THETA_LIMIT]))


@njit(cache=True)
def update(model, p, step, free):
    """The parameters after a fit step: ``step`` holds one value per ``free`` intrinsic
    column, in column order (log focal length multiplies, coefficients add)."""
    q = p.copy()
    used = 0
    if free[0]:
        q[0] = p[0] * math.exp(step[0])
        used = 1
    for k in range(1, N_INTRINSIC):
        if free[k]:
            q[2 + k] = p[2 + k] + step[used]
            used += 1
    return q


@njit(cache=True)
def pixels_to_bearings(model, p, xy):
    """Unit directions (n, 3) of pixels (n, 2)."""
    out = np.empty((len(xy), 3))
    for s in range(len(xy)):
        unproject(model, p, xy[s, 0], xy[s, 1], out[s])
    return out


@njit(cache=True)
def sees_all(model, p, width, height, cos_limit, c):
    """``sees`` for each row of ``c`` (n, 3)."""
    out = np.zeros(len(c), dtype=np.bool_)
    J_c = np.empty((2, 3))
    J_p = np.empty((2, N_INTRINSIC))
    for s in range(len(c)):
        out[s] = sees(model, p, width, height, cos_limit, c[s, 0], c[s, 1], c[s, 2], J_c, J_p)
    return out


@njit(cache=True)
def bearings_at_focals(model, p, xy, focal):
    """Unit directions (m, k, 3) of pixels ``xy`` (m, k, 2), row i seen with the focal length
    ``focal[i]`` (px) and the rest of ``p`` (the FOV search's trial scales)."""
    m, k = xy.shape[0], xy.shape[1]
    out = np.empty((m, k, 3))
    q = p.copy()
    for i in range(m):
        q[0] = focal[i]
        for j in range(k):
            unproject(model, q, xy[i, j, 0], xy[i, j, 1], out[i, j])
    return out


@njit(cache=True)
def project_all(model, p, c):
    """Pixels (n, 2) of directions (n, 3), with the Jacobians in the direction (n, 2, 3) and
    in the intrinsics (n, 2, ``N_INTRINSIC``)."""
    n = len(c)
    xy = np.empty((n, 2))
    J_c = np.empty((n, 2, 3))
    J_p = np.empty((n, 2, N_INTRINSIC))
    for s in range(n):
        xy[s, 0], xy[s, 1] = project(model, p, c[s, 0], c[s, 1], c[s, 2], J_c[s], J_p[s])
    return xy, J_c, J_p


@njit(cache=True)
def bearings_to_pixels(model, p, c):
    """Pixels (n, 2) of camera-frame directions (n, 3)."""
    out = np.empty((len(c), 2))
    J_c = np.empty((2, 3))
    J_p = np.empty((2, N_INTRINSIC))
    for s in range(len(c)):
        out[s, 0], out[s, 1] = project(model, p, c[s, 0], c[s, 1], c[s, 2], J_c, J_p)
    return out


@njit(cache=True)
def sees(model, p, width, height, cos_limit, c0, c1, c2, J_c, J_p):
    """Whether the unit direction lands inside the image (in front of a pinhole, within the
    cone of cosine ``cos_limit``, then projected inside [0, width] x [0, height]); ``J_c``,
    ``J_p``: work space of ``project``."""
    if c2 <= cos_limit or (model == PINHOLE and c2 <= 0.0):
        return False
    x, y = project(model, p, c0, c1, c2, J_c, J_p)
    return 0.0 <= x <= width and 0.0 <= y <= height
