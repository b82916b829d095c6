"""Kernels of the identification stage (numba; plain Python under ``NUMBA_DISABLE_JIT=1``).

Cone searches on the catalog's RA / Dec grid, the one-to-one pairing of bearings with
reprojected catalog stars, the binomial tail of the false-match model, the catalog triangle
join on the pair table, the test of one hypothesis (attitude, agreement, mirror check) and
Mortari's triangle loop over an array of star triples, shared by Pyramid, Triangle and
tracking. Every decision of the verification is written here once; the Python modules
(``verify``, ``pyramid``, ``tracking``, ...) call these kernels.

The sky grid ``sky = (vectors, start, rows, n_dec, n_ra, step_rad)``: cell ``i * n_ra + j``
(Dec band i from the south pole, RA column j) holds catalog rows ``rows[start[c]:start[c+1]]``
(``identify.database.sky_grid``). Searches see only the rows where ``allowed`` is True
(tracking: the stars near the prior).
"""

from __future__ import annotations

import math
import time
from collections import namedtuple

import numpy as np
from numba import njit, objmode

from starnav.attitude.rotation import det3, wahba

# outcomes of a hypothesis test and of a search
REJECTED, FOUND, AMBIGUOUS, NOT_FOUND, OUT_OF_TIME = 0, 1, 2, 3, 4
FLAT_FACTOR = 3.0  # a triangle is too flat to give its orientation below 3 tol x its longest side
GATE_SIGMAS = 3.0  # a gated catalog star's radius grows by this many sigma of its position
PRIOR_SIGMAS = 3.0  # tracking allows the catalog stars within the field plus this many sigma
_NO_EDGE = 1e6  # cost of a pair that is not within the radius (chord^2 is at most 4)
SMALL_GROUP = 8  # contested groups of up to this many pairs: every subset tried (2^8)

Pairs = namedtuple("Pairs", "obs cat dist n_cone field_area")
Tested = namedtuple("Tested", "status obs cat R p")
Search = namedtuple("Search", "status obs cat R parity p hypotheses proposed best_p")


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
WIDE_SCREEN_RAD = math.radians(35.0)  # wider fields screen hypotheses star by star
CLOCK_EVERY = 32  # with a time budget, the clock is read every this many hypotheses


@njit(cache=True, inline="always")
def _within(vectors, r, axis, chord2):
    """Whether row ``r`` of ``vectors`` is within chord sqrt(chord2) of ``axis``."""
    dx = vectors[r, 0] - axis[0]
    dy = vectors[r, 1] - axis[1]
    dz = vectors[r, 2] - axis[2]
    return dx * dx + dy * dy + dz * dz <= chord2


@njit(cache=True)
def cone(axis, chord2, sky, allowed, out):
    """Allowed rows of the sky's vectors within chord sqrt(chord2) of ``axis``, written to
    ``out``; returns how many."""
    vectors, start, rows, n_dec, n_ra, step = sky
    n = 0
    radius = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(chord2))) + 1e-9
    if radius > WIDE_CONE_RAD:  # a wide field's cone: every row beats visiting the cells
        for r in range(len(vectors)):
            if allowed[r] and _within(vectors, r, axis, chord2):
                out[n] = r
                n += 1
        return n
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
    for i in range(i_lo, i_hi + 1):
        for jj in range(j_lo, j_hi + 1):
            cell = i * n_ra + jj % n_ra
            for m in range(start[cell], start[cell + 1]):
                r = rows[m]
                if allowed[r] and _within(vectors, r, axis, chord2):
                    out[n] = r
                    n += 1
    return n


@njit(cache=True)
def binomial_tail(trials, extra, p):
    """P(X >= extra), X ~ Binomial(trials, p) (= scipy's betainc(extra, trials-extra+1, p))."""
    if p >= 1.0:
        return 1.0
    if p <= 0.0:
        return 0.0
    lp, lq = math.log(p), math.log1p(-p)
    top = math.lgamma(trials + 1.0)
    s = 0.0
    for j in range(extra, trials + 1):
        s += math.exp(
            top - math.lgamma(j + 1.0) - math.lgamma(trials - j + 1.0) + j * lp + (trials - j) * lq
        )
    return min(1.0, s)


