"""Kernels of the identification stage (numba; plain Python under ``NUMBA_DISABLE_JIT=1``).

Cone searches on the catalog's RA / Dec grid, the one-to-one pairing of bearings with
reprojected catalog stars, the false-match probability (likelihood ratios), the catalog triangle
join on the pair table, the test of one hypothesis (attitude, agreement, mirror check) and
Mortari's triangle loop over an array of star triples, shared by Pyramid, Triangle and
tracking. Every decision of the verification is written here once; the Python modules
(``verify``, ``pyramid``, ``tracking``, ...) call these kernels.

The sky grid ``sky = (vectors, start, rows, n_dec, n_ra, step_rad)``: cell ``i * n_ra + j``
(Dec band i from the south pole, RA column j) holds catalog rows ``rows[start[c]:start[c+1]]``
(``identify.database.sky_grid``); the screen asks instead one cell of a cube's faces whether a
star is near (``near = (start, rows, n)``, ``identify.database.near_grid``). Searches see only
the rows where ``allowed`` is True (tracking: the stars near the prior).
"""

from __future__ import annotations

import math
import time
from collections import namedtuple

import numpy as np
from numba import objmode

from starnav.attitude.rotation import det3, wahba
from starnav.runtime.caching import njit

# outcomes of a hypothesis test and of a search
REJECTED, FOUND, AMBIGUOUS, NOT_FOUND, OUT_OF_TIME = 0, 1, 2, 3, 4
FLAT_FACTOR = 3.0  # a triangle is too flat to give its orientation below 3 tol x its longest side
GATE_SIGMAS = 3.0  # a gated catalog star's radius grows by this many sigma of its position
PRIOR_SIGMAS = 3.0  # tracking allows the catalog stars within the field plus this many sigma
_NO_EDGE = 1e6  # cost of a pair that is not within the radius (chord^2 is at most 4)
SMALL_GROUP = 8  # contested groups of up to this many pairs: every subset tried (2^8)

Pairs = namedtuple("Pairs", "obs cat dist n_cone field_area")
Tested = namedtuple("Tested", "status obs cat R p log_sides")
Search = namedtuple("Search", "status obs cat R parity p log_sides hypotheses proposed best_p")


@njit(cache=True)
def chord(angle):
    """Chord between unit vectors ``angle`` (rad) apart."""
    return 2.0 * math.sin(0.5 * angle)


@njit(cache=True)
def angle(a, b):
    """Angle (rad) between unit vectors (stable at small and large angles)."""
    d = 0.0
    s = 0.0
    for k in range(3):
        d += (a[k] - b[k]) ** 2
        s += (a[k] + b[k]) ** 2
    return 2.0 * math.atan2(math.sqrt(d), math.sqrt(s))


WIDE_CONE_RAD = math.radians(60.0)  # cones wider than this are searched row by row
WIDE_SCREEN_RAD = math.radians(35.0)  # wider fields: the screen does not count the field cone
CLOCK_EVERY = 32  # with a time budget, the clock is read every this many hypotheses


@njit(cache=True, inline="always")
def _within(vectors, r, axis, chord2):
    """Whether row ``r`` of ``vectors`` is within chord sqrt(chord2) of ``axis``."""
    dx = vectors[r, 0] - axis[0]
    dy = vectors[r, 1] - axis[1]
    dz = vectors[r, 2] - axis[2]
    return dx * dx + dy * dy + dz * dz <= chord2


@njit(cache=True, inline="always")
def _cells(axis, radius, n_dec, n_ra, step):
    """The Dec bands ``i_lo..i_hi`` and RA columns ``j_lo..j_hi`` (mod ``n_ra``) of the sky
    grid that hold every point within ``radius`` (rad) of ``axis``."""
    dec0 = math.asin(max(-1.0, min(1.0, axis[2])))
    ra0 = math.atan2(axis[1], axis[0])
    lo, hi = dec0 - radius, dec0 + radius
    i_lo = max(0, math.floor((lo + 0.5 * math.pi) / step))
    i_hi = min(n_dec - 1, math.floor((hi + 0.5 * math.pi) / step))
    full = hi >= 0.5 * math.pi or lo <= -0.5 * math.pi or math.sin(radius) >= math.cos(dec0)
    j_lo, j_hi = 0, n_ra - 1
    if not full:
        half = math.asin(math.sin(radius) / math.cos(dec0)) + 1e-9
        j_lo = math.floor((ra0 - half) / step)
        j_hi = math.floor((ra0 + half) / step)
        if j_hi - j_lo + 1 >= n_ra:
            j_lo, j_hi = 0, n_ra - 1
    return i_lo, i_hi, j_lo, j_hi


