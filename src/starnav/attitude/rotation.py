"""Rotation kernels (numba; plain Python under ``NUMBA_DISABLE_JIT=1``): the nearest
rotation, Wahba's problem and the small-rotation update, shared by the identification's
hypotheses and the attitude fit. They need no camera: identification imports them alone.
"""

from __future__ import annotations

import math

import numpy as np

from starnav.runtime.caching import njit


@njit(cache=True)
def det3(a, b, c):
    """det[a, b, c] of three 3-vectors."""
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


@njit(cache=True)
def nearest_rotation(B):
    """The rotation nearest to B (3x3): U diag(1, 1, det(U V^T)) V^T of B's SVD. With
    det(B) clearly positive it is B's orthogonal polar factor, found by Newton's iteration
    X <- (g X + X^-T / g) / 2 (Higham; a few 3x3 inverses instead of an SVD); otherwise,
    or if that does not settle to 1e-15, by LAPACK's SVD."""
    scale = math.sqrt(np.sum(B * B))
    det = det3(B[0], B[1], B[2])
    if scale > 0.0 and det > 1e-12 * scale**3:
        X = B / scale
        C = np.empty((3, 3))  # X^-T: the cofactor matrix over the determinant
        Y = np.empty((3, 3))  # the next iterate (the two swap: no array made in the loop)
        for _ in range(30):
            d = det3(X[0], X[1], X[2])
            for i in range(3):
                i1, i2 = (i + 1) % 3, (i + 2) % 3
                for j in range(3):
                    j1, j2 = (j + 1) % 3, (j + 2) % 3
                    C[i, j] = (X[i1, j1] * X[i2, j2] - X[i1, j2] * X[i2, j1]) / d
            g = (abs(d) ** (-1.0 / 3.0)) if abs(d) > 0 else 1.0  # determinant scaling
            change = 0.0
            for i in range(3):
                for j in range(3):
                    Y[i, j] = 0.5 * (g * X[i, j] + C[i, j] / g)
                    change = max(change, abs(Y[i, j] - X[i, j]))
            X, Y = Y, X
            if change < 1e-15 and d == d:  # (a NaN determinant: to the SVD)
                return X
    U, _, Vt = np.linalg.svd(B)
    d = det3(U[:, 0], U[:, 1], U[:, 2]) * det3(Vt[0], Vt[1], Vt[2])
    for i in range(3):
        U[i, 2] *= d
    return U @ Vt


@njit(cache=True)
def wahba(b, r, w, parity):
    """``R_cam_from_icrs`` minimising sum w |b - R r|^2 over pairs (b camera, r ICRS, (n, 3);
    weights ``w`` (n,)); for parity -1 the camera is mirrored (y flipped) and R has
    determinant -1. Markley's SVD method, the determinant guarded."""
    B = np.zeros((3, 3))
    for k in range(len(b)):
        for i in range(3):
            bi = -b[k, i] if (parity < 0 and i == 1) else b[k, i]
            for j in range(3):
                B[i, j] += w[k] * bi * r[k, j]
    R = nearest_rotation(B)
    if parity < 0:
        for j in range(3):
            R[1, j] = -R[1, j]
    return R


@njit(cache=True)
def rotate_by(omega, R0):
    """exp([omega]x) @ R0 (Rodrigues' formula)."""
    angle = math.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    if angle < 1e-300:
        return R0.copy()
    k0, k1, k2 = omega[0] / angle, omega[1] / angle, omega[2] / angle
    K = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    return (np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)) @ R0