@njit(cache=True)
def false_match(n_stars, n_agree, n_used, p_chance, hypotheses):
    """Chance that a wrong hypothesis makes ``n_agree`` of ``n_stars`` agree: ``n_used``
    built it, each of the others agrees by chance with probability ``p_chance``; times the
    ``hypotheses`` tried (Bonferroni)."""
    trials = n_stars - n_used
    extra = n_agree - n_used
    if extra <= 0 or trials <= 0:
        return 1.0
    return min(1.0, binomial_tail(trials, extra, p_chance) * max(hypotheses, 1))


@njit(cache=True)
def p_chance(n_cone, field_area, radius):
    """Chance that a random point lands within ``radius`` (rad) of one of ``n_cone`` catalog
    stars spread over a field cone whose ``1 - cos(half-angle)`` is ``field_area``."""
    if field_area <= 0:
        return 1.0
    return min(1.0, n_cone * (1.0 - math.cos(radius)) / field_area)


@njit(cache=True)
def false_match_radii(dist, n_cone, field_area, n_stars, n_used, hypotheses, radii):
    """The false-match probability at each match radius (stars with chord ``dist`` within
    it agree; chance per star n_cone (1 - cos r) / field_area), the best one times the
    number of radii (Bonferroni again)."""
    best = 1.0
    for radius in radii:
        limit = chord(radius) * (1 + 1e-12)
        n_agree = 0
        for d in dist:
            if d <= limit:
                n_agree += 1
        chance = p_chance(n_cone, field_area, radius)
        best = min(best, false_match(n_stars, n_agree, n_used, chance, hypotheses))
    return min(1.0, best * len(radii))


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
def test_hypothesis(bearings, obs_rows, cat_rows, parity, sky, allowed, radii, hypotheses,
                    max_p, parity_known, work):  # fmt: skip
    """Verify one hypothesis (bearing rows paired with catalog rows, with a parity): its
    attitude (Wahba), the agreeing stars of the whole field, the false-match probability
    over ``hypotheses``; accepted (``FOUND``) below ``max_p`` unless the parity is unknown
    (``parity_known`` 0) and the mirror image verifies too (``AMBIGUOUS``: collinear stars)."""
    vectors = sky[0]
    no_cov = np.zeros((3, 3))
    radius = radii.max()
    n_used = len(obs_rows)
    R = wahba(bearings[obs_rows], vectors[cat_rows], np.ones(n_used), parity)
    v = pair_catalog(bearings, R, sky, allowed, radius, no_cov, False, work)
    p = false_match_radii(v.dist, v.n_cone, v.field_area, len(bearings), n_used, hypotheses, radii)
    if p > max_p:
        return Tested(REJECTED, v.obs, v.cat, R, p)
    if parity_known == 0:
        R_m = wahba(bearings[v.obs], vectors[v.cat], np.ones(len(v.obs)), -parity)
        m = pair_catalog(bearings, R_m, sky, allowed, radius, no_cov, False, work)
        p_m = false_match_radii(m.dist, m.n_cone, m.field_area, len(bearings), n_used,
                                hypotheses, radii)  # fmt: skip
        if p_m <= max_p:
            return Tested(AMBIGUOUS, v.obs, v.cat, R, p)
    return Tested(FOUND, v.obs, v.cat, R, p)


@njit(cache=True)
def _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors, cos_hi, cos_lo, out):
    """The triangles of ``catalog_triangles``: side ij (both ways) joined to the lists of side
    ik at its first star, side jk checked; written to ``out`` unless it has no rows (then
    only counted). Returns how many."""
    n = 0
    fill = len(out) > 0
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
                if fill:
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
    counted = _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors,
                    cos_hi, cos_lo, np.empty((0, 3), dtype=np.int64))  # fmt: skip
    out = np.empty((counted, 3), dtype=np.int64)
    _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors, cos_hi, cos_lo, out)
    for k in range(n1):  # leave the work space as found
        for star in (pair_a[lo1 + k], pair_b[lo1 + k]):
            head[star] = -1
            mark[star] = False
    return out


