"""Lost-in-space identification by geometric voting (Kolomenkin, Pollak, Yavneh and Tal 2008),
verified by reprojection.

Every measured pair among the first stars looks up the catalog pairs whose angle agrees within
the tolerance and casts a vote for both catalog stars on both measured stars; each measured star's
candidates are the catalog stars voted for most. A validation round (Kolomenkin's second vote)
checks, among the candidates, which pairs have a catalog angle that agrees with the measured
one; the candidates agreeing with the most other stars seed a group that is grown greedily into
a mutually consistent set. The widest triangle of that group is the hypothesis, verified by the
shared ``HypothesisTester``; when it fails, the next group (other candidates, second-best
votes) is tried.

Counting hypotheses. The vote looks at every pair of the voting stars before it chooses: the
triangle it tests was picked, out of all the catalog triangles that agree with some measured
triangle of those stars, *because* its catalog stars have the right angles to the other stars,
and those are the stars the verification then counts as independent chance agreements. A count
of one per tested triangle would let that selection pass as evidence. The count is therefore
the size of the set the vote chose from, a union bound that holds however the choice was made:
the number of catalog triangles that agree with each measured triangle of the voting stars,
summed over all of them (``triangle_hypotheses``; estimated, not enumerated, since enumerating
would cost what the triangle search does). The number of voting stars is the largest that keeps
this count within 90 % of the hypothesis budget. Every tested hypothesis is counted once more on
top.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np

from starnav.geometry import angle_between, triple_product
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.verify import HypothesisTester

# without it the estimate falls short of the enumerated count (``catalog_triangles``) by up to
# 1.2x: the tolerance on the two other sides widens the window. With 2 it was 1.2-1.9 times the
# enumerated count, summed over the triangles of the first 10 stars, on every one of 25
# simulated Hp <= 6 frames per case (12°/512 px and 20°/1024 px, tolerances 1, 2.1, 4.2 px)
_TRIANGLE_COUNT_SAFETY = 2.0
# share of the hypothesis budget the vote may spend: the count grows as the cube of the voting
# stars, and more of them is what the vote needs with wide tolerances (noisy frames at
# sigma_px 1: 95 of 150 solved at half the budget, 136 at 0.9); the rest is left for tests
_VOTE_BUDGET = 0.9


@dataclass(frozen=True)
class PairWindows:
    """Measured angles between ``n`` stars and their windows in the pair database.

    ``angles`` (n, n) radians; ``valid`` (n, n): pairs far enough apart to be separate stars
    (>= 2 tolerances) and close enough to be in the database; ``lo``/``hi`` (n, n): the slice
    of the database's pairs within the tolerance of each measured angle (empty when invalid);
    ``cos_lo``/``cos_hi`` (n, n): the cosines a catalog pair's angle must lie between to agree
    (an empty interval for invalid pairs).
    """

    angles: np.ndarray
    valid: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    cos_lo: np.ndarray
    cos_hi: np.ndarray

    @classmethod
    def measure(cls, bearings: np.ndarray, database: PairDatabase, tol_rad: float) -> PairWindows:
        """Windows of every pair of ``bearings`` (n, 3) at tolerance ``tol_rad``."""
        angles = angle_between(bearings[:, None, :], bearings[None, :, :])
        valid = (angles >= 2.0 * tol_rad) & (angles <= database.max_angle_rad + tol_rad)
        lo = np.searchsorted(database.pair_angle_rad, angles - tol_rad)
        hi = np.searchsorted(database.pair_angle_rad, angles + tol_rad)
        hi = np.where(valid, hi, lo)
        cos_lo = np.where(valid, np.cos(angles + tol_rad), 2.0)
        cos_hi = np.cos(np.maximum(angles - tol_rad, 0.0))
        return cls(angles, valid, lo, hi, cos_lo, cos_hi)

    @property
    def counts(self) -> np.ndarray:
        """Catalog pairs in each window (n, n)."""
        return self.hi - self.lo


def expand_windows(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All database rows of the slices ``lo[m]:hi[m]``, concatenated, and the ``m`` of each."""
    counts = hi - lo
    owner = np.repeat(np.arange(len(lo)), counts)
    start = np.cumsum(counts) - counts
    rows = np.arange(int(counts.sum())) - np.repeat(start - lo, counts)
    return owner, rows


