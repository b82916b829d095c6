"""The one-to-one pairing of bearings with the catalog stars an attitude reprojects near them
(numba kernels): the candidate pairs within the match radius, contested groups resolved by
the most pairs, then the least total squared distance (every subset of a small group; an
exact linear assignment of a larger one, ``assign``).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from starnav.identify.kernels.sky import chord, cone, field_radius
from starnav.runtime.caching import njit

GATE_SIGMAS = 3.0  # a gated catalog star's radius grows by this many sigma of its position
_NO_EDGE = 1e6  # cost of a pair that is not within the radius (chord^2 is at most 4)
SMALL_GROUP = 8  # contested groups of up to this many pairs: every subset tried (2^8)

Pairs = namedtuple("Pairs", "obs cat dist n_cone field_area")


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
