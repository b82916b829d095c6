"""Lost-in-space identification by pairwise angular distances and a match group (the classical
method of van Bezooijen's AST-1 tracker, in Gottlieb's survey of star identification),
verified by reprojection.

For a reference star, every neighbour among the brightest stars looks up the catalog pairs whose
angle agrees with its distance to the reference; either end of such a pair could be the
reference star, and the catalog star named by the most neighbours wins (votes weighted as in
``voting.WindowVotes``). The neighbours that voted for it take their identity from the other
end of their pair; of those, the ones whose catalog angles also agree with each other form the
match group (grown greedily from the best supported). The hypothesis is the reference star and
two members of its match group, the widest such triangle (the attitude is best conditioned
there), with the parity of its orientation. Runner-up catalog stars are tried before moving on
to the next reference star: with 4 px tolerances the true star is often not the winner (on 27
frames with 1 px noise, 30 % missing and no brightness order, 30 candidates solved 25, 10
solved 22).

Counting hypotheses: the winner was chosen for agreeing with the neighbours' distances, the very
stars the verification then counts as chance agreements, so one count per tested triangle
would overstate the evidence. Each reference star counts the catalog triangles that agree with
any measured triangle of it and two of its neighbours (not already counted for an earlier
reference star), the set its choice was made from, as ``voting`` does; each tested hypothesis
counts once more.
"""

from __future__ import annotations

import numpy as np

from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.verify import HypothesisTester
from starnav.identify.voting import (
    PairWindows,
    WindowVotes,
    consistency,
    grow_group,
    support,
    triangle_hypotheses,
    try_triangle,
    widest_triangles,
)

# a true match group holds every true star among the neighbours (their distances to the
# reference agree by construction), and one agreeing star beyond the three of the hypothesis is
# never convincing: a group of 3 could only be confirmed by stars outside the neighbours, and
# testing such groups cost most of the time on fields of random points
_MIN_GROUP = 4


def _pairs(m: int) -> np.ndarray:
    j, k = np.triu_indices(m, 1)
    return np.column_stack([j, k])


class AngleMatch:
    """Match-group identification on the pair database with whole-field verification.

    Options: ``candidates``, catalog stars tried per reference star (the winner and
    runners-up); ``max_reference_stars``, reference stars tried before giving up.
    """

    name = "angle"

    def __init__(self, *, candidates: int = 30, max_reference_stars: int = 6):
        self.candidates = candidates
        self.max_reference_stars = max_reference_stars

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (the only table this searches)."""
        return database.nbytes

    @staticmethod
    def _neighbours(
        b: np.ndarray,
        windows: PairWindows,
        ref: int,
        covered: np.ndarray,
        settings: MatchSettings,
        n_catalog: int,
    ) -> tuple[np.ndarray, float]:
        """The neighbours of ``ref`` that vote (the first ones whose triangles with ``ref`` keep
        the count within a quarter of the budget) and the hypotheses their triangles with
        ``ref`` add. ``covered[e, x]``: star ``x`` was a voting neighbour of the earlier
        reference star ``e``, whose count took in every triangle of ``e`` and two of them."""
        nbrs = np.flatnonzero(windows.valid[ref])
        jk = nbrs[_pairs(len(nbrs))]
        triangles = np.column_stack([np.full(len(jk), ref), jk])
        h = triangle_hypotheses(
            b,
            windows,
            triangles,
            n_catalog,
            settings.pair_tol_rad,
            parity_known=settings.parity is not None,
        )
        j, k = jk.T
        seen = (covered[j, ref] & covered[j, k]) | (covered[k, ref] & covered[k, j])
        h = np.where(seen, 0.0, h)
        # the triangles of the first m neighbours are those whose later neighbour is < m
        later = np.searchsorted(nbrs, jk[:, 1])
        per_m = np.cumsum(np.bincount(later, weights=h, minlength=len(nbrs)))
        fits = np.flatnonzero(per_m <= 0.25 * settings.max_hypotheses)
        m = max(2, int(fits[-1]) + 1) if len(fits) else 2
        m = min(m, len(nbrs))
        return nbrs[:m], float(per_m[m - 1]) if m else 0.0

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        stars = order[: settings.max_stars]
        if len(stars) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        tol = settings.pair_tol_rad
        vectors = database.catalog.vectors
        n_cat = len(vectors)
        tester = HypothesisTester(bearings, database, settings, order=order)
        b = bearings[stars]
        windows = PairWindows.measure(b, database, tol)
        covered = np.zeros((len(stars), len(stars)), dtype=bool)
        for ref in range(min(len(stars), self.max_reference_stars)):
            if tester.exhausted:
                break
            nbrs, hypotheses = self._neighbours(b, windows, ref, covered, settings, n_cat)
            covered[ref, nbrs] = True
            if len(nbrs) < 2:
                continue
            tester.count(int(np.ceil(hypotheses)))
            votes = WindowVotes.cast(database, windows, np.full(len(nbrs), ref), nbrs, tol)
            score = np.bincount(votes.star, weights=votes.weight, minlength=n_cat)
            k = min(self.candidates, n_cat)
            top = np.argpartition(-score, k - 1)[:k]
            top = top[np.argsort(-score[top], kind="stable")]
            top = top[score[top] > 0]
            # the votes for the candidates, grouped by candidate
            chosen = np.zeros(n_cat, dtype=bool)
            chosen[top] = True
            mine = np.flatnonzero(chosen[votes.star])
            mine = mine[np.argsort(votes.star[mine], kind="stable")]
            first = np.searchsorted(votes.star[mine], top)
            last = np.searchsorted(votes.star[mine], top, side="right")
            for c, lo, hi in zip(top, first, last, strict=True):
                # the match group: the reference star as ``c`` and its supporters
                sel = mine[lo:hi]
                obs = np.concatenate([[ref], nbrs[votes.pair[sel]]])
                cat = np.concatenate([[c], votes.partner[sel]])
                weight = np.concatenate([[np.inf], votes.weight[sel]])
                # candidates listed star by star, as ``support`` needs
                by_star = np.lexsort((-weight, obs))
                obs, cat, weight = obs[by_star], cat[by_star], weight[by_star]
                seed = int(np.flatnonzero(obs == ref)[0])
                consistent = consistency(obs, cat, windows, vectors)
                rank = np.lexsort((-weight, -support(consistent, obs)))
                group = grow_group(consistent, seed, rank)
                if len(group) < _MIN_GROUP:
                    continue
                keep = int(np.flatnonzero(group == seed)[0])
                t = widest_triangles(b[obs[group]], keep=keep)[0]
                outcome = try_triangle(tester, stars[obs[group[t]]], cat[group[t]])
                if outcome is not None:
                    return outcome
        return tester.outcome("no reference star's match group agrees with the catalog")
