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

from starnav.attitude.wahba import wahba
from starnav.geometry import chord_from_angle
from starnav.identify.base import Identification, IdentifyOutcome, MatchSettings
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
    *,
    rotation_cov_rad2: np.ndarray | None = None,
    gate_sigmas: float = 3.0,
) -> Verification:
    """Pair bearings with reprojected catalog stars within ``radius_rad``, one to one, with
    the least total squared distance (so close doubles are not both given one star).

    ``rotation_cov_rad2`` (3, 3): the covariance of the attitude (a small rotation about the
    camera axes, radians squared); when given, each catalog star's radius grows by
    ``gate_sigmas`` times its predicted position error, so that a star far from the ones that
    made a poorly fixed attitude (e.g. all in one corner) can still be found.
    """
    boresight = R_cam_from_icrs[2]
    field_rad = field_radius_rad(bearings, radius_rad)
    cone = database.cone(boresight, field_rad)
    if len(cone) == 0:
        empty = np.empty(0, dtype=np.intp)
        return Verification(empty, empty, np.empty(0), 0, 1.0 - np.cos(field_rad))
    cam = database.catalog.vectors[cone] @ R_cam_from_icrs.T
    d2 = np.sum((bearings[:, None, :] - cam[None, :, :]) ** 2, axis=2)  # chord squared
    radius2 = np.full(len(cone), chord_from_angle(radius_rad) ** 2)
    if rotation_cov_rad2 is not None and np.all(np.isfinite(rotation_cov_rad2)):
        # a rotation omega moves c by omega x c: E|omega x c|^2 = tr(C) - c^T C c
        C = np.asarray(rotation_cov_rad2)
        var = np.trace(C) - np.einsum("ni,ij,nj->n", cam, C, cam)
        radius2 += gate_sigmas**2 * np.maximum(var, 0.0)
    within = d2 <= radius2[None, :]
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


class HypothesisTester:
    """The verification step every identification algorithm shares.

    An algorithm proposes hypotheses (measured rows paired with catalog rows, and a parity);
    ``test`` builds the attitude (Wahba), reprojects the catalog, and accepts the hypothesis
    when its false-match probability, corrected for every hypothesis counted so far, is below
    the threshold and its mirror image does not verify too. ``outcome`` gives the reason when
    nothing was accepted. Count hypotheses with ``count`` as they are generated (before
    screening), so the correction covers all of them.
    """

    def __init__(
        self, bearings: np.ndarray, database: PairDatabase, settings: MatchSettings
    ) -> None:
        self.bearings = bearings
        self.database = database
        self.settings = settings
        self.hypotheses = 0
        self.best_p = 1.0
        self.proposed = 0  # hypotheses that reached ``test``

    def count(self, n: int) -> None:
        """Record ``n`` more hypotheses generated."""
        self.hypotheses += int(n)

    @property
    def exhausted(self) -> bool:
        """Whether the hypothesis budget of the settings is spent."""
        return self.hypotheses >= self.settings.max_hypotheses

    def _verify(self, R: np.ndarray, n_used: int) -> tuple[Verification, float]:
        s = self.settings
        ver = match_catalog(self.bearings, R, self.database, s.match_radius_rad)
        p = ver.false_match_probability(
            len(self.bearings), n_used, self.hypotheses, s.match_radii_rad
        )
        return ver, p

    def test(
        self, obs_rows: np.ndarray, cat_rows: np.ndarray, parity: int
    ) -> IdentifyOutcome | None:
        """Verify one hypothesis; an outcome when it is accepted or found ambiguous."""
        self.proposed += 1
        s = self.settings
        vectors = self.database.catalog.vectors
        n_used = len(obs_rows)
        R = wahba(self.bearings[obs_rows], vectors[cat_rows], parity=parity)
        ver, p = self._verify(R, n_used)
        self.best_p = min(self.best_p, p)
        if p > s.max_false_match_probability:
            return None
        if s.parity is None:
            # collinear stars verify in the mirror image as well: then the parity is unknown
            R_mirror = wahba(self.bearings[ver.obs_index], vectors[ver.cat_index], parity=-parity)
            _, p_mirror = self._verify(R_mirror, n_used)
            if p_mirror <= s.max_false_match_probability:
                return IdentifyOutcome(
                    None,
                    "parity ambiguous: the identified stars are nearly collinear "
                    "(give the parity to solve)",
                    self.hypotheses,
                )
        found = Identification(ver.obs_index, ver.cat_index, R, parity, p, self.hypotheses)
        return IdentifyOutcome(found, "", self.hypotheses)

    def outcome(
        self, nothing_matched: str = "no star pattern matches the catalog"
    ) -> IdentifyOutcome:
        """The outcome when no hypothesis was accepted."""
        reason = not_found_reason(
            self.hypotheses, self.proposed, self.best_p, self.settings, nothing_matched
        )
        return IdentifyOutcome(None, reason, self.hypotheses)


def not_found_reason(
    hypotheses: int,
    proposed: int,
    best_p: float,
    settings: MatchSettings,
    nothing_matched: str,
) -> str:
    """Why no hypothesis was accepted, from the count of ``hypotheses`` generated, of those
    ``proposed`` for verification and the best false-match probability ``best_p`` seen;
    ``nothing_matched`` when no hypothesis was generated."""
    if hypotheses >= settings.max_hypotheses:
        return f"gave up after {hypotheses} hypotheses"
    if hypotheses == 0:
        return nothing_matched
    if proposed == 0:
        return "no hypothesis had enough agreeing stars to be worth verifying"
    if best_p < 1.0:
        return (
            f"best hypothesis not convincing (false-match probability {best_p:.2g} > "
            f"{settings.max_false_match_probability:g})"
        )
    return "no hypothesis agreed with enough stars to be convincing"
