"""Mortari's triangle loop over an array of star triples (numba kernels), shared by Pyramid,
Triangle and tracking: each measured triangle's catalog triangles looked up, all their
hypotheses screened (a quick count of the bearings near a catalog star), the best verified
until one is accepted, nothing left can be, the hypothesis budget is spent or the clock runs
out.
"""

from __future__ import annotations

import math
import time
from collections import namedtuple

import numpy as np

from starnav.attitude.rotation import det3, wahba
from starnav.identify.kernels.evidence import (
    best_case_false_match,
    brightness_log_bound,
    scored_count,
    side_log_bound,
)
from starnav.identify.kernels.hypothesis import (
    NOT_FOUND,
    OUT_OF_TIME,
    REJECTED,
    test_hypothesis,
)
from starnav.identify.kernels.sky import angle, chord, cone, field_radius, near_cell
from starnav.identify.kernels.triangles import catalog_triangles
from starnav.runtime.caching import kernel_objmode, njit

FLAT_FACTOR = 3.0  # a triangle is too flat to give its orientation below 3 tol x its longest side
WIDE_SCREEN_RAD = math.radians(35.0)  # wider fields: the screen does not count the field cone
CLOCK_EVERY = 32  # with a time budget, the clock is read every this many hypotheses

objmode = kernel_objmode()  # numba's, or a stand-in when the kernels run as plain Python

Search = namedtuple("Search", "status obs cat R parity p log_sides hypotheses proposed best_p")


@njit(cache=True)
def _screen(bearings, tri, triples, parities, sky, near, allowed, screen2, end_time):
    """Per hypothesis, how many bearings land near some catalog star under its attitude (a
    quick count: each bearing's one cell of the near-star grid ``near`` looked up),
    and its boresight (ICRS, for the field cone's star count, which the search makes only for
    the hypotheses it may verify); stops early (the rest counted 0) after ``end_time``
    (``clock`` seconds)."""
    vectors = sky[0]
    m = len(triples)
    agree = np.zeros(m, dtype=np.int64)
    axes = np.zeros((m, 3))
    ones = np.ones(3)
    sky_b = np.empty(3)
    for h in range(m):
        if h % CLOCK_EVERY == CLOCK_EVERY - 1 and end_time < math.inf and clock() > end_time:
            break
        R = wahba(tri, vectors[triples[h]], ones, parities[h])
        for k in range(3):
            axes[h, k] = R[2, k]
        for b in range(len(bearings)):
            for k in range(3):
                sky_b[k] = (
                    R[0, k] * bearings[b, 0] + R[1, k] * bearings[b, 1] + R[2, k] * bearings[b, 2]
                )
            agree[h] += near_cell(sky_b, screen2, near, vectors, allowed)
    return agree, axes


@njit(cache=True)
def _orientations(tri, triples, vectors, tol, longest, parity_known):
    """The hypotheses of a measured triangle's catalog triangles, each with its parity (the
    sign of the triple products; both ways when the triangle is too flat to tell), only
    those of the known parity when it is known."""
    m = len(triples)
    det_obs = det3(tri[0], tri[1], tri[2])
    parities = np.empty(m, dtype=np.int64)
    for h in range(m):
        det_cat = det3(vectors[triples[h, 0]], vectors[triples[h, 1]], vectors[triples[h, 2]])
        parities[h] = 1 if np.sign(det_obs) == np.sign(det_cat) else -1
    if abs(det_obs) < FLAT_FACTOR * tol * longest:
        both = np.empty((2 * m, 3), dtype=np.int64)
        both[:m] = triples
        both[m:] = triples
        par2 = np.empty(2 * m, dtype=np.int64)
        par2[:m] = parities
        par2[m:] = -parities
        triples, parities = both, par2
    if parity_known != 0:
        keep = parities == parity_known
        triples, parities = triples[keep], parities[keep]
    return triples, parities


@njit(cache=True)
def _shortest_sides_first(bearings, idx):
    """The triangle ``idx`` (3 rows of ``bearings``) with its first star opposite its longest
    side: the catalog join scans the pairs of the two sides at the first star, and there are
    fewer pairs at shorter angles (about in proportion)."""
    s01 = angle(bearings[idx[0]], bearings[idx[1]])
    s02 = angle(bearings[idx[0]], bearings[idx[2]])
    s12 = angle(bearings[idx[1]], bearings[idx[2]])
    out = idx.copy()
    if s01 >= s02 and s01 >= s12:  # longest 01: star 2 first
        out[0], out[1], out[2] = idx[2], idx[0], idx[1]
    elif s02 >= s01 and s02 >= s12:  # longest 02: star 1 first
        out[0], out[1], out[2] = idx[1], idx[0], idx[2]
    return out


