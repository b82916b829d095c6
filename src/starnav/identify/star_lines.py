"""Lost-in-space identification by star lines: the angles between the arcs joining a star to
its neighbours.

Seen from a reference star, every neighbour lies at some distance along some direction; the
directions measured from the arc to the nearest neighbour do not change when the camera rolls,
and change sign in a mirror image (the polygon-angle features of e.g. Ramos-Alcaraz et al.,
"Star-identification system based on polygon recognition", Aerospace 10, 748, 2023: central
star, nearest neighbour, angles of the other stars from that line). Here the catalog side is not
a table of such features but the pair database: the candidates for the reference star and its
nearest neighbour are the catalog pairs at their separation, and each candidate predicts, for
every other neighbour, where a catalog star must be (the measured distance along the measured
line angle), in both mirror-symmetric arrangements when the parity is unknown. The candidate
arrangements with the most neighbours found where predicted are verified on the whole field
(``HypothesisTester``), best supported first.

A missing neighbour is simply not looked for and a false one not found: each costs one vote,
not the feature. The method's weak point is the reference arc: a false nearest neighbour
spoils the reference star (the next one is tried).
"""

from __future__ import annotations

import numpy as np

from starnav.errors import StarnavError, shown
from starnav.geometry import angle_between, chord_from_angle
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.verify import (
    HypothesisTester,
    best_case_probability,
    field_radius_rad,
)

MIN_ARC_PX = 10.0  # the reference arc's shortest length: the double-star separation constraint


