"""Lost-in-space identification by star triangles on a pair database, verified by reprojection.

The idea of Mortari's Pyramid: pick measured star triangles in an order that moves away from
any one star quickly (so a false star cannot stall the search), look up the catalog pairs whose
angles agree with each side, join them into catalog triangles, and test every catalog triangle
as an attitude hypothesis. Where Pyramid confirms with a fourth star, this verifies with the
whole field: the hypothesis's attitude reprojects the catalog, the agreeing stars are counted,
and the answer is accepted only when the chance of a wrong hypothesis agreeing as well is below
the threshold. Parity comes from the orientation of the triangle (the sign of the triple
product) and is tested both ways when the triangle is too flat to tell.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from starnav.geometry import angle_between, chord_from_angle, triple_product
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase
from starnav.identify.verify import (
    HypothesisTester,
    false_match_probability,
    field_radius_rad,
)

NO_TRIANGLE = "no star triangle matches the catalog"  # the reason when nothing matched
_SCREEN_CHUNK = 2000  # hypotheses screened per batch (bounds memory on wide fields)


def triangle_order(n: int) -> Iterator[tuple[int, int, int]]:
    """Index triples (i < j < k) of ``n`` stars in Mortari's order: every star is left behind
    soon, so one false star costs only a few triangles."""
    for dj in range(1, n - 1):
        for dk in range(1, n - dj):
            for i in range(n - dj - dk):
                yield i, i + dj, i + dj + dk


def _both_ways(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.concatenate([a, b]), np.concatenate([b, a])


def catalog_triangles(
    database: PairDatabase, side_ij: float, side_ik: float, side_jk: float, tol_rad: float
) -> np.ndarray:
    """Catalog index triples (a, b, c), shape (m, 3), whose sides ab, ac, bc agree with the
    measured sides ij, ik, jk within ``tol_rad``."""
    empty = np.empty((0, 3), dtype=np.int64)
    a1, b1 = database.pairs_within(side_ij, tol_rad)
    a2, c2 = database.pairs_within(side_ik, tol_rad)
    if len(a1) == 0 or len(a2) == 0:
        return empty
    n_cat = len(database.catalog)
    a1, b1 = _both_ways(a1, b1)
    a2, c2 = _both_ways(a2, c2)
    # side ik grouped by its first star (counting sort), then joined to side ij on star a
    count2 = np.bincount(a2, minlength=n_cat)
    start2 = np.cumsum(count2) - count2
    c2 = c2[np.argsort(a2, kind="stable")]
    count = count2[a1]
    total = int(count.sum())
    if total == 0:
        return empty
    row = np.repeat(np.arange(len(a1)), count)
    offset = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    a, b, c = a1[row], b1[row], c2[start2[a1][row] + offset]
    # keep the (b, c) whose separation agrees with side jk
    cos_bc = np.einsum("ij,ij->i", database.catalog.vectors[b], database.catalog.vectors[c])
    ok = (cos_bc >= np.cos(side_jk + tol_rad)) & (cos_bc <= np.cos(max(side_jk - tol_rad, 0.0)))
    ok &= b != c
    return np.column_stack([a[ok], b[ok], c[ok]]).astype(np.intp)


def _screen(
    bearings: np.ndarray,
    triangle: np.ndarray,
    catalog_triangles: np.ndarray,
    parities: np.ndarray,
    database: PairDatabase,
    settings: MatchSettings,
) -> np.ndarray:
    """Number of bearings that land near some catalog star, for every hypothesis at once.

    ``triangle`` (3, 3): the measured triangle; ``catalog_triangles`` (m, 3, 3): the catalog
    vectors of each hypothesis; ``parities`` (m,). A quick count that may only err high (a
    catalog star may be hit twice); the hypotheses that pass are verified with
    ``match_catalog``.
    """
    if len(parities) > _SCREEN_CHUNK:
        return np.concatenate(
            [
                _screen(
                    bearings,
                    triangle,
                    catalog_triangles[k : k + _SCREEN_CHUNK],
                    parities[k : k + _SCREEN_CHUNK],
                    database,
                    settings,
                )
                for k in range(0, len(parities), _SCREEN_CHUNK)
            ]
        )
    flip = np.ones((len(parities), 1, 3))
    flip[:, 0, 1] = parities
    # Wahba by SVD for all hypotheses, on the y-flipped bearings of mirrored ones
    B = np.einsum("ki,mkj->mij", triangle, catalog_triangles) * flip.transpose(0, 2, 1)
    U, _, Vt = np.linalg.svd(B)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    U[:, :, 2] *= d[:, None]
    R_proper = U @ Vt  # maps ICRS to the (flipped) camera frame
    # measured bearings into ICRS: r = R_proper^T (flip * b)
    icrs = np.einsum("mnj,mji->mni", bearings[None, :, :] * flip, R_proper)
    dist, _ = database.tree.query(
        icrs.reshape(-1, 3), k=1, distance_upper_bound=chord_from_angle(settings.match_radius_rad)
    )
    return np.isfinite(dist).reshape(len(parities), len(bearings)).sum(axis=1)


def _triple_product(v: np.ndarray) -> np.ndarray:
    """det[v0, v1, v2] for arrays of shape (..., 3, 3)."""
    return triple_product(v[..., 0, :], v[..., 1, :], v[..., 2, :])


def match_triangles(
    bearings: np.ndarray,
    triangles: Iterable[np.ndarray],
    database: PairDatabase,
    settings: MatchSettings,
) -> IdentifyOutcome:
    """Try measured triangles (rows of ``bearings``, 3 each) in the order given: look up the
    catalog triangles of each, screen them all at once, verify the best until one is accepted
    or the hypothesis budget is spent. Shared by Pyramid and Liebe's triangle method, which
    differ in the order of the triangles."""
    n_total = len(bearings)
    tol = settings.pair_tol_rad
    vectors = database.catalog.vectors
    tester = HypothesisTester(bearings, database, settings)
    # the smallest chance agreement per star any hypothesis can have (a field holding a
    # single catalog star): hypotheses whose screen count cannot beat the threshold even
    # with it are not verified in full
    field_rad = field_radius_rad(bearings, settings.match_radius_rad)
    p_floor = (1.0 - np.cos(min(settings.match_radii_rad))) / (1.0 - np.cos(field_rad))
    n_radii = len(settings.match_radii_rad)
    for idx in triangles:
        b = bearings[idx]
        sides = angle_between(b[[0, 0, 1]], b[[1, 2, 2]])
        # a side within the tolerance of zero matches nearly every catalog pair
        if sides.min() < 2.0 * tol or sides.max() > database.max_angle_rad + tol:
            continue
        triples = catalog_triangles(database, sides[0], sides[1], sides[2], tol)
        if len(triples) == 0:
            continue
        det_obs = _triple_product(b)
        det_cat = _triple_product(vectors[triples])
        parities = np.where(np.sign(det_obs) == np.sign(det_cat), 1, -1)
        if abs(det_obs) < 3.0 * tol * sides.max():  # too flat to tell the orientation
            triples = np.concatenate([triples, triples])
            parities = np.concatenate([parities, -parities])
        if settings.parity is not None:
            keep = parities == settings.parity
            triples, parities = triples[keep], parities[keep]
        if len(triples) == 0:
            continue
        tester.count(len(triples))
        agree = _screen(bearings, b, vectors[triples], parities, database, settings)
        for h in np.argsort(-agree, kind="stable"):
            p_best_case = n_radii * false_match_probability(
                n_total, agree[h], 3, p_floor, tester.hypotheses
            )
            if p_best_case > settings.max_false_match_probability:
                break  # neither this nor any later (lower) count can be convincing
            outcome = tester.test(idx, triples[h], int(parities[h]))
            if outcome is not None:
                return outcome
        if tester.exhausted:
            break
    return tester.outcome(NO_TRIANGLE)


class Pyramid:
    """Triangle search on the pair database with whole-field verification (the default)."""

    name = "pyramid"

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pair database (the only table this searches)."""
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
        order = np.asarray(order)[: settings.max_stars]
        if len(order) < 3:
            return IdentifyOutcome(None, "fewer than 3 stars", 0)
        triangles = (order[list(t)] for t in triangle_order(len(order)))
        return match_triangles(bearings, triangles, database, settings)