@njit(cache=True)
def triangle_search(bearings, triangles, pair_a, pair_b, pair_angle, max_angle, sky, near,
                    allowed, tol, radius, sigmas, rank, point_mag, mags, bright_drop, max_p,
                    parity_known, max_hypotheses, end_time):  # fmt: skip
    """Try the measured ``triangles`` (rows of ``bearings``, (t, 3)) in order: look up the
    catalog triangles of each, screen all their hypotheses, verify the best (by the screen)
    until one is accepted, nothing left can be, ``max_hypotheses`` are spent or the
    ``clock`` passes ``end_time`` (s; looked at for every triangle and every ``CLOCK_EVERY``
    hypotheses screened or verified; status ``OUT_OF_TIME``)."""
    vectors = sky[0]
    field_rad = field_radius(bearings, radius)
    field_area = 1.0 - math.cos(field_rad)
    ranked = len(mags) > 0
    n_ranked = scored_count(rank, 1e18)
    sides_bound = side_log_bound(sigmas.max(), tol)
    screen2 = chord(radius) ** 2
    wide = field_rad > WIDE_SCREEN_RAD
    cone2 = chord(field_rad) ** 2
    work = np.empty(len(vectors), dtype=np.int64)
    head = np.full(len(vectors), -1, dtype=np.int64)
    mark = np.zeros(len(vectors), dtype=np.bool_)
    hypotheses, proposed, best_p = 0, 0, 1.0
    empty = np.empty(0, dtype=np.int64)
    tri = np.empty((3, 3))
    timed = end_time < math.inf
    status = NOT_FOUND
    for t in range(len(triangles)):
        if timed and clock() > end_time:
            status = OUT_OF_TIME
            break
        idx = _shortest_sides_first(bearings, triangles[t])
        for k in range(3):
            tri[k] = bearings[idx[k]]
        s01, s02, s12 = angle(tri[0], tri[1]), angle(tri[0], tri[2]), angle(tri[1], tri[2])
        longest = s12
        # a side within the tolerance of zero matches nearly every catalog pair
        if min(s01, s02, s12) < 2.0 * tol or longest > max_angle + tol:
            continue
        triples = catalog_triangles(pair_a, pair_b, pair_angle, vectors, allowed, s01, s02, s12,
                                    tol, head, mark)  # fmt: skip
        if len(triples) == 0:
            continue
        triples, parities = _orientations(tri, triples, vectors, tol, longest, parity_known)
        if len(triples) == 0:
            continue
        hypotheses += len(triples)
        agree, axes = _screen(bearings, tri, triples, parities, sky, near, allowed, screen2,
                              end_time)  # fmt: skip
        if timed and clock() > end_time:
            status = OUT_OF_TIME
            break
        for h in np.argsort(-agree, kind="mergesort"):
            # on a field of one catalog star, the brightness at its best, no point scored but
            # the agreeing ones (no field does better): neither this nor any later (lower)
            # count can be convincing; on its own field: not this one
            best_other = sides_bound + brightness_log_bound(agree[h], bright_drop, 1e9, ranked)
            n_best = min(agree[h], n_ranked)
            if best_case_false_match(n_best, n_best, 3, 1, field_area, hypotheses, sigmas,
                                     radius, best_other) > max_p:  # fmt: skip
                break
            # the catalog stars of its field cone (as ``pair_catalog`` counts them; not
            # counted, 0, on a wide field)
            n_cone = 0 if wide else cone(axes[h], cone2, sky, allowed, work)
            own = sides_bound + brightness_log_bound(agree[h], bright_drop, n_cone, ranked)
            n_scored = scored_count(rank, n_cone)
            if n_cone > 0 and best_case_false_match(n_scored, agree[h], 3, n_cone,
                                                       field_area, hypotheses, sigmas, radius,
                                                       own) > max_p:  # fmt: skip
                continue
            if timed and proposed % CLOCK_EVERY == CLOCK_EVERY - 1 and clock() > end_time:
                status = OUT_OF_TIME
                break
            proposed += 1
            r = test_hypothesis(bearings, idx, triples[h], parities[h], sky, allowed, radius,
                                sigmas, tol, rank, point_mag, mags, bright_drop, hypotheses, max_p,
                                parity_known, work)  # fmt: skip
            best_p = min(best_p, r.p)
            if r.status != REJECTED:
                return Search(r.status, r.obs, r.cat, r.R, parities[h], r.p, r.log_sides,
                              hypotheses, proposed, best_p)  # fmt: skip
        if status == OUT_OF_TIME or hypotheses >= max_hypotheses:
            break
    return Search(status, empty, empty, np.zeros((3, 3)), 0, 1.0, 0.0, hypotheses, proposed,
                  best_p)  # fmt: skip


@njit(cache=True)
def clock():
    """``time.perf_counter()`` inside a kernel (s; ~2 µs a call): for the time budget."""
    with objmode(t="float64"):
        t = time.perf_counter()
    return t
