"""Verification of an attitude hypothesis: reproject the catalog, pair the agreeing stars, and
compute the probability that the answer is wrong.

The false-match probability is ``len(sigmas) * hypotheses / Lambda``: Lambda is the product
over the points (but the ones that built the hypothesis) of the likelihood ratio of "right
hypothesis" (a point is a catalog star with chance 1/2, off it by a 2-D Gaussian of the
centroid sigma; or a false point) against "wrong hypothesis" (points fall anywhere on the
field, near a catalog star at the field's catalog density). Every ratio has expectation 1
under a wrong hypothesis, so by Markov's inequality, over the hypotheses tried, a wrong answer
reaches p <= alpha with probability at most alpha. A star's score grows as its residual
shrinks relative to the sigma, and falls with the catalog density; a point with no star
near it lowers the odds. With no sigma told, the best of a few sigmas is taken (their number
multiplies p). Derivation and calibration: docs/verification.md.

The arithmetic and the accept / mirror decision are the kernels of ``identify.kernels``
(``pairing.pair_catalog``, ``evidence.false_match``, ``hypothesis.test_hypothesis``),
imported on first use (numba takes ~0.2 s to load); this module is their Python face for the
algorithms that propose hypotheses one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.identify.base import Identification, IdentifyOutcome, MatchSettings
from starnav.identify.database import PairDatabase
from starnav.runtime.budget import expired

AMBIGUOUS_PARITY = (
    "parity ambiguous: the identified stars are nearly collinear (give the parity to solve)"
)


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

    def false_match_probability(
        self,
        n_stars: int,
        n_used: int,
        hypotheses: int,
        settings: MatchSettings,
        log_other: float = 0.0,
    ) -> float:
        """False-match probability of these pairs among ``n_stars`` points, ``n_used`` of
        which built the hypothesis, ``hypotheses`` tried, with other evidence of natural-log
        likelihood ratio ``log_other`` (``identify.kernels.evidence.false_match``)."""
        from starnav.identify.kernels.evidence import false_match

        radius, sigmas = settings.kernel_args()
        return float(
            false_match(
                self.distance_rad,
                self.n_cone,
                self.field_area,
                n_stars,
                n_used,
                hypotheses,
                sigmas,
                radius,
                log_other,
            )
        )


def field_radius_rad(bearings: np.ndarray, radius_rad: float) -> float:
    """Half-angle (radians) of the cone about the boresight holding every bearing, grown by
    the match radius: the field the chance of agreement is reckoned over."""
    from starnav.identify.kernels.sky import field_radius

    return float(field_radius(np.ascontiguousarray(bearings, dtype=float), radius_rad))


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
    from starnav.identify.kernels.pairing import pair_catalog

    gate = rotation_cov_rad2 is not None
    cov = np.zeros((3, 3)) if rotation_cov_rad2 is None else rotation_cov_rad2
    v = pair_catalog(
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


def point_ranks(order: np.ndarray | None, n: int) -> np.ndarray:
    """The place (0: first) of each of ``n`` points in their ``order`` (rows best-first;
    None: as given), -1 for the rows it leaves out."""
    if order is None:
        return np.arange(n, dtype=np.int64)
    rank = np.full(n, -1, dtype=np.int64)
    order = np.asarray(order, dtype=np.int64)
    rank[order] = np.arange(len(order))
    return rank


def kernel_point_mags(point_mag: np.ndarray | None, n: int) -> np.ndarray:
    """The ``n`` points' magnitudes ``point_mag`` as the kernels take them (empty: not
    known)."""
    if point_mag is None:
        return np.empty(0)
    mags = np.ascontiguousarray(point_mag, dtype=np.float64)
    if len(mags) != n:
        raise ValueError(f"{len(mags)} point magnitudes for {n} points")
    return mags


def catalog_mags(database: PairDatabase, ranked: bool) -> np.ndarray:
    """The magnitudes of the database's catalog rows as the kernels take them when the
    points' order is their brightness's (``ranked``), else none (no brightness evidence)."""
    if not ranked:
        return np.empty(0)
    return database.mags


def best_case_probability(
    n_stars: int, n_agree: int, hypotheses: int, field_rad: float, settings: MatchSettings
) -> float:
    """The smallest false-match probability a three-star hypothesis with ``n_agree`` of
    ``n_stars`` points agreeing could reach on a field cone of half-angle ``field_rad``
    holding a single catalog star, with the brightness at its best on any field and no point
    scored but the agreeing ones (no field scores better): a screen bound; a hypothesis that
    cannot beat the threshold even so is not verified."""
    from starnav.identify.kernels.evidence import best_case_false_match, brightness_log_bound

    radius, sigmas = settings.kernel_args()
    area = 1.0 - np.cos(field_rad)
    bright = brightness_log_bound(n_agree, 3, 1e9, settings.ranked)
    n = min(n_agree, n_stars)
    return float(best_case_false_match(n, n, 3, 1, area, hypotheses, sigmas, radius, bright))


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
    ``test`` runs the one hypothesis test (``identify.kernels.hypothesis``): the
    attitude (Wahba), the whole field reprojected, accepted when its false-match probability,
    corrected for every hypothesis counted so far, is below the threshold and its mirror image
    does not verify too. ``outcome`` gives the reason when nothing was accepted. Count
    hypotheses with ``count`` as they are generated (before screening), so the correction
    covers all of them. A ``tally`` may be shared by the testers of one search (the FOV
    search tests each focal length with its own bearings), and with it the ``work`` space.
    ``order``: the rows best-first, whose brightness the statistic weighs when
    ``settings.ranked``.
    """

    def __init__(
        self,
        bearings: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
        tally: Tally | None = None,
        allowed: np.ndarray | None = None,
        work: np.ndarray | None = None,
        order: np.ndarray | None = None,
    ) -> None:
        self.bearings = np.ascontiguousarray(bearings, dtype=np.float64)
        self.database = database
        self.settings = settings
        self.tally = tally if tally is not None else Tally()
        self.allowed = database.everything if allowed is None else allowed
        self.rank = point_ranks(order, len(self.bearings))
        self.mags = catalog_mags(database, settings.ranked)
        self.point_mag = kernel_point_mags(settings.point_mag, len(self.bearings))
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
        from starnav.identify.kernels.hypothesis import test_hypothesis

        self.tally.proposed += 1
        s = self.settings
        if self._work is None:
            self._work = np.empty(len(self.database.catalog), dtype=np.int64)
        r = test_hypothesis(
            self.bearings,
            np.ascontiguousarray(obs_rows, dtype=np.int64),
            np.ascontiguousarray(cat_rows, dtype=np.int64),
            int(parity),
            self.database.sky,
            self.allowed,
            *s.kernel_args(),
            0.0,  # hypotheses not from a triangle look-up: no side evidence
            self.rank,
            self.point_mag,
            self.mags,
            len(obs_rows),  # their own stars may be from tables of bright stars
            self.tally.hypotheses,
            s.max_false_match_probability,
            s.parity or 0,
            self._work,
        )
        return self.tested(
            r.status, r.obs, r.cat, r.R, int(parity), float(r.p), bright_drop=len(obs_rows)
        )

    def tested(
        self,
        status,
        obs,
        cat,
        R,
        parity: int,
        p: float,
        log_sides: float = 0.0,
        bright_drop: int = 4,
    ) -> IdentifyOutcome | None:
        """The outcome of a kernel's test (None when rejected), the tally updated."""
        from starnav.identify.kernels.hypothesis import AMBIGUOUS, REJECTED

        self.tally.best_p = min(self.tally.best_p, p)
        if status == REJECTED:
            return None
        if status == AMBIGUOUS:
            return IdentifyOutcome(None, AMBIGUOUS_PARITY, self.tally.hypotheses)
        found = Identification(
            obs.astype(np.intp),
            cat.astype(np.intp),
            R,
            parity,
            p,
            self.tally.hypotheses,
            float(log_sides),
            int(bright_drop),
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
