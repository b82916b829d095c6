"""Lost-in-space identification by the sum of angular distances to a star's nearest neighbours.

A star's feature is the sum of the angles (radians) to its ``k`` nearest neighbours: one number
per star, unchanged by rotation and by the mirror image, looked up in a table of catalog stars
sorted by the same sum (a ``searchsorted`` range). It is one of the classical single-star
features ("sums of angular distances to neighbours"; a pattern-recognition method in the terms
of Spratling & Mortari's 2009 survey): cheap, but a star's feature is right only when all its
true neighbours are in the image and seen, so missing stars, false stars and the image edge
corrupt it. Three measures keep it honest:

- stars whose ``k``-th neighbour is closer than the edge of the observed point cloud are tried
  first (their neighbourhood lies inside the image), the others after them, nearest to
  qualifying first;
- a feature match is never trusted alone: two stars' candidates must be a catalog pair at the
  measured separation (pair check), a third star at the right distances from both fixes the
  parity by the sign of the triple product;
- the whole field verifies the attitude (``HypothesisTester``), which refuses the rest.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from starnav.errors import StarnavError, shown
from starnav.geometry import angle_between, chord_from_angle, triple_product
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.verify import (
    HypothesisTester,
    best_case_probability,
    field_radius_rad,
)
from starnav.runtime.caches import process_cache

DEFAULT_K = 2
# catalog features, per (catalog fingerprint, largest pair angle, k): built in milliseconds
# for Hipparcos-size catalogs, so memory is the only cache
_FEATURES = process_cache("neighbor-sum features")


def catalog_neighbor_sums(database: PairDatabase, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Catalog neighbour-sum features sorted ascending (radians) and their catalog rows.

    Neighbours are searched within half the database's largest angle (a star whose ``k``-th
    neighbour lies farther cannot have its neighbourhood inside the field); stars without
    ``k`` neighbours there get no feature.
    """
    key = (database.catalog.fingerprint, round(database.max_angle_rad, 9), k)
    if key not in _FEATURES:
        vectors = database.catalog.vectors
        chord, _ = database.tree.query(
            vectors, k=k + 1, distance_upper_bound=chord_from_angle(0.5 * database.max_angle_rad)
        )
        chord = chord[:, 1:]  # the first "neighbour" is the star itself
        ok = np.all(np.isfinite(chord), axis=1)
        feature = np.sum(2.0 * np.arcsin(0.5 * chord[ok]), axis=1)
        rows = np.flatnonzero(ok)
        order = np.argsort(feature, kind="stable")
        index_type = np.int32 if len(vectors) > np.iinfo(np.uint16).max else np.uint16
        _FEATURES[key] = (feature[order], rows[order].astype(index_type))
    return _FEATURES[key]