@njit(cache=True)
def cone_radius(chord2):
    """The angle (rad) of chord sqrt(``chord2``), a hair wider (the cells searched for it)."""
    return 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(chord2))) + 1e-9


@njit(cache=True)
def cone(axis, chord2, sky, allowed, out):
    """Allowed rows of the sky's vectors within chord sqrt(chord2) of ``axis``, written to
    ``out``; returns how many."""
    vectors, start, rows, n_dec, n_ra, step = sky
    radius = cone_radius(chord2)
    # a wide field's cone: every row in one run beats visiting the cells
    wide = radius > WIDE_CONE_RAD
    i_lo, i_hi, j_lo, j_hi = (0, 0, 0, 0) if wide else _cells(axis, radius, n_dec, n_ra, step)
    n_j = j_hi - j_lo + 1
    n = 0
    for g in range(1 if wide else (i_hi - i_lo + 1) * n_j):
        lo, hi = 0, len(vectors)
        if not wide:
            cell = (i_lo + g // n_j) * n_ra + (j_lo + g % n_j) % n_ra
            lo, hi = start[cell], start[cell + 1]
        for m in range(lo, hi):
            r = m if wide else rows[m]
            if allowed[r] and _within(vectors, r, axis, chord2):
                out[n] = r
                n += 1
    return n


@njit(cache=True)
def near_cell(axis, chord2, near, vectors, allowed):
    """Whether an allowed row of ``vectors`` is within chord sqrt(chord2) of ``axis`` (a
    unit vector), for a chord within the radius ``near`` was built for
    (``identify.database.near_grid``): the stars listed in the one cell of ``axis``."""
    start, rows, n = near
    ax, big = 0, abs(axis[0])
    if abs(axis[1]) > big:
        ax, big = 1, abs(axis[1])
    if abs(axis[2]) > big:
        ax, big = 2, abs(axis[2])
    face = 2 * ax + (1 if axis[ax] < 0.0 else 0)
    i = min(max(math.floor((axis[(ax + 1) % 3] / big + 1.0) * 0.5 * n), 0), n - 1)
    j = min(max(math.floor((axis[(ax + 2) % 3] / big + 1.0) * 0.5 * n), 0), n - 1)
    cell = (face * n + i) * n + j
    for m in range(start[cell], start[cell + 1]):
        r = rows[m]
        if allowed[r] and _within(vectors, r, axis, chord2):
            return True
    return False


# the chance that a measured point is a star of the catalog under a right hypothesis (the
# rest: false stars, stars fainter than the catalog). Any value keeps each likelihood ratio's
# expectation 1 under a wrong hypothesis; at 1/2 a false point halves the odds
Q_STAR = 0.5
# brightness (when the points' magnitudes are known): under a right hypothesis a point of
# magnitude m is, with chance BRIGHT_WEIGHT, a star of catalog magnitude m + z + N(0, sigma)
# (z the zero point, the same for every point), otherwise any star of the field cone; sigma one
# of MAG_SIGMAS_MAG, or the brightness tells nothing (weight NO_BRIGHTNESS_WEIGHT, the rest
# split evenly); z uniform over what the field's and the points' magnitudes allow, widened by
# ZERO_POINT_MARGIN_MAG, on a grid of MAG_STEPS steps a sigma (brightness_log_ratio). The
# BRIGHT_PAIRS brightest points paired are scored, each ratio capped at BRIGHT_MAX_RATIO
BRIGHT_WEIGHT = 0.9
MAG_SIGMAS_MAG = (0.1, 0.2, 0.4, 0.8)
NO_BRIGHTNESS_WEIGHT = 0.2
ZERO_POINT_MARGIN_MAG = 0.5
BRIGHT_PAIRS = 8
BRIGHT_MAX_RATIO = 16.0
MAG_STEPS = 8
MAG_CUT = 5  # sigma
MAG_WINDOW = 3.0  # sigma
# the magnitude kernel g at offsets -MAG_CUT..MAG_CUT sigma, in steps of 1 / MAG_STEPS sigma
MAG_TABLE = np.array(
    [
        math.exp(-0.5 * (d / MAG_STEPS) ** 2)
        for d in range(-MAG_CUT * MAG_STEPS, MAG_CUT * MAG_STEPS + 1)
    ]
)
# the points scored: the first SCORED_PER_STAR x the catalog stars of the field cone in the
# order (at least MIN_SCORED); the fainter ones are expected to be fainter than the catalog
SCORED_PER_STAR = 2.0
MIN_SCORED = 8


@njit(cache=True)
def _log_add(a, b):
    """log(e^a + e^b) without overflow."""
    m = max(a, b)
    return m + math.log(math.exp(a - m) + math.exp(b - m))


@njit(cache=True)
def star_log_ratios(dist, n_cone, field_area, sigma, q, radius, out):
    """Natural-log likelihood ratios, right hypothesis against wrong, of the paired points
    (chords ``dist``) written to ``out``, and returned: that of one unmatched point.

    A wrong hypothesis drops a point anywhere on the field: the ``n_cone`` catalog stars of
    a field cone whose ``1 - cos(half-angle)`` is ``field_area`` are a Poisson field to it,
    so in s = 1 - cos d its nearest star is exponential of rate rho = n_cone / field_area
    (u = rho s; no star within ``radius``: e^(-u_R)). Under the right one a point is a
    catalog star with chance ``q``, its offset a 2-D Gaussian of ``sigma`` (rad): s is
    exponential with mean sigma^2; otherwise it falls as under the wrong one. So a pair at s
    scores (1 - q) + q e^(u - s / sigma^2) / lambda, lambda = rho sigma^2, and a point with
    no star within the radius (1 - q) + q e^(u_R - s_R / sigma^2)."""
    rho = n_cone / field_area
    log_q, log_rest = math.log(q), math.log(1.0 - q)
    log_lam = math.log(max(rho * sigma * sigma, 1e-300))
    for k in range(len(dist)):
        s = 0.5 * dist[k] * dist[k]
        out[k] = _log_add(log_rest, log_q - log_lam + rho * s - s / (sigma * sigma))
    s_r = 2.0 * math.sin(0.5 * radius) ** 2  # 1 - cos(radius)
    return _log_add(log_rest, log_q + rho * s_r - s_r / (sigma * sigma))


@njit(cache=True)
def brightness_log_ratio(obs, cat, rank, point_mag, mags, cone_rows, n_cone, n_used):
    """Natural-log likelihood ratio, right hypothesis against wrong, of the magnitudes of
    the pairs (points ``obs`` of places ``rank`` in the order, -1: not in it, and
    magnitudes ``point_mag``, NaN: not measured, empty: the brightness is not known;
    catalog rows ``cat`` of magnitudes ``mags``) among the ``n_cone`` catalog stars
    ``cone_rows`` of the field.

    A wrong hypothesis pairs a point with any star of the field, whatever its magnitude; a
    right one pairs a point of magnitude m with a star of magnitude about t = m + z. A pair
    scores (1 - w) + w n_cone g(M) / sum over the field's stars of g(M'), g a Gaussian of
    the magnitude sigma about t: its expectation under a wrong hypothesis is 1 for any t
    fixed by the point alone, so is the product's over pairs at one zero point z, and the
    mixture's over z, the sigmas and no evidence (see the constants). To make it cheap and
    exact, magnitudes and zero points are counted in steps of a ``MAG_STEPS``-th of the
    sigma: z on the grid of steps (uniform over the prior's grid points), m rounded to a
    step, M to the middle of its 4 steps' bin, g cut at ``MAG_CUT`` sigma; the zero points
    further than ``MAG_WINDOW`` sigma from the pairs' median offset are left out (which can
    only make the ratio smaller). The ``BRIGHT_PAIRS`` pairs of the brightest points are
    scored; when the hypothesis's own stars came from tables of the brightest stars (the FOV
    search's, wide fields'), the ``n_used`` largest scores are left out."""
    if len(mags) == 0 or len(point_mag) == 0 or n_cone < 2:
        return 0.0
    # the pairs of the brightest points with a magnitude
    order = np.argsort(rank[obs])
    m = np.empty(BRIGHT_PAIRS)
    M = np.empty(BRIGHT_PAIRS)
    n = 0
    for k in order:
        if n < BRIGHT_PAIRS and rank[obs[k]] >= 0 and math.isfinite(point_mag[obs[k]]):
            m[n], M[n] = point_mag[obs[k]], mags[cat[k]]
            n += 1
    if n <= n_used:
        return 0.0
    m, M = m[:n], M[:n]
    cone = mags[cone_rows[:n_cone]]
    cone_lo, cone_hi = cone.min(), cone.max()
    # the zero point's prior: the brightest point is at most the field's faintest star and
    # at least its brightest (both within the margin)
    m_min = math.inf
    for i in range(len(point_mag)):
        if rank[i] >= 0 and math.isfinite(point_mag[i]):
            m_min = min(m_min, point_mag[i])
    z_lo = cone_lo - m_min - ZERO_POINT_MARGIN_MAG
    z_hi = cone_hi - m_min + ZERO_POINT_MARGIN_MAG
    z_mid = np.median(M - m)
    w = BRIGHT_WEIGHT
    cut = MAG_CUT * MAG_STEPS
    table = MAG_TABLE
    factors = np.empty(n)
    total = math.log(NO_BRIGHTNESS_WEIGHT)
    log_each = math.log((1.0 - NO_BRIGHTNESS_WEIGHT) / len(MAG_SIGMAS_MAG))
    for sigma in MAG_SIGMAS_MAG:
        h = sigma / MAG_STEPS
        i_lo, i_hi = math.ceil(z_lo / h), math.floor(z_hi / h)  # the prior's grid points
        w_lo = max(i_lo, math.ceil((z_mid - MAG_WINDOW * sigma) / h))
        w_hi = min(i_hi, math.floor((z_mid + MAG_WINDOW * sigma) / h))
        if w_hi < w_lo:
            continue
        # the field's stars counted in bins of 4 steps, b0 the first
        b0 = math.floor(cone_lo / (4.0 * h))
        counts = np.zeros(math.floor(cone_hi / (4.0 * h)) - b0 + 1)
        for c in range(n_cone):
            counts[math.floor(cone[c] / (4.0 * h)) - b0] += 1.0
        r = np.empty(n, dtype=np.int64)  # the points' magnitudes in steps
        bins = np.empty(n, dtype=np.int64)  # their stars' bins
        for k in range(n):
            r[k] = round(m[k] / h)
            bins[k] = math.floor(M[k] / (4.0 * h)) - b0
        # the sum over the field of g at every t (in steps) the pairs take
        j_lo, j_hi = r.min() + w_lo, r.max() + w_hi
        field_sum = np.zeros(j_hi - j_lo + 1)
        for j in range(j_lo, j_hi + 1):
            b_first = max(math.ceil((j - cut - 2) / 4.0) - b0, 0)
            b_last = min(math.floor((j + cut - 2) / 4.0) - b0, len(counts) - 1)
            acc = 0.0
            for b in range(b_first, b_last + 1):
                acc += counts[b] * table[4 * (b + b0) + 2 - j + cut]
            field_sum[j - j_lo] = acc
        acc = 0.0
        for i in range(w_lo, w_hi + 1):
            for k in range(n):
                j = r[k] + i
                d = 4 * (bins[k] + b0) + 2 - j
                own = table[d + cut] if abs(d) <= cut else 0.0
                ratio = n_cone * own / max(field_sum[j - j_lo], own) if own > 0.0 else 0.0
                factors[k] = (1.0 - w) + w * min(ratio, BRIGHT_MAX_RATIO)
            if n_used > 0:
                factors.sort()
            product = 1.0  # at most BRIGHT_MAX_RATIO ** BRIGHT_PAIRS: no overflow
            for k in range(n - n_used):
                product *= factors[k]
            acc += product
        total = _log_add(total, log_each + math.log(acc / (i_hi - i_lo + 1)))
    return total


@njit(cache=True)
def brightness_log_bound(n_agree, n_used, n_cone, ranked):
    """The largest ``brightness_log_ratio`` ``n_agree`` pairs, ``n_used`` of them left out,
    can have among ``n_cone`` catalog stars (0 when the brightness is not known)."""
    n = min(n_agree, BRIGHT_PAIRS) - n_used
    if not ranked or n <= 0 or n_cone < 2:
        return 0.0
    ratio = (1.0 - BRIGHT_WEIGHT) + BRIGHT_WEIGHT * min(n_cone, BRIGHT_MAX_RATIO)
    return math.log(NO_BRIGHTNESS_WEIGHT + (1.0 - NO_BRIGHTNESS_WEIGHT) * ratio**n)


@njit(cache=True)
def side_log_ratio(tri, cat_tri, sigma, tol):
    """Natural-log likelihood ratio of the sides of a measured star triangle ``tri`` (3, 3)
    against those of its catalog triangle ``cat_tri`` (3, 3): a wrong hypothesis's catalog
    sides fall anywhere within ``tol`` (rad) of the measured ones, a right one's differ by a
    Gaussian of sqrt(2) ``sigma`` (two centroid errors): 2 tol N(delta) per side, whose
    expectation over the window is at most 1. 0 without a window (``tol`` 0)."""
    if tol <= 0.0:
        return 0.0
    s = math.sqrt(2.0) * sigma
    total = 0.0
    for i in range(3):
        for j in range(i + 1, 3):
            d = angle(tri[i], tri[j]) - angle(cat_tri[i], cat_tri[j])
            total += math.log(2.0 * tol / (math.sqrt(2.0 * math.pi) * s)) - 0.5 * (d / s) ** 2
    return total


@njit(cache=True)
def side_log_bound(sigma, tol):
    """The largest ``side_log_ratio`` (every side exact)."""
    if tol <= 0.0:
        return 0.0
    return 3.0 * math.log(2.0 * tol / (math.sqrt(2.0 * math.pi) * math.sqrt(2.0) * sigma))


@njit(cache=True)
def _scored_limit(n_cone):
    """The place in the order below which points are scored."""
    return max(MIN_SCORED, SCORED_PER_STAR * n_cone)


@njit(cache=True)
def scored_count(rank, n_cone):
    """How many points the statistic scores: those of ``rank`` (their place in the order)
    below max(``MIN_SCORED``, ``SCORED_PER_STAR`` ``n_cone``)."""
    limit = _scored_limit(n_cone)
    n = 0
    for r in rank:
        n += 0 <= r < limit
    return n


@njit(cache=True)
def scored_pairs(dist, obs, rank, n_cone):
    """The chords of the pairs whose points are scored (``scored_count``)."""
    limit = _scored_limit(n_cone)
    keep = np.empty(len(dist), dtype=np.bool_)
    for k in range(len(dist)):
        keep[k] = 0 <= rank[obs[k]] < limit
    return dist[keep]


@njit(cache=True)
def field_false_match(dist, obs, rank, n_cone, field_area, n_used, hypotheses, sigmas, radius,
                      log_other):  # fmt: skip
    """``false_match`` of the scored points only (``scored_count``): pairs ``obs`` (rows of
    the points) at chords ``dist``, the points' places ``rank`` in the order."""
    return false_match(scored_pairs(dist, obs, rank, n_cone), n_cone, field_area,
                       scored_count(rank, n_cone), n_used, hypotheses, sigmas, radius,
                       log_other)  # fmt: skip


@njit(cache=True)
def false_match(dist, n_cone, field_area, n_stars, n_used, hypotheses, sigmas, radius,
                log_other):  # fmt: skip
    """The false-match probability of a hypothesis whose pairs are at chords ``dist`` (rad),
    ``n_stars`` points in all: ``len(sigmas) hypotheses / Lambda``, Lambda the product of the
    points' likelihood ratios (``star_log_ratios``, star fraction ``Q_STAR``) at the centroid
    sigma of ``sigmas`` (rad) that gives the largest, times
    e^``log_other`` (the brightness and triangle-side ratios). The ``n_used`` points that
    built a hypothesis agree by construction: the best-scoring ``n_used`` pairs are left out
    (unmatched points when fewer paired). Each ratio has expectation 1 (at most) under a
    wrong hypothesis, so P(Lambda >= t) <= 1/t (Markov); over the hypotheses tried and the
    sigmas taken the best of, P(p <= alpha) <= alpha (alpha (1 + ln H) over a
    search that stops at its first acceptance, H counted as it goes): a probability of being
    wrong that can only err high."""
    n_pairs = len(dist)
    dropped = min(n_used, n_pairs)
    n_unmatched = max(n_stars - n_pairs - (n_used - dropped), 0)
    best = -math.inf
    logs = np.empty(n_pairs)
    for sigma in sigmas:
        miss = star_log_ratios(dist, n_cone, field_area, sigma, Q_STAR, radius, logs)
        logs.sort()
        total = n_unmatched * miss
        for k in range(n_pairs - dropped):
            total += logs[k]
        best = max(best, total)
    log_p = math.log(len(sigmas) * max(hypotheses, 1)) - best - log_other
    return math.exp(min(log_p, 0.0))


@njit(cache=True)
def best_case_false_match(n_stars, n_agree, n_used, n_cone, field_area, hypotheses, sigmas,
                          radius, max_other):  # fmt: skip
    """The smallest ``false_match`` a hypothesis can reach with ``n_agree`` of ``n_stars``
    points within ``radius`` of a catalog star, ``n_cone`` (at least 1) catalog stars on the
    field: every agreeing point exactly on its star, or none agreeing (better when a field is
    so dense that a match scores less than a miss, lambda > ~1); ``max_other``: the largest
    brightness and side log ratios it can have. For a screen: a hypothesis that cannot beat
    the threshold even so is not verified."""
    n_agree = min(n_agree, n_stars)
    n_cone = max(n_cone, 1)
    on_stars = false_match(np.zeros(n_agree), n_cone, field_area, n_stars, n_used, hypotheses,
                           sigmas, radius, max_other)  # fmt: skip
    none = false_match(np.zeros(0), n_cone, field_area, n_stars, n_used, hypotheses, sigmas,
                       radius, max_other)  # fmt: skip
    return min(on_stars, none)


@njit(cache=True)
def field_radius(bearings, radius):
    """Half-angle (rad) of the cone about the boresight holding every bearing, grown by
    ``radius``: the field the chance of agreement is reckoned over."""
    zmin = 1.0
    for n in range(len(bearings)):
        zmin = min(zmin, bearings[n, 2])
    return math.acos(max(-1.0, min(1.0, zmin))) + radius


@njit(cache=True)
def assign(cost):
    """Rectangular linear assignment of least total cost (rows <= columns): the column of
    each row. The shortest augmenting path method scipy's ``linear_sum_assignment`` uses
    (Crouse 2016), with its tie-breaking."""
    nr, nc = cost.shape
    u = np.zeros(nr)
    v = np.zeros(nc)
    col4row = np.full(nr, -1, dtype=np.int64)
    row4col = np.full(nc, -1, dtype=np.int64)
    for cur in range(nr):
        shortest = np.full(nc, np.inf)
        path = np.full(nc, -1, dtype=np.int64)
        in_rows = np.zeros(nr, dtype=np.bool_)
        in_cols = np.zeros(nc, dtype=np.bool_)
        remaining = np.arange(nc - 1, -1, -1)
        n_left = nc
        min_val = 0.0
        i = cur
        sink = -1
        while sink == -1:
            in_rows[i] = True
            lowest = np.inf
            index = -1
            for it in range(n_left):
                j = remaining[it]
                r = min_val + cost[i, j] - u[i] - v[j]
                if r < shortest[j]:
                    path[j] = i
                    shortest[j] = r
                if shortest[j] < lowest or (shortest[j] == lowest and row4col[j] == -1):
                    lowest = shortest[j]
                    index = it
            min_val = lowest
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            in_cols[j] = True
            n_left -= 1
            remaining[index] = remaining[n_left]
        u[cur] += min_val
        for i in range(nr):
            if in_rows[i] and i != cur:
                u[i] += min_val - shortest[col4row[i]]
        for j in range(nc):
            if in_cols[j]:
                v[j] -= min_val - shortest[j]
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            col4row[i], j = j, col4row[i]
            if i == cur:
                break
    return col4row


@njit(cache=True)
def _resolve_small(members, e_b, e_m, e_d2, chosen):
    """``_resolve_group`` of a group of at most ``SMALL_GROUP`` pairs: every subset of
    pairs tried (no point or star twice; most pairs, then least total squared distance)."""
    size = len(members)
    best_mask, best_n, best_cost = 0, -1, np.inf
    for mask in range(1, 1 << size):
        n_pairs, cost, ok = 0, 0.0, True
        for x in range(size):
            if not (mask >> x) & 1:
                continue
            for y in range(x):
                if (mask >> y) & 1 and (
                    e_b[members[x]] == e_b[members[y]] or e_m[members[x]] == e_m[members[y]]
                ):
                    ok = False
            n_pairs += 1
            cost += e_d2[members[x]]
        if ok and (n_pairs > best_n or (n_pairs == best_n and cost < best_cost)):
            best_mask, best_n, best_cost = mask, n_pairs, cost
    for x in range(size):
        chosen[members[x]] = (best_mask >> x) & 1 == 1


@njit(cache=True)
def _resolve_group(members, e_b, e_m, e_d2, chosen):
    """One-to-one pairing of a group of candidate pairs linked through shared points or
    stars: most pairs, then least total squared distance. Small groups by trying every
    subset; larger ones as a linear assignment in which a pair that is not a candidate costs
    more than any that is."""
    size = len(members)
    if size <= SMALL_GROUP:
        _resolve_small(members, e_b, e_m, e_d2, chosen)
        return
    pts = np.unique(e_b[members])
    sts = np.unique(e_m[members])
    transpose = len(pts) > len(sts)
    nr, nc = (len(sts), len(pts)) if transpose else (len(pts), len(sts))
    cost = np.full((nr, nc), _NO_EDGE)
    for x in range(size):
        e = members[x]
        i = np.searchsorted(pts, e_b[e])
        j = np.searchsorted(sts, e_m[e])
        if transpose:
            cost[j, i] = e_d2[e]
        else:
            cost[i, j] = e_d2[e]
    col = assign(cost)
    for x in range(size):
        e = members[x]
        i = np.searchsorted(pts, e_b[e])
        j = np.searchsorted(sts, e_m[e])
        if transpose:
            chosen[e] = col[j] == i
        else:
            chosen[e] = col[i] == j


@njit(cache=True)
def pair_catalog(bearings, R, sky, allowed, radius, cov, gate, work):
    """Pair ``bearings`` (n, 3) one to one with the catalog stars reprojected by ``R`` within
    chord(``radius``), least total squared distance (so close doubles are not both given one
    star). With ``gate``, each star's radius grows by ``GATE_SIGMAS`` of its position under
    the rotation covariance ``cov`` (a rotation omega moves c by omega x c: E|omega x c|^2 =
    tr C - c^T C c). ``work``: one int64 per catalog row. Pairs come in the order of the
    points."""
    vectors = sky[0]
    field_rad = field_radius(bearings, radius)
    n_cone = cone(R[2], chord(field_rad) ** 2, sky, allowed, work)
    n_b = len(bearings)
    base2 = chord(radius) ** 2
    trace = cov[0, 0] + cov[1, 1] + cov[2, 2]
    use_gate = gate and np.all(np.isfinite(cov))
    cam = np.empty((n_cone, 3))
    radius2 = np.empty(n_cone)
    for m in range(n_cone):
        row = work[m]
        v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
        for i in range(3):
            cam[m, i] = R[i, 0] * v0 + R[i, 1] * v1 + R[i, 2] * v2
        radius2[m] = base2
        if use_gate:
            var = trace
            for i in range(3):
                for j in range(3):
                    var -= cam[m, i] * cov[i, j] * cam[m, j]
            radius2[m] += GATE_SIGMAS**2 * max(var, 0.0)
    # candidate pairs, point by point: counted, then listed (no array grows in a loop)
    n_e = 0
    for b in range(n_b):
        for m in range(n_cone):
            dx = bearings[b, 0] - cam[m, 0]
            dy = bearings[b, 1] - cam[m, 1]
            dz = bearings[b, 2] - cam[m, 2]
            n_e += dx * dx + dy * dy + dz * dz <= radius2[m]
    e_b = np.empty(n_e, dtype=np.int64)
    e_m = np.empty(n_e, dtype=np.int64)
    e_d2 = np.empty(n_e)
    row_deg = np.zeros(n_b, dtype=np.int64)
    col_deg = np.zeros(max(n_cone, 1), dtype=np.int64)
    e = 0
    for b in range(n_b):
        for m in range(n_cone):
            dx = bearings[b, 0] - cam[m, 0]
            dy = bearings[b, 1] - cam[m, 1]
            dz = bearings[b, 2] - cam[m, 2]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 <= radius2[m]:
                e_b[e], e_m[e], e_d2[e] = b, m, d2
                row_deg[b] += 1
                col_deg[m] += 1
                e += 1
    chosen = np.zeros(n_e, dtype=np.bool_)
    group = np.full(n_e, -1, dtype=np.int64)
    for e in range(n_e):
        if row_deg[e_b[e]] == 1 and col_deg[e_m[e]] == 1:
            chosen[e] = True
        elif group[e] < 0:
            # the group of pairs linked to this one through shared points or stars
            members = np.empty(n_e, dtype=np.int64)
            members[0] = e
            group[e] = e
            size, head = 1, 0
            while head < size:
                f = members[head]
                head += 1
                for g in range(n_e):
                    if group[g] < 0 and (e_b[g] == e_b[f] or e_m[g] == e_m[f]):
                        group[g] = e
                        members[size] = g
                        size += 1
            _resolve_group(members[:size], e_b, e_m, e_d2, chosen)
    n = 0
    for e in range(n_e):
        n += chosen[e]
    obs = np.empty(n, dtype=np.int64)
    cat = np.empty(n, dtype=np.int64)
    dist = np.empty(n)
    k = 0
    for e in range(n_e):
        if chosen[e]:
            obs[k], cat[k], dist[k] = e_b[e], work[e_m[e]], math.sqrt(e_d2[e])
            k += 1
    return Pairs(obs, cat, dist, n_cone, 1.0 - math.cos(field_rad))


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


@njit(cache=True)
def _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors, cos_hi, cos_lo, out):
    """The triangles of ``catalog_triangles``: side ij (both ways) joined to the lists of side
    ik at its first star, side jk checked; written to ``out`` as far as it has rows, all
    counted. Returns how many."""
    n = 0
    rows = len(out)
    for k in range(2 * n1):
        if k < n1:
            a, b = np.int64(pair_a[lo1 + k]), np.int64(pair_b[lo1 + k])
        else:
            a, b = np.int64(pair_b[lo1 + k - n1]), np.int64(pair_a[lo1 + k - n1])
        if not (allowed[a] and allowed[b]):
            continue
        m = head[a]
        while m >= 0:
            c = np.int64(pair_b[lo2 + m]) if m < n2 else np.int64(pair_a[lo2 + m - n2])
            m = after[m]
            if b == c:
                continue
            cos_bc = vectors[b, 0] * vectors[c, 0] + vectors[b, 1] * vectors[c, 1]
            cos_bc += vectors[b, 2] * vectors[c, 2]
            if cos_bc >= cos_hi and cos_bc <= cos_lo:
                if n < rows:
                    out[n, 0], out[n, 1], out[n, 2] = a, b, c
                n += 1
    return n


