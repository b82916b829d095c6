"""The test of one hypothesis (numba kernel): its attitude (Wahba), the agreeing stars of the
whole field, its false-match probability, and the mirror check when the parity is unknown;
and the outcomes of a test and of a search.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from starnav.attitude.rotation import wahba
from starnav.identify.kernels.evidence import (
    brightness_log_ratio,
    field_false_match,
    side_log_ratio,
)
from starnav.identify.kernels.pairing import pair_catalog
from starnav.runtime.caching import njit

# outcomes of a hypothesis test and of a search
REJECTED, FOUND, AMBIGUOUS, NOT_FOUND, OUT_OF_TIME = 0, 1, 2, 3, 4

Tested = namedtuple("Tested", "status obs cat R p log_sides")


@njit(cache=True)
def test_hypothesis(bearings, obs_rows, cat_rows, parity, sky, allowed, radius, sigmas, tol,
                    rank, point_mag, mags, bright_drop, hypotheses, max_p, parity_known,
                    work):  # fmt: skip
    """Verify one hypothesis (bearing rows paired with catalog rows, with a parity): its
    attitude (Wahba), the agreeing stars of the whole field, the false-match probability
    over ``hypotheses`` (``false_match``: pairs within ``radius``, the centroid sigma the best
    of ``sigmas``, rad; ``rank``: the points' places in the order, -1: not in it, the first
    ``scored_count`` scored; ``point_mag``: their magnitudes (``brightness_log_ratio``);
    ``mags``: the catalog's, empty when the points' brightness is not known, ``bright_drop``
    of the pairs' brightness scores left out: the built stars', when they come from tables
    of bright stars; with the triangle's sides when it is a triangle
    looked up within ``tol``, rad, 0: not); accepted (``FOUND``) below ``max_p`` unless the
    parity is unknown (``parity_known`` 0) and the mirror image verifies too (``AMBIGUOUS``:
    collinear stars)."""
    vectors = sky[0]
    no_cov = np.zeros((3, 3))
    n_used = len(obs_rows)
    log_sides = 0.0
    if n_used == 3:
        log_sides = side_log_ratio(bearings[obs_rows], vectors[cat_rows], sigmas.max(), tol)
    R = wahba(bearings[obs_rows], vectors[cat_rows], np.ones(n_used), parity)
    v = pair_catalog(bearings, R, sky, allowed, radius, no_cov, False, work)
    log_other = log_sides + brightness_log_ratio(v.obs, v.cat, rank, point_mag, mags, work,
                                                 v.n_cone, bright_drop)  # fmt: skip
    p = field_false_match(v.dist, v.obs, rank, v.n_cone, v.field_area, n_used, hypotheses,
                          sigmas, radius, log_other)  # fmt: skip
    if p > max_p:
        return Tested(REJECTED, v.obs, v.cat, R, p, log_sides)
    if parity_known == 0:
        R_m = wahba(bearings[v.obs], vectors[v.cat], np.ones(len(v.obs)), -parity)
        m = pair_catalog(bearings, R_m, sky, allowed, radius, no_cov, False, work)
        log_m = log_sides + brightness_log_ratio(m.obs, m.cat, rank, point_mag, mags, work,
                                                 m.n_cone, bright_drop)  # fmt: skip
        p_m = field_false_match(m.dist, m.obs, rank, m.n_cone, m.field_area, n_used,
                                hypotheses, sigmas, radius, log_m)  # fmt: skip
        if p_m <= max_p:
            return Tested(AMBIGUOUS, v.obs, v.cat, R, p, log_sides)
    return Tested(FOUND, v.obs, v.cat, R, p, log_sides)