def _closing_fraction(d1: np.ndarray, d2: np.ndarray, d3: np.ndarray, tol_rad: float):
    """Fraction of random azimuths between two sides ``d1``, ``d2`` from one star that give a
    third side within ``tol_rad`` of ``d3`` (spherical law of cosines)."""
    denom = np.sin(d1) * np.sin(d2)

    def azimuth(d):
        cos_phi = (np.cos(d) - np.cos(d1) * np.cos(d2)) / np.where(denom > 0, denom, 1.0)
        return np.arccos(np.clip(cos_phi, -1.0, 1.0))

    return (azimuth(d3 + tol_rad) - azimuth(np.maximum(d3 - tol_rad, 0.0))) / np.pi


def triangle_hypotheses(
    bearings: np.ndarray,
    windows: PairWindows,
    triangles: np.ndarray,
    n_catalog: int,
    tol_rad: float,
    *,
    parity_known: bool,
) -> np.ndarray:
    """Expected number of catalog hypotheses for each measured triangle (m,) of ``triangles``
    (m, 3) (rows of ``bearings``): the catalog triangles whose sides agree within ``tol_rad``
    (the true one included), twice for triangles too flat to tell their parity.

    With ``L`` catalog pairs in the window of side pq and ``M`` in that of side pr, a catalog star
    starts on average ``4 L M / n_catalog`` pairs of sides about it; the third side closes for
    the fraction of azimuths between them that ``_closing_fraction`` gives. Averaged over the
    three corners, raised by a safety factor. Triangles with a side that is not a valid pair are
    never tested: 0.
    """
    if len(triangles) == 0:
        return np.zeros(0)
    i, j, k = np.asarray(triangles).T
    n = windows.counts.astype(float)
    a = windows.angles
    wedges = np.zeros(len(i))
    for p, q, r in ((i, j, k), (j, i, k), (k, i, j)):
        closing = _closing_fraction(a[p, q], a[p, r], a[q, r], tol_rad)
        wedges += 4.0 * n[p, q] * n[p, r] / n_catalog * closing
    expected = 1.0 + _TRIANGLE_COUNT_SAFETY * wedges / 3.0
    if not parity_known:
        det = triple_product(bearings[i], bearings[j], bearings[k])
        longest = np.max([a[i, j], a[i, k], a[j, k]], axis=0)
        expected *= np.where(np.abs(det) < 3.0 * tol_rad * longest, 2.0, 1.0)
    ok = windows.valid[i, j] & windows.valid[i, k] & windows.valid[j, k]
    return np.where(ok, expected, 0.0)


@lru_cache(maxsize=64)
def _triples(n: int) -> np.ndarray:
    return np.array(list(combinations(range(n), 3)), dtype=np.intp).reshape(-1, 3)


def consistency(
    obs: np.ndarray, cat: np.ndarray, windows: PairWindows, vectors: np.ndarray
) -> np.ndarray:
    """(m, m) whether candidate identifications ``obs[u] -> cat[u]`` and ``obs[v] -> cat[v]``
    agree: different measured and catalog stars, a valid measured pair, and a catalog angle
    within the tolerance of the measured one (the test ``catalog_triangles`` applies)."""
    w = vectors[cat]
    # einsum, not ``w @ w.T``: BLAS goes multithreaded from a few hundred rows and is then
    # ten times slower on a busy machine
    cos_cat = np.einsum("ik,jk->ij", w, w)
    ok = cos_cat >= windows.cos_lo[obs][:, obs]
    ok &= cos_cat <= windows.cos_hi[obs][:, obs]
    ok &= cat[:, None] != cat[None, :]
    return ok