def _tangent(origin: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Unit tangent vectors at ``origin`` along the great circle towards ``target`` (..., 3)."""
    t = target - np.einsum("...i,...i->...", origin, target)[..., None] * origin
    return t / np.linalg.norm(t, axis=-1, keepdims=True)


def line_angles(bearings: np.ndarray, ref: int, nearest: int, others: np.ndarray) -> np.ndarray:
    """Position angles (radians, -pi..pi) at star ``ref`` of the arcs to ``others``, measured
    from the arc to ``nearest`` towards ``ref x e1`` (counter-clockwise seen from outside the
    sphere, which the mirror image reverses)."""
    p = bearings[ref]
    e1 = _tangent(p, bearings[nearest])
    e2 = np.cross(p, e1)
    t = _tangent(p, bearings[others])
    return np.arctan2(t @ e2, t @ e1)


class StarLines:
    """Star-line angles about a reference star, matched through the pair database.

    ``neighbors``: the reference star's nearest measured neighbours used (the first gives the
    reference arc, the others vote; 5 measured as a compromise: on 400 frames with 1 px noise,
    30 % missing and 2 false stars 4 / 5 / 6 solve 362 / 366 / 370, at 31 / 45 / 46 ms CPU
    median on random fields); ``tests_per_star``: arrangements of one reference star verified
    at most (the best supported first).
    """

    name = "star-lines"

    def __init__(self, *, neighbors: int = 5, tests_per_star: int = 2) -> None:
        for label, value in (("neighbors", neighbors), ("tests_per_star", tests_per_star)):
            if not (isinstance(value, int | np.integer) and value >= 1):
                raise StarnavError(f"{label} must be an integer >= 1, got {shown(value)}")
        if neighbors < 2:
            raise StarnavError(
                f"neighbors must be >= 2 (an arc and a vote), got {shown(neighbors)}"
            )
        self.neighbors = int(neighbors)
        self.tests_per_star = int(tests_per_star)

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (with the catalog vectors its KD-tree holds)."""
        return database.nbytes

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        n = len(bearings)
        if n < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        tol = settings.pair_tol_rad
        min_arc = max(2.0 * tol, MIN_ARC_PX * (settings.pixel_rad or 0.0))
        angles = angle_between(bearings[:, None, :], bearings[None, :, :])
        tester = HypothesisTester(bearings, database, settings, order=order)
        field_rad = field_radius_rad(bearings, settings.match_radius_rad)
        for ref in np.asarray(order)[: settings.max_stars]:
            by_distance = np.argsort(angles[ref], kind="stable")
            d = angles[ref, by_distance]
            # unresolved companions and stars beyond the database's reach take no part
            by_distance = by_distance[(d >= 2.0 * tol) & (d <= database.max_angle_rad - tol)]
            arcs = by_distance[angles[ref, by_distance] >= min_arc]
            if len(arcs) == 0 or len(by_distance) < 2:
                continue
            nearest = arcs[0]
            others = by_distance[by_distance != nearest][: self.neighbors - 1]
            outcome = self._try_reference(
                ref, nearest, others, bearings, angles, database, tester, field_rad
            )
            if outcome is not None:
                return outcome
            if tester.exhausted:
                break
        return tester.outcome("no star-line pattern matches the catalog")

    def _try_reference(
        self,
        ref: int,
        nearest: int,
        others: np.ndarray,
        bearings: np.ndarray,
        angles: np.ndarray,
        database: PairDatabase,
        tester: HypothesisTester,
        field_rad: float,
    ) -> IdentifyOutcome | None:
        """Match the star lines about ``ref`` (reference arc to ``nearest``, votes from
        ``others``) and verify the best supported arrangements; an outcome when one is
        accepted or found ambiguous."""
        settings = tester.settings
        tol = settings.pair_tol_rad
        vectors = database.catalog.vectors
        d_nn = angles[ref, nearest]
        pa, pb = database.pairs_within(d_nn, tol)
        if len(pa) == 0:
            return None
        # the reference star may be either end of a catalog pair
        a = np.concatenate([pa, pb]).astype(np.intp)
        b = np.concatenate([pb, pa]).astype(np.intp)
        va = vectors[a]
        e1 = _tangent(va, vectors[b])
        e2 = np.cross(va, e1)
        d = angles[ref, others]
        theta = line_angles(bearings, ref, nearest, others)
        # the line angle carries the direction errors of both arcs (each ~ tol / length): the
        # prediction may be off by tol along the arc and tol * sqrt(1 + (d / d_nn)^2) across
        across = tol * np.sqrt(1.0 + (d / d_nn) ** 2)
        parities = np.array([1, -1] if settings.parity is None else [settings.parity])
        # a neighbour can only agree where some catalog star lies at its distance from the
        # candidate reference star: the pair database says which stars have such a partner
        ring = np.zeros((len(others), len(vectors)), dtype=bool)
        for q, d_q in enumerate(d):
            ring_a, ring_b = database.pairs_within(d_q, tol)
            ring[q, ring_a] = True
            ring[q, ring_b] = True
        cand, nb = np.nonzero(ring[:, a].T)
        if len(cand) == 0:
            return None
        # every (candidate, neighbour) in each arrangement: where its catalog star must be
        cand = np.tile(cand, len(parities))
        nb = np.tile(nb, len(parities))
        par = np.repeat(np.arange(len(parities)), len(cand) // len(parities))
        sin_t = parities[par] * np.sin(theta[nb])
        direction = np.cos(theta[nb])[:, None] * e1[cand] + sin_t[:, None] * e2[cand]
        predicted = np.cos(d[nb])[:, None] * va[cand] + np.sin(d[nb])[:, None] * direction
        reach = float(np.max(np.hypot(tol, across)))
        _, hit = database.tree.query(predicted, k=1, distance_upper_bound=chord_from_angle(reach))
        found = hit < len(vectors)
        cand, nb, par, hit = cand[found], nb[found], par[found], hit[found]
        predicted, direction = predicted[found], direction[found]
        vc = vectors[hit]
        # the right distance from the reference star, and the right line angle
        cos_along = np.einsum("ij,ij->i", va[cand], vc)
        offset = np.einsum("ij,ij->i", vc - predicted, np.cross(va[cand], direction))
        ok = (cos_along >= np.cos(d[nb] + tol)) & (cos_along <= np.cos(d[nb] - tol))
        ok &= (np.abs(offset) <= across[nb]) & (hit != a[cand]) & (hit != b[cand])
        cand, nb, par, hit = cand[ok], nb[ok], par[ok], hit[ok]
        support = np.zeros((len(a), len(parities)), dtype=np.intp)
        np.add.at(support, (cand, par), 1)
        ch, ph = np.nonzero(support)
        if len(ch) == 0:
            return None
        # every agreeing neighbour makes a three-star hypothesis (reference, nearest, it): all
        # are counted; one per arrangement is tested (the others give the same attitude), and
        # the rest of its agreeing neighbours are evidence like any star of the field
        tester.count(int(support.sum()))
        n_total = len(bearings)
        # the best-conditioned third star: the largest triangle volume
        volume = np.abs(
            np.einsum("i,ni->n", np.cross(bearings[ref], bearings[nearest]), bearings[others])
        )
        tested = 0
        for h in np.argsort(-support[ch, ph], kind="stable"):
            c, p = ch[h], ph[h]
            # the stars that are not neighbours could all agree too
            p_best_case = best_case_probability(
                n_total,
                n_total - len(others) + support[c, p],
                tester.hypotheses,
                field_rad,
                settings,
            )
            if p_best_case > settings.max_false_match_probability:
                break  # neither this nor any later (less supported) arrangement can convince
            agree = np.flatnonzero((cand == c) & (par == p))
            third = agree[np.argmax(volume[nb[agree]])]
            obs_rows = np.array([ref, nearest, others[nb[third]]])
            cat_rows = np.array([a[c], b[c], hit[third]])
            outcome = tester.test(obs_rows, cat_rows, int(parities[p]))
            if outcome is not None:
                return outcome
            tested += 1
            if tested >= self.tests_per_star:
                break
        return None
