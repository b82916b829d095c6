"""Verification of an attitude hypothesis: reproject the catalog, count agreeing stars, and
compute the probability that a wrong hypothesis would agree as well.

False-match model: with an attitude that is wrong, every measured star that was not used to
make the hypothesis lands within the match radius of some catalog star with probability
``p = n_catalog_in_field * (solid angle of the match circle) / (solid angle of the field)``.
The number of such chance agreements is binomial; the probability of at least the observed
count is multiplied by the number of hypotheses tried (a Bonferroni bound). It is evaluated
at a few match radii (1, 2 and 3.5 sigma): close agreement of few stars and loose agreement of
many both count, and the best is multiplied by the number of radii (Bonferroni again).

The arithmetic and the accept / mirror decision are the kernels of ``identify.kernels``
(``pair_catalog``, ``false_match_radii``, ``test_hypothesis``); this module is their Python
face for the algorithms that propose hypotheses one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.budget import expired
from starnav.identify.base import Identification, IdentifyOutcome, MatchSettings
from starnav.identify.database import PairDatabase

AMBIGUOUS_PARITY = (
    "parity ambiguous: the identified stars are nearly collinear (give the parity to solve)"
)


def kernels():
    """The identification kernels (imported on first use: numba takes ~0.2 s to load)."""
    from starnav.identify import kernels

    return kernels


@dataclass(frozen=True)
class Verification:
    """Agreeing stars of one hypothesis: rows of the bearings and of the catalog, the distance
    of each pair (chord between unit vectors, = angle in radians for small angles);
    ``n_cone`` catalog stars in the field cone whose ``1 - cos(radius)`` is ``field_area``."""

    obs_index: np.ndarray
    cat_index: np.ndarray
    distance_rad: np.ndarray
    n_cone: int
    field_area: float

    def p_chance(self, radius_rad: float) -> float:
        """Chance that a random point lands within ``radius_rad`` of a catalog star."""
        return float(kernels().p_chance(self.n_cone, self.field_area, radius_rad))

    def false_match_probability(
        self, n_stars: int, n_used: int, hypotheses: int, radii_rad: tuple[float, ...]
    ) -> float:
        """False-match probability, the best over the match radii ``radii_rad`` (stars
        agreeing within each), corrected for the number of radii tried."""
        return float(
            kernels().false_match_radii(
                self.distance_rad,
                self.n_cone,
                self.field_area,
                n_stars,
                n_used,
                hypotheses,
                np.asarray(radii_rad, dtype=np.float64),
            )
        )


def field_radius_rad(bearings: np.ndarray, radius_rad: float) -> float:
    """Half-angle (radians) of the cone about the boresight holding every bearing, grown by
    the match radius: the field the chance of agreement is reckoned over."""
    return float(kernels().field_radius(np.ascontiguousarray(bearings, dtype=float), radius_rad))


def match_catalog(
    bearings: np.ndarray,
    R_cam_from_icrs: np.ndarray,
    database: PairDatabase,
    radius_rad: float,
    *,
    rotation_cov_rad2: np.ndarray | None = None,
) -> Verification:
    """Pair bearings with reprojected catalog stars within ``radius_rad``, one to one, with
    the least total squared distance (so close doubles are not both given one star).

    ``rotation_cov_rad2`` (3, 3): the covariance of the attitude (a small rotation about the
    camera axes, radians squared); when given, each catalog star's radius grows by 3 times
    its predicted position error, so that a star far from the ones that made a poorly fixed
    attitude (e.g. all in one corner) can still be found.
    """
    k = kernels()
    gate = rotation_cov_rad2 is not None
    cov = np.zeros((3, 3)) if rotation_cov_rad2 is None else rotation_cov_rad2
    v = k.pair_catalog(
        np.ascontiguousarray(bearings, dtype=np.float64),
        np.ascontiguousarray(R_cam_from_icrs, dtype=np.float64),
        database.sky,
        database.everything,
        float(radius_rad),
        np.ascontiguousarray(cov, dtype=np.float64),
        gate,
        np.empty(len(database.catalog), dtype=np.int64),
    )
    return Verification(
        v.obs.astype(np.intp), v.cat.astype(np.intp), v.dist, int(v.n_cone), float(v.field_area)
    )


def false_match_probability(
    n_stars: int, n_agree: int, n_used: int, p_chance: float, hypotheses: int
) -> float:
    """Chance that a wrong hypothesis makes ``n_agree`` of ``n_stars`` agree.

    ``n_used`` stars built the hypothesis (they agree by construction); each of the other
    ``n_stars - n_used`` agrees by chance with probability ``p_chance``.
    """
    return float(kernels().false_match(n_stars, n_agree, n_used, p_chance, hypotheses))


@dataclass
class Tally:
    """What a search has tried: ``hypotheses`` generated, ``proposed`` for verification and
    the best false-match probability seen (shared by every tester of one search)."""

    hypotheses: int = 0
    proposed: int = 0
    best_p: float = 1.0


class HypothesisTester:
    """The verification step every identification algorithm shares.

    An algorithm proposes hypotheses (measured rows paired with catalog rows, and a parity);
    ``test`` runs the one hypothesis test (``identify.kernels.test_hypothesis``): the
    attitude (Wahba), the whole field reprojected, accepted when its false-match probability,
    corrected for every hypothesis counted so far, is below the threshold and its mirror image
    does not verify too. ``outcome`` gives the reason when nothing was accepted. Count
    hypotheses with ``count`` as they are generated (before screening), so the correction
    covers all of them. A ``tally`` may be shared by the testers of one search (the FOV
    search tests each focal length with its own bearings), and with it the ``work`` space.
    """

    def __init__(
        self,
        bearings: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
        tally: Tally | None = None,
        allowed: np.ndarray | None = None,
        work: np.ndarray | None = None,
    ) -> None:
        self.bearings = np.ascontiguousarray(bearings, dtype=np.float64)
        self.database = database
        self.settings = settings
        self.tally = tally if tally is not None else Tally()
        self.allowed = database.everything if allowed is None else allowed
        self._radii = np.asarray(settings.match_radii_rad, dtype=np.float64)
        # one int64 per catalog row: the kernels' work space (a search may share one; made
        # on the first test, as the triangle search only uses the tally and outcome)
        self._work = work

    @property
    def hypotheses(self) -> int:
        """Hypotheses generated so far (in the whole tally)."""
        return self.tally.hypotheses

    def count(self, n: int) -> None:
        """Record ``n`` more hypotheses generated."""
        self.tally.hypotheses += int(n)

    @property
    def exhausted(self) -> bool:
        """Whether the hypothesis budget or the time budget of the settings is spent."""
        return self.tally.hypotheses >= self.settings.max_hypotheses or expired(
            self.settings.deadline
        )

    def test(
        self, obs_rows: np.ndarray, cat_rows: np.ndarray, parity: int
    ) -> IdentifyOutcome | None:
        """Verify one hypothesis; an outcome when it is accepted or found ambiguous."""
        k = kernels()
        self.tally.proposed += 1
        s = self.settings
        if self._work is None:
            self._work = np.empty(len(self.database.catalog), dtype=np.int64)
        r = k.test_hypothesis(
            self.bearings,
            np.ascontiguousarray(obs_rows, dtype=np.int64),
            np.ascontiguousarray(cat_rows, dtype=np.int64),
            int(parity),
            self.database.sky,
            self.allowed,
            self._radii,
            self.tally.hypotheses,
            s.max_false_match_probability,
            s.parity or 0,
            self._work,
        )
        return self.tested(r.status, r.obs, r.cat, r.R, int(parity), float(r.p))

    def tested(self, status, obs, cat, R, parity: int, p: float) -> IdentifyOutcome | None:
        """The outcome of a kernel's test (None when rejected), the tally updated."""
        k = kernels()
        self.tally.best_p = min(self.tally.best_p, p)
        if status == k.REJECTED:
            return None
        if status == k.AMBIGUOUS:
            return IdentifyOutcome(None, AMBIGUOUS_PARITY, self.tally.hypotheses)
        found = Identification(
            obs.astype(np.intp), cat.astype(np.intp), R, parity, p, self.tally.hypotheses
        )
        return IdentifyOutcome(found, "", self.tally.hypotheses)

    def outcome(
        self, nothing_matched: str = "no star pattern matches the catalog"
    ) -> IdentifyOutcome:
        """The outcome when no hypothesis was accepted."""
        t = self.tally
        reason = not_found_reason(
            t.hypotheses, t.proposed, t.best_p, self.settings, nothing_matched
        )
        return IdentifyOutcome(None, reason, t.hypotheses)


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
    if expired(settings.deadline):
        return settings.deadline.reason(f"{hypotheses} hypotheses, {proposed} verified")
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