def observed_neighbor_sums(
    bearings: np.ndarray, k: int, margin_rad: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Neighbour-sum feature (radians) of every bearing, whether its neighbourhood is inside
    the observed field, and the matrix of inter-star angles (radians).

    The image edges are unknown, so the bounding box of the points on the tangent plane stands
    for the image (the image holds it). A star is "inside" when the disk reaching to its
    ``k``-th neighbour, grown by ``margin_rad``, fits in that box: then every catalog star
    that close to it is in the image. Stars with fewer than ``k`` neighbours get ``inf``.
    """
    n = len(bearings)
    angles = angle_between(bearings[:, None, :], bearings[None, :, :])
    if n <= k:
        return np.full(n, np.inf), np.full(n, -np.inf), angles
    nearest = np.sort(angles + np.diag(np.full(n, np.inf)), axis=1)[:, :k]
    feature = nearest.sum(axis=1)
    plane = bearings[:, :2] / bearings[:, 2:3]
    lo, hi = plane.min(axis=0), plane.max(axis=0)
    edge = np.minimum(plane - lo, hi - plane).min(axis=1)
    # the gnomonic projection stretches a disk by up to 1 / cos^2 of its off-axis angle
    stretch = 1.0 / np.min(bearings[:, 2]) ** 2
    margin = edge - (nearest[:, -1] + margin_rad) * stretch
    return feature, margin, angles


def pair_order(n: int) -> Iterator[tuple[int, int]]:
    """Index pairs (i < j) of ``n`` stars, nearest ranks first: a bad star is left soon."""
    for dj in range(1, n):
        for i in range(n - dj):
            yield i, i + dj


class NeighborSum:
    """Neighbour-sum features matched in pairs, extended by a third star, whole-field verified.

    ``k``: neighbours summed. 2 measured best on 300 uniform-sky 12° / 512 px Hp <= 6 frames
    (solved clean / noisy: k=2 296 / 267, k=3 281 / 215, k=4 250 / 175): a longer sum
    discriminates a little better, but fewer stars have their k neighbours inside the image
    and more have one of them missing or false. ``feature_tol_scale``: the feature tolerance
    in units of ``sqrt(k)`` pair tolerances (the sum carries k measured angles).
    ``edge_stars``: after the stars whose neighbourhood is inside the field, try the others
    too (without them 200 / 169 of the same frames solve: most fields have few inside stars).
    """

    name = "neighbor-sum"

    def __init__(
        self, *, k: int = DEFAULT_K, feature_tol_scale: float = 1.5, edge_stars: bool = True
    ) -> None:
        if not (isinstance(k, int | np.integer) and k >= 1):
            raise StarnavError(f"k (neighbours summed) must be an integer >= 1, got {shown(k)}")
        if not (np.isfinite(feature_tol_scale) and feature_tol_scale > 0):
            raise StarnavError(f"feature_tol_scale must be > 0, got {shown(feature_tol_scale)}")
        self.k = int(k)
        self.feature_tol_scale = float(feature_tol_scale)
        self.edge_stars = bool(edge_stars)

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (its KD-tree's catalog vectors) and the feature table."""
        feature, rows = catalog_neighbor_sums(database, self.k)
        return database.nbytes + feature.nbytes + rows.nbytes

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        order = np.asarray(order)
        if len(order) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        tol = settings.pair_tol_rad
        k = self.k
        feature_tol = self.feature_tol_scale * np.sqrt(k) * tol
        cat_feature, cat_rows = catalog_neighbor_sums(database, k)
        feature, margin, angles = observed_neighbor_sums(bearings, k, tol)
        ranked = order[np.isfinite(feature[order])]
        inside = ranked[margin[ranked] > 0]
        candidates = inside
        if self.edge_stars:
            # then the stars nearest to having their neighbourhood inside the field
            edge = ranked[margin[ranked] <= 0]
            candidates = np.concatenate([inside, edge[np.argsort(-margin[edge], kind="stable")]])
        candidates = candidates[: settings.max_stars]
        if len(candidates) < 2:
            return IdentifyOutcome(None, f"fewer than 2 stars with {k} neighbours", 0)
        # catalog rows whose feature agrees with each candidate star's
        lo = np.searchsorted(cat_feature, feature[candidates] - feature_tol)
        hi = np.searchsorted(cat_feature, feature[candidates] + feature_tol)
        # which catalog stars each candidate star may be (its feature agrees)
        member = np.zeros((len(candidates), len(database.catalog)), dtype=bool)
        for ci in range(len(candidates)):
            member[ci, cat_rows[lo[ci] : hi[ci]]] = True
        tester = HypothesisTester(bearings, database, settings, order=order)
        parities = (1, -1) if settings.parity is None else (settings.parity,)
        # a hypothesis whose support could not beat the threshold on any field is not
        # verified (``best_case_probability``)
        field_rad = field_radius_rad(bearings, settings.match_radius_rad)
        for ci, cj in pair_order(len(candidates)):
            if lo[ci] == hi[ci] or lo[cj] == hi[cj]:
                continue
            i, j = candidates[ci], candidates[cj]
            d_ij = angles[i, j]
            if d_ij < 2.0 * tol or d_ij > database.max_angle_rad + tol:
                continue
            # pair check: catalog pairs at the measured separation whose ends have the
            # features of i and j (either way round)
            u, v = database.pairs_within(d_ij, tol)
            forward = member[ci, u] & member[cj, v]
            backward = member[ci, v] & member[cj, u]
            a = np.concatenate([u[forward], v[backward]]).astype(np.intp)
            b = np.concatenate([v[forward], u[backward]]).astype(np.intp)
            if len(a) == 0:
                continue
            tester.count(len(a) * len(parities))
            outcome = self._test_pairs(i, j, a, b, bearings, angles, database, tester, field_rad)
            if outcome is not None:
                return outcome
            if tester.exhausted:
                break
        return tester.outcome("no pair of neighbour-sum features matches the catalog")

    def _test_pairs(
        self,
        i: int,
        j: int,
        a: np.ndarray,
        b: np.ndarray,
        bearings: np.ndarray,
        angles: np.ndarray,
        database: PairDatabase,
        tester: HypothesisTester,
        field_rad: float,
    ) -> IdentifyOutcome | None:
        """Test the pair hypotheses (i -> a, j -> b), each extended by a third star.

        For every other measured star l, the catalog stars near a at its distances from i and
        from j (within the pair tolerance) are its possible identities; on which side of the
        great circle a-b such a star lies, against the side of l from i-j in the image (the
        signs of the triple products), gives the parity. The number of measured stars that
        find an identity screens the hypotheses: the best supported are tested first, and
        none whose support could not convince even if every such star agreed.
        """
        settings = tester.settings
        tol = settings.pair_tol_rad
        vectors = database.catalog.vectors
        others = np.flatnonzero((np.arange(len(bearings)) != i) & (np.arange(len(bearings)) != j))
        if len(a) == 0 or len(others) == 0:
            return None
        d_il, d_jl = angles[i, others], angles[j, others]
        # catalog stars near each candidate a: one KD-tree call for all pairs
        cones = database.tree.query_ball_point(
            vectors[a], chord_from_angle(float(d_il.max()) + tol), return_sorted=False
        )
        size = np.array([len(cone) for cone in cones])
        if size.sum() == 0:
            return None
        pair = np.repeat(np.arange(len(a)), size)  # (m,) pair index of each cone star
        star = np.concatenate([np.asarray(cone, dtype=np.intp) for cone in cones])
        cos_a = np.einsum("mj,mj->m", vectors[a[pair]], vectors[star])
        cos_b = np.einsum("mj,mj->m", vectors[b[pair]], vectors[star])
        # (m, others): the cone star shows both distances of the other measured star
        ok = (cos_a[:, None] >= np.cos(d_il + tol)) & (
            cos_a[:, None] <= np.cos(np.maximum(d_il - tol, 0.0))
        )
        ok &= (cos_b[:, None] >= np.cos(d_jl + tol)) & (
            cos_b[:, None] <= np.cos(np.maximum(d_jl - tol, 0.0))
        )
        ok &= ((star != a[pair]) & (star != b[pair]))[:, None]
        m, lk = np.nonzero(ok)
        if len(m) == 0:
            return None
        # every (pair, third star) below is a 3-star hypothesis the search chooses from, by
        # how many other stars support it: all are counted (counting only the pairs let a
        # 5-star false match through on the 3° grid, p 6e-5 from 4 "hypotheses")
        tester.count(len(m) * (2 if settings.parity is None else 1))
        h_of, c_of, l_of = pair[m], star[m], others[lk]
        # parity: the side of the third star from the pair, in the image and in the catalog
        det_obs = triple_product(bearings[i], bearings[j], bearings[l_of])
        det_cat = triple_product(vectors[a[h_of]], vectors[b[h_of]], vectors[c_of])
        same = np.sign(det_obs) == np.sign(det_cat)
        longest = np.maximum(angles[i, j], np.maximum(angles[i, l_of], angles[j, l_of]))
        flat = np.abs(det_obs) < 3.0 * tol * longest  # too flat to tell the side
        parities = (1, -1) if settings.parity is None else (settings.parity,)
        n_total = len(bearings)
        hypotheses = []  # (support, parity, pair index, row of the third star, its catalog row)
        abs_det = np.abs(det_obs)
        for parity in parities:
            fits = np.flatnonzero(flat | (same if parity == 1 else ~same))
            if len(fits) == 0:
                continue
            # support: the measured stars (each counted once) a catalog star confirms
            keys = np.unique(h_of[fits] * n_total + l_of[fits])
            support = np.bincount(keys // n_total, minlength=len(a))
            # per pair, the best-conditioned third star (largest triangle volume) makes the
            # attitude
            by_pair = fits[np.lexsort((-abs_det[fits], h_of[fits]))]
            first = np.flatnonzero(np.r_[True, h_of[by_pair][1:] != h_of[by_pair][:-1]])
            for best in by_pair[first]:
                h = h_of[best]
                hypotheses.append((int(support[h]), parity, h, l_of[best], int(c_of[best])))
        hypotheses.sort(key=lambda t: -t[0])
        for support, parity, h, third, c in hypotheses:
            p_best_case = best_case_probability(
                n_total, support + 2, tester.hypotheses, field_rad, settings
            )
            if p_best_case > settings.max_false_match_probability:
                break  # neither this nor any later (less supported) pair can convince
            outcome = tester.test(np.array([i, j, third]), np.array([a[h], b[h], c]), parity)
            if outcome is not None:
                return outcome
        return None
