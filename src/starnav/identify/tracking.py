"""Tracking: identification near a known previous attitude.

With a prior attitude good to ``sigma_deg``, the stars in view can only be catalog stars within
the field plus 3 sigma of the prior boresight. The triangle search of ``pyramid`` runs on the
pair table with only those stars allowed (a mask over the catalog): few hypotheses, so it is
fast, and the false-match probability is reckoned over those hypotheses only — the prior has
legitimately removed the rest of the sky. The parity is the prior's. When nothing verifies, the
caller falls back to lost-in-space.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.pyramid import FEWER_THAN_3, match_triangles, triangle_order


class Tracking:
    """Identification in the neighbourhood of ``R_prior`` (``R_cam_from_icrs``), which is good
    to ``sigma_deg`` (1-sigma, any axis)."""

    name = "tracking"

    def __init__(self, *, R_prior: np.ndarray, sigma_deg: float) -> None:
        self.R_prior = np.ascontiguousarray(R_prior, dtype=np.float64)
        self.sigma_rad = float(np.radians(sigma_deg))
        self.parity = 1 if np.linalg.det(self.R_prior) > 0 else -1

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (its grid finds the neighbourhood)."""
        return database.nbytes

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify ``bearings`` (n, 3) among the catalog stars near the prior."""
        order = np.asarray(order)[: settings.max_stars]
        if len(order) < 3:
            return IdentifyOutcome(None, FEWER_THAN_3, 0)
        from starnav.identify.kernels.sky import prior_mask

        bearings = np.ascontiguousarray(bearings, dtype=np.float64)
        allowed = prior_mask(
            bearings, self.R_prior, settings.match_radius_rad, self.sigma_rad, database.sky
        )
        return match_triangles(
            bearings,
            order[triangle_order(len(order))],
            database,
            replace(settings, parity=self.parity),
            allowed=allowed,
            order=order,
        )
