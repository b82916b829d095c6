"""Wahba's problem by SVD (Markley 1988) with the determinant guard."""

from __future__ import annotations

import numpy as np

_MIRROR = np.diag([1.0, -1.0, 1.0])


def wahba(
    cam_vectors: np.ndarray,
    icrs_vectors: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    parity: int = 1,
) -> np.ndarray:
    """``R_cam_from_icrs`` minimising sum w |b - R r|^2 for pairs of unit vectors (n, 3).

    With ``parity=-1`` the camera is mirrored (y flipped on the sky): the result then has
    determinant -1 and still maps ICRS vectors to camera vectors.
    """
    b = np.asarray(cam_vectors, dtype=float)
    r = np.asarray(icrs_vectors, dtype=float)
    if parity < 0:
        b = b @ _MIRROR
    w = np.ones(len(b)) if weights is None else np.asarray(weights, dtype=float)
    B = (b * w[:, None]).T @ r
    U, _, Vt = np.linalg.svd(B)
    guard = np.diag([1.0, 1.0, np.linalg.det(U) * np.linalg.det(Vt)])
    R = U @ guard @ Vt
    return _MIRROR @ R if parity < 0 else R
