"""Attitude from matched vector pairs: Wahba's problem, then least squares on the image."""

from starnav.attitude.refine import Refinement, refine_attitude
from starnav.attitude.wahba import wahba

__all__ = ["Refinement", "refine_attitude", "wahba"]
