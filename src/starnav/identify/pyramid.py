"""Lost-in-space identification by star triangles on a pair database, verified by reprojection.

The idea of Mortari's Pyramid: pick measured star triangles in an order that moves away from
any one star quickly (so a false star cannot stall the search), look up the catalog pairs whose
angles agree with each side, join them into catalog triangles, and test every catalog triangle
as an attitude hypothesis. Where Pyramid confirms with a fourth star, this verifies with the
whole field: the hypothesis's attitude reprojects the catalog, the agreeing stars are counted,
and the answer is accepted only when the chance of a wrong hypothesis agreeing as well is below
the threshold. Parity comes from the orientation of the triangle (the sign of the triple
product) and is tested both ways when the triangle is too flat to tell. The loop is the kernel
``identify.kernels.search.triangle_search``, shared with Liebe's triangle method and tracking, which
differ only in the triangles they give it (and tracking in the catalog stars it allows).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from starnav.identify.base import (
    PAIR_TOL_SIGMAS,
    IdentifyOutcome,
    MatchSettings,
    screen_stars_only,
)
from starnav.identify.database import PairDatabase
from starnav.identify.verify import HypothesisTester, Tally

# with the points in brightness order and a field up to NARROW_DEG across, Pyramid gives up
# after this many hypotheses: the early triangles are the likely ones (at the default options
# every solved frame of 4000 took fewer than 400, 99.9 % fewer than 250; frames with as many
# false as true stars 98 % fewer than 1000), and a random field is refused after it in ~7 ms
# instead of after ``MatchSettings.max_hypotheses`` (docs/verification.md, "Refusing fast")
RANKED_MAX_HYPOTHESES = 1000
# ... at a pair tolerance of RANKED_TOL_PX (0.5 px centroids); a measured triangle finds about
# (tolerance / RANKED_TOL_PX)^3 as many catalog triangles at a wider one, and the budget grows
# with it (a fixed 1000 left pyramid 39 % of the frames at 2 px noise, against 92 % before it)
RANKED_TOL_PX = PAIR_TOL_SIGMAS * math.sqrt(2.0) * 0.5
NARROW_DEG = 59.0
NO_TRIANGLE = "no star triangle matches the catalog"  # the reason when nothing matched
FEWER_THAN_3 = "fewer than 3 stars"
_CLOCKED: list[bool] = []  # whether the kernel and its clock are compiled in this process


@functools.cache
def triangle_order(n: int) -> np.ndarray:
    """Index triples (i < j < k), shape (m, 3), of ``n`` stars in Mortari's order: every star
    is left behind soon, so one false star costs only a few triangles."""
    out = [
        (i, i + dj, i + dj + dk)
        for dj in range(1, n - 1)
        for dk in range(1, n - dj)
        for i in range(n - dj - dk)
    ]
    triples = np.array(out, dtype=np.int64).reshape(-1, 3)
    triples.setflags(write=False)
    return triples


def ranked_budget(settings: MatchSettings) -> int:
    """Pyramid's hypothesis budget with the points in brightness order: ``RANKED_MAX_HYPOTHESES``
    times the cube of the pair tolerance over ``RANKED_TOL_PX`` (at least 1), at most
    ``settings.max_hypotheses``."""
    growth = 1.0
    if settings.pixel_rad:
        growth = max(1.0, settings.pair_tol_rad / settings.pixel_rad / RANKED_TOL_PX) ** 3
    return min(settings.max_hypotheses, round(RANKED_MAX_HYPOTHESES * growth))


def catalog_triangles(
    database: PairDatabase, side_ij: float, side_ik: float, side_jk: float, tol_rad: float
) -> np.ndarray:
    """Catalog index triples (a, b, c), shape (m, 3), whose sides ab, ac, bc agree with the
    measured sides ij, ik, jk within ``tol_rad``."""
    from starnav.identify.kernels import triangles

    n = len(database.catalog)
    return triangles.catalog_triangles(
        database.pair_a,
        database.pair_b,
        database.pair_angle_rad,
        database.catalog.vectors,
        database.everything,
        side_ij,
        side_ik,
        side_jk,
        tol_rad,
        np.full(n, -1, dtype=np.int64),
        np.zeros(n, dtype=np.bool_),
    ).astype(np.intp)


def match_triangles(
    bearings: np.ndarray,
    triangles: np.ndarray,
    database: PairDatabase,
    settings: MatchSettings,
    *,
    allowed: np.ndarray | None = None,
    order: np.ndarray | None = None,
) -> IdentifyOutcome:
    """Try measured triangles (rows of ``bearings``, (m, 3)) in the order given: look up the
    catalog triangles of each, screen them all at once, verify the best until one is accepted
    or the hypothesis budget is spent. ``allowed``: a mask of the catalog rows the search may
    use (default all); ``order``: the rows best-first (``HypothesisTester``)."""
    from starnav.identify.kernels.hypothesis import NOT_FOUND, OUT_OF_TIME
    from starnav.identify.kernels.search import triangle_search

    bearings = np.ascontiguousarray(bearings, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    tester = HypothesisTester(bearings, database, settings, Tally(), allowed, order=order)
    # catalog triangles of a pair table of the whole catalog are made of any stars: their
    # brightness is evidence; of the brightest stars only (wide fields), it is not
    bright_drop = 0 if database.pair_stars in (0, len(database.catalog)) else 3
    search = triangle_search
    radius_rad, sigmas_rad = settings.kernel_args()
    args = (
        bearings,
        triangles,
        database.pair_a,
        database.pair_b,
        database.pair_angle_rad,
        database.max_angle_rad,
        database.sky,
        database.near(radius_rad),
        tester.allowed,
        settings.pair_tol_rad,
        radius_rad,
        sigmas_rad,
        tester.rank,
        tester.point_mag,
        tester.mags,
        bright_drop,
        settings.max_false_match_probability,
        settings.parity or 0,
        settings.max_hypotheses,
    )
    deadline = settings.deadline
    if deadline is not None and not _CLOCKED:
        # compile (or load) the kernel, and run its clock once (its object-mode block
        # compiles when first run inside the kernel: 75 ms) before the deadline's end is
        # read: compiling is not counted; an end of -inf stops at the first triangle
        search(*args[:1], triangles[:1], *args[2:], -math.inf)
        _CLOCKED.append(True)
    r = search(*args, math.inf if deadline is None else deadline.end_time)
    tester.tally.hypotheses, tester.tally.proposed = int(r.hypotheses), int(r.proposed)
    tester.tally.best_p = float(r.best_p)
    if r.status == OUT_OF_TIME:
        tried = f"{r.hypotheses} hypotheses, {r.proposed} verified"
        return IdentifyOutcome(None, deadline.reason(tried), int(r.hypotheses))
    if r.status == NOT_FOUND:
        return tester.outcome(NO_TRIANGLE)
    outcome = tester.tested(
        r.status, r.obs, r.cat, r.R, int(r.parity), float(r.p), float(r.log_sides), bright_drop
    )
    return outcome or tester.outcome(NO_TRIANGLE)


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
            return IdentifyOutcome(None, FEWER_THAN_3, 0)
        if settings.ranked and database.max_angle_rad <= math.radians(NARROW_DEG):
            settings = settings.replaced(max_hypotheses=ranked_budget(settings))
        return match_triangles(
            bearings, order[triangle_order(len(order))], database, settings, order=order
        )
