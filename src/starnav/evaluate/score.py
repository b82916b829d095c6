"""Whether an answer is right: the one rule by which ``starnav evaluate`` and the benchmarks
(``benchmarks/harness.py``) score an attitude against the truth.

An answer is correct when it has the truth's parity and its boresight is within
``CORRECT_BORESIGHT_DEG`` of the truth's and its roll about the boresight within
``CORRECT_ROLL_DEG``, or when both errors are within ``CORRECT_SIGMAS`` of the answer's own
reported 1-sigma errors (as with 2 px noise and few stars; NaN or unreported sigmas never
vouch for an answer); else it is wrong. The parity is compared because a mirrored attitude
differs from its unmirrored twin by no angle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from starnav.geometry import attitude_difference_deg

if TYPE_CHECKING:
    from starnav.results import Solution

CORRECT_BORESIGHT_DEG = 0.05  # a solution is correct within this and ...
CORRECT_ROLL_DEG = 0.5  # ... this of the truth,
CORRECT_SIGMAS = 5.0  # or within this many of its own reported 1-sigma errors; else wrong


@dataclass(frozen=True)
class AttitudeScore:
    """An answer against the truth: its boresight and roll errors (degrees; roll: the
    rotation about the boresight), whether its parity is the truth's (True when it reported
    none), whether both errors are within the fixed tolerance, and whether both are within
    ``CORRECT_SIGMAS`` of its own reported sigmas."""

    boresight_deg: float
    roll_deg: float
    same_parity: bool
    within_tolerance: bool
    within_sigmas: bool

    @property
    def correct(self) -> bool:
        """The rule of this module."""
        return bool(self.same_parity and (self.within_tolerance or self.within_sigmas))

    @property
    def boresight_arcsec(self) -> float:
        return self.boresight_deg * 3600.0

    @property
    def roll_arcsec(self) -> float:
        return self.roll_deg * 3600.0


def parity_of(R: np.ndarray) -> int:
    """+1 for a rotation, -1 for a mirrored attitude (determinant -1)."""
    return 1 if np.linalg.det(R) > 0 else -1


def score_attitude(
    R_cam_from_icrs: np.ndarray,
    R_true: np.ndarray,
    *,
    parity: int | None = None,
    sigma_boresight_arcsec: float = float("nan"),
    sigma_roll_arcsec: float = float("nan"),
) -> AttitudeScore:
    """An attitude against the true one: ``parity`` the answer's (None: not reported),
    the sigmas its reported 1-sigma errors (NaN: none)."""
    boresight_deg, roll_deg = attitude_difference_deg(R_cam_from_icrs, R_true)
    within_tolerance = boresight_deg < CORRECT_BORESIGHT_DEG and roll_deg < CORRECT_ROLL_DEG
    # NaN sigmas (undetermined) never vouch for an answer
    within_sigmas = (
        boresight_deg * 3600.0 <= CORRECT_SIGMAS * sigma_boresight_arcsec
        and roll_deg * 3600.0 <= CORRECT_SIGMAS * sigma_roll_arcsec
    )
    same_parity = parity is None or parity == parity_of(R_true)
    return AttitudeScore(
        boresight_deg=boresight_deg,
        roll_deg=roll_deg,
        same_parity=bool(same_parity),
        within_tolerance=bool(within_tolerance),
        within_sigmas=bool(within_sigmas),
    )


def score_solution(solution: Solution, R_true: np.ndarray) -> AttitudeScore:
    """``score_attitude`` of a solver's ``Solution``: its attitude, parity and sigmas."""
    return score_attitude(
        solution.R_cam_from_icrs,
        R_true,
        parity=solution.parity,
        sigma_boresight_arcsec=solution.sigma_boresight_arcsec,
        sigma_roll_arcsec=solution.sigma_roll_arcsec,
    )
