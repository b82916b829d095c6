"""Verification of an attitude hypothesis: reproject the catalog, count agreeing stars, and
compute the probability that a wrong hypothesis would agree as well.

False-match model: with an attitude that is wrong, every measured star that was not used to
make the hypothesis lands within the match radius of some catalog star with probability
``p = n_catalog_in_field * (solid angle of the match circle) / (solid angle of the field)``.
The number of such chance agreements is binomial; the probability of at least the observed
count is multiplied by the number of hypotheses tried (a Bonferroni bound). It is evaluated
at a few match radii (1, 2 and 3.5 sigma): close agreement of few stars and loose agreement of
many both count, and the best is multiplied by the number of radii (Bonferroni again).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.special import betainc

from starnav.geometry import chord_from_angle
from starnav.identify.database import PairDatabase


@dataclass(frozen=True)
class Verification:
    """Agreeing stars of one hypothesis: rows of the bearings and of the catalog, the distance
    of each pair (chord between unit vectors, = angle in radians for small angles);
    ``n_cone`` catalog stars in the field cone whose
    ``1 - cos(radius)`` is ``field_area``."""

    obs_index: np.ndarray
    cat_index: np.ndarray
    distance_rad: np.ndarray
    n_cone: int
    field_area: float

    def p_chance(self, radius_rad: float) -> float:
        """Chance that a random point lands within ``radius_rad`` of a catalog star."""
        if self.field_area <= 0:
            return 1.0
        return min(1.0, self.n_cone * (1.0 - np.cos(radius_rad)) / self.field_area)

    def false_match_probability(
        self, n_stars: int, n_used: int, hypotheses: int, radii_rad: tuple[float, ...]
    ) -> float:
        """False-match probability, the best over the match radii ``radii_rad`` (stars
        agreeing within each), corrected for the number of radii tried."""
        best = 1.0
        for radius in radii_rad:
            n_agree = int(np.sum(self.distance_rad <= chord_from_angle(radius) * (1 + 1e-12)))
            p = false_match_probability(n_stars, n_agree, n_used, self.p_chance(radius), hypotheses)
            best = min(best, p)
        return min(1.0, best * len(radii_rad))


def field_radius_rad(bearings: np.ndarray, radius_rad: float) -> float:
    """Half-angle (radians) of the cone about the boresight holding every bearing, grown by
    the match radius: the field the chance of agreement is reckoned over."""
    return float(np.arccos(np.clip(np.min(bearings[:, 2]), -1.0, 1.0))) + radius_rad


def match_catalog(
    bearings: np.ndarray,
    R_cam_from_icrs: np.ndarray,
    database: PairDatabase,
    radius_rad: float,
) -> Verification:
    """Pair bearings with reprojected catalog stars within ``radius_rad``, one to one, with
    the least total squared distance (so close doubles are not both given one star)."""
    boresight = R_cam_from_icrs[2]
    field_rad = field_radius_rad(bearings, radius_rad)
    cone = database.cone(boresight, field_rad)
    if len(cone) == 0:
        empty = np.empty(0, dtype=np.intp)
        return Verification(empty, empty, np.empty(0), 0, 1.0 - np.cos(field_rad))
    cam = database.catalog.vectors[cone] @ R_cam_from_icrs.T
    d2 = np.sum((bearings[:, None, :] - cam[None, :, :]) ** 2, axis=2)  # chord squared
    within = d2 <= chord_from_angle(radius_rad) ** 2
    rows = np.flatnonzero(within.any(axis=1))
    cols = np.flatnonzero(within.any(axis=0))
    # one-to-one pairing of least total squared distance (matters for close double stars)
    cost = np.where(within[np.ix_(rows, cols)], d2[np.ix_(rows, cols)], 1e6)
    r, c = linear_sum_assignment(cost)
    ok = cost[r, c] < 1e6
    obs, cat = rows[r[ok]], cols[c[ok]]
    dist = np.sqrt(d2[obs, cat])
    return Verification(obs, cone[cat], dist, len(cone), float(1.0 - np.cos(field_rad)))


def false_match_probability(
    n_stars: int, n_agree: int, n_used: int, p_chance: float, hypotheses: int
) -> float:
    """Chance that a wrong hypothesis makes ``n_agree`` of ``n_stars`` agree.

    ``n_used`` stars built the hypothesis (they agree by construction); each of the other
    ``n_stars - n_used`` agrees by chance with probability ``p_chance``.
    """
    trials = n_stars - n_used
    extra = n_agree - n_used
    if extra <= 0 or trials <= 0:
        return 1.0
    # P(X >= extra) for X ~ Binomial(trials, p) is the regularised incomplete beta function
    tail = float(betainc(extra, trials - extra + 1, p_chance))
    return min(1.0, tail * max(hypotheses, 1))
