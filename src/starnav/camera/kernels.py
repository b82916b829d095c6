"""Projection kernels of the lens models (numba; plain Python under ``NUMBA_DISABLE_JIT=1``).

The one place a projection is written. A model is a code (``PINHOLE``, ...) and a parameter
vector ``p``; ``project`` and ``unproject`` dispatch on the code, so the attitude fit, the
verification and the Python ``Camera`` methods all call the same arithmetic. Intrinsic
parameters the fit can free are the model's columns of ``J_p``: for the pinhole
(``p = [focal_px, cx, cy, k1, k2]``) they are log focal length, k1 and k2.

Pixels: x right, y down, origin at the top-left corner; camera frame x right, y down, z out
along the boresight.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

PINHOLE = 0
N_INTRINSIC = 3  # columns of J_p: d/d(log focal), then the model's coefficients
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
    return x, y


@njit(cache=True)
def project(model, p, c0, c1, c2, J_c, J_p):
    """Pixel (x, y) of the camera-frame direction (c0, c1, c2) (c2 > 0 for the pinhole),
    with d(x, y)/dc written to ``J_c`` (2, 3) and d(x, y)/d(intrinsics) to ``J_p``
    (2, ``N_INTRINSIC``)."""
    if model == PINHOLE:
        return _pinhole_project(p, c0, c1, c2, J_c, J_p)
    raise ValueError("unknown camera model code")


@njit(cache=True)
def unproject(model, p, x, y, out):
    """The unit camera-frame direction of pixel (x, y), written to ``out`` (3,)."""
    if model != PINHOLE:
        raise ValueError("unknown camera model code")
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
    """Largest angle (rad) between the boresight and a corner of the image."""
    if model != PINHOLE:
        raise ValueError("unknown camera model code")
    f, cx, cy = p[0], p[1], p[2]
    return math.atan(math.hypot(max(cx, width - cx), max(cy, height - cy)) / f)


@njit(cache=True)
def field_cos(model, p, width, height):
    """Cosine of the cone about the boresight outside which nothing is in the image."""
    return math.cos(half_diagonal(model, p, width, height) + MARGIN_RAD)


@njit(cache=True)
def update(model, p, step, free):
    """The parameters after a fit step: ``step[k]`` applies to intrinsic column k where
    ``free[k]`` (log focal length multiplies, coefficients add)."""
    q = p.copy()
    if free[0]:
        q[0] = p[0] * math.exp(step[0])
    for k in range(1, N_INTRINSIC):
        if free[k]:
            q[2 + k] = p[2 + k] + step[k]
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
    """Whether the direction lands inside the image (in front of the camera, within the cone
    of cosine ``cos_limit``, then projected inside [0, width] x [0, height]); ``J_c``,
    ``J_p``: work space of ``project``."""
    if not (c2 > 0.0 and c2 > cos_limit):
        return False
    x, y = project(model, p, c0, c1, c2, J_c, J_p)
    return 0.0 <= x <= width and 0.0 <= y <= height