@njit(cache=True)
def catalog_triangles(pair_a, pair_b, pair_angle, vectors, allowed, s_ij, s_ik, s_jk, tol,
                      head, mark):  # fmt: skip
    """Catalog rows (a, b, c), shape (m, 3), of allowed stars whose sides ab, ac, bc are
    within ``tol`` of the measured ij, ik, jk (the pair table sorted by angle). ``head``
    (-1) and ``mark`` (False) per catalog row: work space, left as found."""
    lo1 = np.searchsorted(pair_angle, s_ij - tol)
    hi1 = np.searchsorted(pair_angle, s_ij + tol)
    lo2 = np.searchsorted(pair_angle, s_ik - tol)
    hi2 = np.searchsorted(pair_angle, s_ik + tol)
    n1, n2 = hi1 - lo1, hi2 - lo2
    out = np.empty((0, 3), dtype=np.int64)
    if n1 == 0 or n2 == 0:
        return out
    # only stars that start a side ij can start a triangle: mark them, link side ik's entries
    # (both ways; entry k of the doubled list: pair lo2 + k, reversed for k >= n2) that start
    # at a marked star into a list per star, in the pairs' order
    for k in range(n1):
        mark[pair_a[lo1 + k]] = True
        mark[pair_b[lo1 + k]] = True
    after = np.empty(2 * n2, dtype=np.int64)
    for k in range(2 * n2 - 1, n2 - 1, -1):  # the reversed half, last entry first
        first = pair_b[lo2 + k - n2]
        if mark[first] and allowed[first] and allowed[pair_a[lo2 + k - n2]]:
            after[k] = head[first]
            head[first] = k
    for k in range(n2 - 1, -1, -1):
        first = pair_a[lo2 + k]
        if mark[first] and allowed[first] and allowed[pair_b[lo2 + k]]:
            after[k] = head[first]
            head[first] = k
    cos_hi = math.cos(s_jk + tol)
    cos_lo = math.cos(max(s_jk - tol, 0.0))
    # written as they are found into room for a side's worth (most triangles have far fewer
    # matches than that), joined again into the exact room if they did not fit
    out = np.empty((max(n1, n2), 3), dtype=np.int64)
    counted = _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors,
                    cos_hi, cos_lo, out)  # fmt: skip
    if counted > len(out):
        out = np.empty((counted, 3), dtype=np.int64)
        _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors, cos_hi, cos_lo,
              out)  # fmt: skip
    out = out[:counted]
    for k in range(n1):  # leave the work space as found
        for star in (pair_a[lo1 + k], pair_b[lo1 + k]):
            head[star] = -1
            mark[star] = False
    return out


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


@njit(cache=True)
def prior_mask(bearings, R_prior, match_radius, sigma, sky):
    """The catalog stars a prior attitude allows: within the field plus ``PRIOR_SIGMAS``
    ``sigma`` (rad) of its boresight (a mask over the catalog)."""
    radius = field_radius(bearings, match_radius) + PRIOR_SIGMAS * sigma
    allowed = np.zeros(len(sky[0]), dtype=np.bool_)
    everything = np.ones(len(sky[0]), dtype=np.bool_)
    work = np.empty(len(sky[0]), dtype=np.int64)
    n = cone(R_prior[2].copy(), chord(radius) ** 2, sky, everything, work)
    for k in range(n):
        allowed[work[k]] = True
    return allowed
