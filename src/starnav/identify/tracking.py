"""Tracking: identification near a known previous attitude.

With a prior attitude good to ``sigma_deg``, the stars in view can only be catalog stars within
the field plus 3 sigma of the prior boresight. The pair table of just those stars (a few dozen)
is built on the spot and the triangle search of ``pyramid`` runs on it: few hypotheses, so it is
fast, and the false-match probability is reckoned over those hypotheses only — the prior has
legitimately removed the rest of the sky. The parity is the prior's. When nothing verifies, the
caller falls back to lost-in-space.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from starnav.catalog import Catalog
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase, build_pairs
from starnav.identify.pyramid import match_triangles, triangle_order
from starnav.identify.verify import field_radius_rad


def local_database(
    database: PairDatabase, axis: np.ndarray, radius_rad: float
) -> tuple[PairDatabase, np.ndarray]:
    """The pair table of the catalog stars within ``radius_rad`` of ``axis``, and their rows in
    the full catalog (local row k is full row ``rows[k]``)."""
    rows = np.sort(database.cone(axis, radius_rad))  # ascending: the order of the local table
    cat = database.catalog
    sub = Catalog(cat.ids[rows], cat.ra_deg[rows], cat.dec_deg[rows], cat.mag[rows], cat.name)
    vectors = cat.vectors[rows]
    if len(rows) >= 2:
        a, b, angle, tree = build_pairs(vectors, database.max_angle_rad)
    else:
        a = b = np.empty(0, dtype=np.uint16)
        angle, tree = np.empty(0), cKDTree(vectors.reshape(-1, 3))
    sub.__dict__["vectors"] = vectors  # the cached property, without recomputing it
    local = PairDatabase(sub, database.max_angle_rad, a, b, angle, tree, 0.0, False, None)
    return local, rows


class Tracking:
    """Identification in the neighbourhood of ``R_prior`` (``R_cam_from_icrs``), which is good
    to ``sigma_deg`` (1-sigma, any axis)."""

    name = "tracking"

    def __init__(self, *, R_prior: np.ndarray, sigma_deg: float) -> None:
        self.R_prior = np.asarray(R_prior, dtype=float)
        self.sigma_rad = float(np.radians(sigma_deg))

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (its KD-tree finds the neighbourhood)."""
        return database.nbytes

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        order = np.asarray(order)[: settings.max_stars]
        if len(order) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        radius = field_radius_rad(bearings, settings.match_radius_rad) + 3.0 * self.sigma_rad
        local, rows = local_database(database, self.R_prior[2], radius)
        parity = 1 if np.linalg.det(self.R_prior) > 0 else -1
        triangles = (order[list(t)] for t in triangle_order(len(order)))
        outcome = match_triangles(bearings, triangles, local, replace(settings, parity=parity))
        found = outcome.identification
        if found is None:
            return outcome
        return replace(outcome, identification=replace(found, cat_index=rows[found.cat_index]))