def support(consistent: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Per candidate, the number of other measured stars with a candidate agreeing with it
    (``obs`` sorted, as the candidates are listed star by star)."""
    starts = np.flatnonzero(np.concatenate([[True], obs[1:] != obs[:-1]]))
    return np.logical_or.reduceat(consistent, starts, axis=1).sum(axis=1)


def grow_group(consistent: np.ndarray, seed: int, rank: np.ndarray) -> np.ndarray:
    """A mutually consistent set of candidates containing ``seed``, grown greedily in the order
    ``rank`` (best first). One candidate per measured star, since candidates of the same star
    never agree."""
    position = np.empty(len(rank), dtype=np.intp)
    position[rank] = np.arange(len(rank))
    members = [seed]
    alive = consistent[seed].copy()
    while alive.any():
        u = int(rank[np.min(position[alive])])
        members.append(u)
        alive &= consistent[u]
    return np.array(members, dtype=np.intp)


def widest_triangles(bearings: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
    """Index triples of the rows of ``bearings`` (g, 3), widest (largest |triple product|, the
    best conditioned attitude) first; with ``keep`` only triples containing row ``keep``."""
    t = _triples(len(bearings))
    if keep is not None:
        t = t[np.any(t == keep, axis=1)]
    b = bearings[t]
    det = np.abs(triple_product(b[:, 0], b[:, 1], b[:, 2]))
    return t[np.argsort(-det, kind="stable")]


def try_triangle(
    tester: HypothesisTester, obs_rows: np.ndarray, cat_rows: np.ndarray
) -> IdentifyOutcome | None:
    """Test the hypothesis ``obs_rows -> cat_rows`` (3 stars) with the parity its orientation
    gives (both when it is too flat to tell); counts each parity tried."""
    s = tester.settings
    b = tester.bearings[obs_rows]
    v = tester.database.catalog.vectors[cat_rows]
    det_obs = float(triple_product(*b))
    det_cat = float(triple_product(*v))
    parity = 1 if np.sign(det_obs) == np.sign(det_cat) else -1
    sides = angle_between(b[[0, 0, 1]], b[[1, 2, 2]])
    parities = [parity]
    if abs(det_obs) < 3.0 * s.pair_tol_rad * sides.max():  # too flat to tell the orientation
        parities.append(-parity)
    if s.parity is not None:
        parities = [p for p in parities if p == s.parity]
    tester.count(len(parities))
    for p in parities:
        outcome = tester.test(obs_rows, cat_rows, p)
        if outcome is not None:
            return outcome
    return None


@dataclass(frozen=True)
class WindowVotes:
    """The votes of measured pairs ``(p[m], q[m])``: for every catalog pair in their windows,
    both ends, as ``pair`` (the ``m``), ``star`` (the catalog star voted for), ``partner`` (the
    other end) and ``weight``."""

    pair: np.ndarray
    star: np.ndarray
    partner: np.ndarray
    weight: np.ndarray

    @classmethod
    def cast(
        cls,
        database: PairDatabase,
        windows: PairWindows,
        p: np.ndarray,
        q: np.ndarray,
        tol_rad: float,
    ) -> WindowVotes:
        """Each catalog pair in a measured pair's window votes for both of its stars.

        Two changes to the plain count of the literature, both measured to matter on Hp <= 6
        fields with 2 px tolerances: a measured pair votes at most once for a catalog star (a
        star with several partners at that distance, common in dense fields, otherwise
        outvotes the true one: Kolomenkin's plain count ranked the true star first for 2 % of
        noisy stars, 33 % with this), and a vote is weighted by the log likelihood ratio of its
        angle difference, a Gaussian of sigma ``tol/3`` against the chance of a catalog pair
        anywhere in the window (48 % first).
        """
        n_cat = len(database.catalog)
        pair, rows = expand_windows(windows.lo[p, q], windows.hi[p, q])
        a = database.pair_a[rows].astype(np.intp)
        b = database.pair_b[rows].astype(np.intp)
        sigma = tol_rad / 3.0
        delta = database.pair_angle_rad[rows] - windows.angles[p, q][pair]
        likelihood = np.exp(-0.5 * (delta / sigma) ** 2) * (
            2.0 * tol_rad / (np.sqrt(2.0 * np.pi) * sigma)
        )
        chance = 2.0 * windows.counts[p, q][pair] / n_cat  # partners a random star has there
        weight = np.log1p(likelihood / chance)
        pair, star, partner = np.tile(pair, 2), np.concatenate([a, b]), np.concatenate([b, a])
        weight = np.tile(weight, 2)
        # one vote per (measured pair, catalog star): duplicates share their mean weight
        key = pair * n_cat + star
        weight /= np.bincount(key, minlength=len(p) * n_cat)[key]
        return cls(pair, star, partner, weight)


def pair_votes(
    database: PairDatabase,
    windows: PairWindows,
    p: np.ndarray,
    q: np.ndarray,
    n: int,
    tol_rad: float,
) -> np.ndarray:
    """Votes (n, n_catalog) of the measured pairs ``(p[m], q[m])`` among ``n`` stars for the
    catalog stars: every catalog pair in a window votes for both its stars on both measured
    stars (Kolomenkin et al.), weighted as ``WindowVotes.cast`` explains."""
    n_cat = len(database.catalog)
    v = WindowVotes.cast(database, windows, p, q, tol_rad)
    votes = np.bincount(p[v.pair] * n_cat + v.star, weights=v.weight, minlength=n * n_cat)
    votes += np.bincount(q[v.pair] * n_cat + v.star, weights=v.weight, minlength=n * n_cat)
    return votes.reshape(n, n_cat)


class GeometricVoting:
    """Geometric voting on the pair database with whole-field verification.

    Options: ``max_vote_stars``, most stars taking part in the vote (fewer when the hypothesis
    count would pass 90 % of the budget; 12 or 14 solved no more frames than 10);
    ``candidates``, catalog candidates per star that enter the validation (Kolomenkin keeps the
    best one; with 2 px tolerances the true star is often second or tenth: on 300 noisy frames
    10 solved 288, 30 solved 292, 60 solved 295; at sigma_px 1, 30 solved 136 of 150 and 60
    solved 142); ``max_groups``, consistent groups tried before giving up.
    """

    name = "voting"

    def __init__(self, *, max_vote_stars: int = 10, candidates: int = 60, max_groups: int = 6):
        self.max_vote_stars = max_vote_stars
        self.candidates = candidates
        self.max_groups = max_groups

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (the only table this searches)."""
        return database.nbytes

    @staticmethod
    def _vote_stars(
        bearings: np.ndarray, windows: PairWindows, settings: MatchSettings, n_catalog: int
    ) -> tuple[int, float]:
        """How many of the first stars vote, and the hypotheses that vote chooses from."""
        t = _triples(len(bearings))
        h = triangle_hypotheses(
            bearings,
            windows,
            t,
            n_catalog,
            settings.pair_tol_rad,
            parity_known=settings.parity is not None,
        )
        # cumulative count over the triangles of the first n stars (n = largest index + 1)
        per_n = np.cumsum(np.bincount(t[:, 2], weights=h, minlength=len(bearings)))
        fits = np.flatnonzero(per_n <= _VOTE_BUDGET * settings.max_hypotheses)
        n = max(3, int(fits[-1]) + 1) if len(fits) else 3
        return n, float(per_n[n - 1])

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        stars = order[: min(settings.max_stars, self.max_vote_stars)]
        if len(stars) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        tol = settings.pair_tol_rad
        vectors = database.catalog.vectors
        n_cat = len(vectors)
        tester = HypothesisTester(bearings, database, settings, order=order)
        b = bearings[stars]
        windows = PairWindows.measure(b, database, tol)
        n, hypotheses = self._vote_stars(b, windows, settings, n_cat)
        stars, b = stars[:n], b[:n]
        tester.count(int(np.ceil(hypotheses)))

        # first vote: every catalog pair agreeing with a measured pair votes for both of its
        # stars on both measured stars
        p, q = np.nonzero(np.triu(windows.valid[:n, :n], 1))
        votes = pair_votes(database, windows, p, q, n, tol)
        k = min(self.candidates, n_cat)
        top = np.argpartition(-votes, k - 1, axis=1)[:, :k]
        top_votes = np.take_along_axis(votes, top, axis=1)
        keep = (top_votes > 0).ravel()
        obs = np.repeat(np.arange(n), k)[keep]
        cat = top.ravel()[keep]
        node_votes = top_votes.ravel()[keep]
        if len(obs) < 3:
            return tester.outcome("no star pair agrees with a catalog pair")

        # second vote: candidates whose pairwise catalog angles agree with the measured ones
        consistent = consistency(obs, cat, windows, vectors)
        agree = support(consistent, obs)
        rank = np.lexsort((-node_votes, -agree))
        tried = np.zeros(len(obs), dtype=bool)
        groups = 0
        for seed in rank:
            if agree[seed] < 2 or groups >= self.max_groups or tester.exhausted:
                break
            if tried[seed]:
                continue
            group = grow_group(consistent, seed, rank)
            tried[group] = True
            if len(group) < 3:
                continue
            groups += 1
            for t in widest_triangles(b[obs[group]])[:2]:
                outcome = try_triangle(tester, stars[obs[group[t]]], cat[group[t]])
                if outcome is not None:
                    return outcome
        return tester.outcome("no group of voted stars agrees with the catalog")
