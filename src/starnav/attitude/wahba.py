"""Wahba's problem by SVD (Markley 1988) with the determinant guard."""

from __future__ import annotations

import numpy as np


def wahba(
    cam_vectors: np.ndarray,
    icrs_vectors: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    parity: int = 1,
) -> np.ndarray:
    """``R_cam_from_icrs`` minimising sum w |b - R r|^2 for pairs of unit vectors (n, 3).

    With ``parity=-1`` the camera is mirrored (y flipped on the sky): the result then has
    determinant -1 and still maps ICRS vectors to camera vectors. The arithmetic is the
    kernel ``attitude.rotation.wahba`` the identification uses.
    """
    from starnav.attitude import rotation  # numba: loaded on first use

    b = np.ascontiguousarray(cam_vectors, dtype=np.float64).reshape(-1, 3)
    r = np.ascontiguousarray(icrs_vectors, dtype=np.float64).reshape(-1, 3)
    w = np.ones(len(b)) if weights is None else np.ascontiguousarray(weights, dtype=np.float64)
    return rotation.wahba(b, r, w, -1 if parity < 0 else 1)