@njit(cache=True)
def _screen(bearings, tri, triples, parities, sky, allowed, field_rad, screen2, work, cam,
            end_time):  # fmt: skip
    """Per hypothesis, how many bearings land near some catalog star under its attitude (a
    quick count that may only err high); stops early (the rest counted 0) after
    ``end_time`` (``clock`` seconds)."""
    vectors = sky[0]
    m = len(triples)
    agree = np.zeros(m, dtype=np.int64)
    ones = np.ones(3)
    sky_b = np.empty(3)
    for h in range(m):
        if h % CLOCK_EVERY == CLOCK_EVERY - 1 and end_time < math.inf and clock() > end_time:
            break
        R = wahba(tri, vectors[triples[h]], ones, parities[h])
        if field_rad > WIDE_SCREEN_RAD:  # a wide field: look up each bearing's own cells
            for b in range(len(bearings)):
                for k in range(3):
                    sky_b[k] = (
                        R[0, k] * bearings[b, 0]
                        + R[1, k] * bearings[b, 1]
                        + R[2, k] * bearings[b, 2]
                    )
                agree[h] += cone(sky_b, screen2, sky, allowed, work) > 0
            continue
        n_cone = cone(R[2], chord(field_rad) ** 2, sky, allowed, work)
        for c in range(n_cone):
            row = work[c]
            v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
            for k in range(3):
                cam[c, k] = R[k, 0] * v0 + R[k, 1] * v1 + R[k, 2] * v2
        for b in range(len(bearings)):
            for c in range(n_cone):
                dx = bearings[b, 0] - cam[c, 0]
                if dx * dx >= screen2:
                    continue
                dy = bearings[b, 1] - cam[c, 1]
                dz = bearings[b, 2] - cam[c, 2]
                if dx * dx + dy * dy + dz * dz < screen2:
                    agree[h] += 1
                    break
    return agree


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
def triangle_search(bearings, triangles, pair_a, pair_b, pair_angle, max_angle, sky, allowed,
                    tol, radii, max_p, parity_known, max_hypotheses, end_time):  # fmt: skip
    """Try the measured ``triangles`` (rows of ``bearings``, (t, 3)) in order: look up the
    catalog triangles of each, screen all their hypotheses, verify the best (by the screen)
    until one is accepted, nothing left can be, ``max_hypotheses`` are spent or the
    ``clock`` passes ``end_time`` (s; looked at for every triangle and every ``CLOCK_EVERY``
    hypotheses screened or verified; status ``OUT_OF_TIME``)."""
    vectors = sky[0]
    n_total = len(bearings)
    radius = radii.max()
    field_rad = field_radius(bearings, radius)
    # the smallest chance agreement per star any hypothesis can have (a field holding one
    # catalog star): a screen count that cannot beat the threshold even so is not verified
    p_floor = (1.0 - math.cos(radii.min())) / (1.0 - math.cos(field_rad))
    screen2 = chord(radius) ** 2
    work = np.empty(len(vectors), dtype=np.int64)
    head = np.full(len(vectors), -1, dtype=np.int64)
    mark = np.zeros(len(vectors), dtype=np.bool_)
    cam = np.empty((len(vectors), 3))
    hypotheses, proposed, best_p = 0, 0, 1.0
    empty = np.empty(0, dtype=np.int64)
    tri = np.empty((3, 3))
    timed = end_time < math.inf
    status = NOT_FOUND
    for t in range(len(triangles)):
        if timed and clock() > end_time:
            status = OUT_OF_TIME
            break
        idx = triangles[t]
        for k in range(3):
            tri[k] = bearings[idx[k]]
        s01, s02, s12 = angle(tri[0], tri[1]), angle(tri[0], tri[2]), angle(tri[1], tri[2])
        longest = max(s01, s02, s12)
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
        agree = _screen(bearings, tri, triples, parities, sky, allowed, field_rad, screen2,
                        work, cam, end_time)  # fmt: skip
        if timed and clock() > end_time:
            status = OUT_OF_TIME
            break
        for h in np.argsort(-agree, kind="mergesort"):
            p_best = len(radii) * false_match(n_total, agree[h], 3, p_floor, hypotheses)
            if p_best > max_p:
                break  # neither this nor any later (lower) count can be convincing
            if timed and proposed % CLOCK_EVERY == CLOCK_EVERY - 1 and clock() > end_time:
                status = OUT_OF_TIME
                break
            proposed += 1
            r = test_hypothesis(bearings, idx, triples[h], parities[h], sky, allowed, radii,
                                hypotheses, max_p, parity_known, work)  # fmt: skip
            best_p = min(best_p, r.p)
            if r.status != REJECTED:
                return Search(r.status, r.obs, r.cat, r.R, parities[h], r.p, hypotheses,
                              proposed, best_p)  # fmt: skip
        if status == OUT_OF_TIME or hypotheses >= max_hypotheses:
            break
    return Search(status, empty, empty, np.zeros((3, 3)), 0, 1.0, hypotheses, proposed, best_p)


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
