"""The false-match probability of a hypothesis (numba kernels): the likelihood ratios of its
points' positions (``star_log_ratios``), their brightness (``brightness_log_ratio``) and a
triangle's sides (``side_log_ratio``), their product against the hypotheses tried
(``false_match``), and the bounds a screen uses (``best_case_false_match``).
Derivation and calibration: docs/verification.md.
"""

from __future__ import annotations

import math

import numpy as np

from starnav.identify.kernels.sky import angle
from starnav.runtime.caching import njit

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
