"""The compiled solve path (numba): the default ``solve()`` in two machine-code calls.

Pyramid identification on the pair database (``identify.pyramid``), tracking near a prior
(``identify.tracking``), the whole-field verification (``identify.verify``) and the attitude
fit with its outlier, rematch and refusal steps (``api.conclude``), for a pinhole camera of
known focal length, written as loops that numba compiles. The numpy path makes hundreds of
small array calls per frame, each a few microseconds of interpreter and dispatch; here they
are one call for the identification and one for the fit.

It makes the same decisions as the numpy path: the same triangles in the same order, the same
hypotheses, false-match probabilities, fit steps and refusals (``tests/test_compiled.py``
solves frames both ways and compares). Where the numpy path would do something this does not
- a one-to-one pairing among more than ``_MAX_GROUP_EDGES`` candidate pairs linked through
shared points or stars, or Levenberg-Marquardt because Gauss-Newton did not converge - it
returns None ("defer") and the caller hands the frame to the numpy path. Cone searches use a
1° RA / Dec grid of the catalog instead of the KD-tree.

Numba caches the machine code beside this file (or in numba's user-wide cache directory when
that is read-only): compiled once per installation, in ~30 s on 2 cores, loaded in ~0.1-0.3 s
by each process afterwards.
"""

from __future__ import annotations

import math
import sys
import threading
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numba import njit

# the numpy path's constants, taken from it so that the two paths cannot drift apart
from starnav.api import (
    _MAX_REMATCH,
    _MIN_FIT_STARS,
    _MIN_STARS_SCALE_CHECK,
    _OUTLIER_ALPHA,
    _SCALE_TOLERANCE,
)
from starnav.attitude.refine import _MAX_STEPS, _STEP_TOL_RAD
from starnav.geometry import ARCSEC_PER_RAD
from starnav.identify.base import Identification, IdentifyOutcome, MatchSettings
from starnav.identify.database import PairDatabase
from starnav.identify.pyramid import NO_TRIANGLE
from starnav.identify.verify import not_found_reason

GRID_STEP_DEG = 1.0
_MAX_GROUP_EDGES = 12  # candidate pairs of one group resolved here (2^12 subsets)

# status codes of the kernels
NOT_FOUND, FOUND, AMBIGUOUS, DEFER = 0, 1, 2, 3
# refusal codes of the fit
ACCEPTED, WRONG_SCALE, UNCONVINCING, TOO_FEW = 0, 1, 2, 3


@dataclass(frozen=True, eq=False)
class Sky:
    """A catalog's unit vectors and their RA / Dec grid: cell ``i * n_ra + j`` (Dec band i
    from the south pole, RA column j) holds catalog rows ``rows[start[c]:start[c + 1]]``.
    Searches see only the rows where ``allowed`` is True (tracking: the stars near the
    prior)."""

    vectors: np.ndarray
    start: np.ndarray
    rows: np.ndarray
    n_dec: int
    n_ra: int
    step_rad: float
    allowed: np.ndarray

    def args(self) -> tuple:
        """The tuple the kernels take."""
        return (
            self.vectors,
            self.start,
            self.rows,
            self.n_dec,
            self.n_ra,
            self.step_rad,
            self.allowed,
        )


def sky_grid(vectors: np.ndarray, step_deg: float = GRID_STEP_DEG) -> Sky:
    """The RA / Dec grid of unit ``vectors`` (n, 3) with cells of ``step_deg``."""
    vectors = np.ascontiguousarray(vectors, dtype=np.float64)
    step = math.radians(step_deg)
    n_dec, n_ra = round(180.0 / step_deg), round(360.0 / step_deg)
    dec = np.arcsin(np.clip(vectors[:, 2], -1.0, 1.0))
    ra = np.arctan2(vectors[:, 1], vectors[:, 0]) % (2.0 * np.pi)
    i = np.clip(np.floor((dec + 0.5 * np.pi) / step).astype(np.int64), 0, n_dec - 1)
    j = np.clip(np.floor(ra / step).astype(np.int64), 0, n_ra - 1)
    cell = i * n_ra + j
    rows = np.argsort(cell, kind="stable").astype(np.int64)
    start = np.searchsorted(cell[rows], np.arange(n_dec * n_ra + 1)).astype(np.int64)
    return Sky(vectors, start, rows, n_dec, n_ra, step, np.ones(len(vectors), dtype=np.bool_))


_SKIES: weakref.WeakKeyDictionary[PairDatabase, Sky] = weakref.WeakKeyDictionary()


def database_sky(database: PairDatabase) -> Sky:
    """The grid of a database's catalog (built once per database, ~2 ms for 5000 stars)."""
    sky = _SKIES.get(database)
    if sky is None:
        sky = _SKIES[database] = sky_grid(database.catalog.vectors)
    return sky


# ---------------------------------------------------------------------------- small kernels


@njit(cache=True)
def _chord(angle):
    return 2.0 * math.sin(0.5 * angle)


@njit(cache=True)
def _angle(a, b):
    """Angle (rad) between unit vectors, as geometry.angle_between."""
    d = 0.0
    s = 0.0
    for k in range(3):
        d += (a[k] - b[k]) ** 2
        s += (a[k] + b[k]) ** 2
    return 2.0 * math.atan2(math.sqrt(d), math.sqrt(s))


@njit(cache=True)
def _cone(axis, chord2, sky, out):
    """Allowed rows of the sky's vectors within chord sqrt(chord2) of ``axis``, written to
    ``out``; returns how many."""
    vectors, start, rows, n_dec, n_ra, step, allowed = sky
    n = 0
    radius = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(chord2))) + 1e-9
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
                if not allowed[r]:
                    continue
                dx = vectors[r, 0] - axis[0]
                dy = vectors[r, 1] - axis[1]
                dz = vectors[r, 2] - axis[2]
                if dx * dx + dy * dy + dz * dz <= chord2:
                    out[n] = r
                    n += 1
    return n


@njit(cache=True)
def _binomial_tail(trials, extra, p):
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
def _false_match(n_stars, n_agree, n_used, p_chance, hypotheses):
    """As verify.false_match_probability."""
    trials = n_stars - n_used
    extra = n_agree - n_used
    if extra <= 0 or trials <= 0:
        return 1.0
    return min(1.0, _binomial_tail(trials, extra, p_chance) * max(hypotheses, 1))


@njit(cache=True)
def _false_match_radii(dist, n_cone, field_area, n_stars, n_used, hypotheses, radii):
    """As Verification.false_match_probability: best over the radii, times their number."""
    best = 1.0
    for radius in radii:
        limit = _chord(radius) * (1 + 1e-12)
        n_agree = 0
        for d in dist:
            if d <= limit:
                n_agree += 1
        p_chance = 1.0
        if field_area > 0:
            p_chance = min(1.0, n_cone * (1.0 - math.cos(radius)) / field_area)
        best = min(best, _false_match(n_stars, n_agree, n_used, p_chance, hypotheses))
    return min(1.0, best * len(radii))


@njit(cache=True)
def _field_radius(bearings, radius):
    zmin = 1.0
    for n in range(len(bearings)):
        zmin = min(zmin, bearings[n, 2])
    return math.acos(max(-1.0, min(1.0, zmin))) + radius


@njit(cache=True)
def _det3(a, b, c):
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


@njit(cache=True)
def _wahba(b, r, parity):
    """As attitude.wahba: R_cam_from_icrs of pairs (b camera, r ICRS), mirrored for parity -1."""
    B = np.zeros((3, 3))
    for k in range(len(b)):
        for i in range(3):
            bi = -b[k, i] if (parity < 0 and i == 1) else b[k, i]
            for j in range(3):
                B[i, j] += bi * r[k, j]
    R = _nearest_rotation(B)
    if parity < 0:
        for j in range(3):
            R[1, j] = -R[1, j]
    return R


@njit(cache=True)
def _nearest_rotation(B):
    """The rotation nearest to B (3x3): U diag(1, 1, det(U V^T)) V^T of B's SVD. With
    det(B) clearly positive it is B's orthogonal polar factor, found by Newton's iteration
    X <- (g X + X^-T / g) / 2 (Higham; a few 3x3 inverses instead of an SVD); otherwise,
    or if that does not settle to 1e-15, by LAPACK's SVD."""
    scale = math.sqrt(np.sum(B * B))
    det = _det3(B[0], B[1], B[2])
    if scale > 0.0 and det > 1e-12 * scale**3:
        X = B / scale
        for _ in range(30):
            # X^-T: the cofactor matrix over the determinant
            d = _det3(X[0], X[1], X[2])
            C = np.empty((3, 3))
            for i in range(3):
                i1, i2 = (i + 1) % 3, (i + 2) % 3
                for j in range(3):
                    j1, j2 = (j + 1) % 3, (j + 2) % 3
                    C[i, j] = (X[i1, j1] * X[i2, j2] - X[i1, j2] * X[i2, j1]) / d
            g = (abs(d) ** (-1.0 / 3.0)) if abs(d) > 0 else 1.0  # determinant scaling
            Y = 0.5 * (g * X + C / g)
            change = np.max(np.abs(Y - X))
            X = Y
            if change < 1e-15:
                return X
    U, _, Vt = np.linalg.svd(B)
    d = _det3(U[:, 0], U[:, 1], U[:, 2]) * _det3(Vt[0], Vt[1], Vt[2])
    for i in range(3):
        U[i, 2] *= d
    return U @ Vt


@njit(cache=True)
def _match(bearings, R, sky, radius, cov, gate, field_rad, work):
    """As verify.match_catalog: (obs, cat rows, chord distances, n_cone, deferred). With
    ``gate``, each star's radius grows by 3 sigma of its position under the rotation
    covariance ``cov``. The one-to-one pairing is scipy's: most pairs in each group of points
    and stars that share candidates, then the least total squared distance; a group of more
    than ``_MAX_GROUP_EDGES`` candidate pairs is left to the numpy path (``deferred``)."""
    vectors = sky[0]
    n_cone = _cone(R[2], _chord(field_rad) ** 2, sky, work)
    n_b = len(bearings)
    base2 = _chord(radius) ** 2
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
            radius2[m] += 9.0 * max(var, 0.0)
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
    deferred = False
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
            if size > _MAX_GROUP_EDGES:
                deferred = True
                continue
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
                if (best_mask >> x) & 1:
                    chosen[members[x]] = True
    n = 0
    for e in range(n_e):
        n += chosen[e]
    obs = np.empty(n, dtype=np.int64)
    cat = np.empty(n, dtype=np.int64)
    dist = np.empty(n)
    k = 0
    for e in range(n_e):  # in order of the points, as scipy's assignment returns them
        if chosen[e]:
            obs[k], cat[k], dist[k] = e_b[e], work[e_m[e]], math.sqrt(e_d2[e])
            k += 1
    return obs, cat, dist, n_cone, deferred


# ---------------------------------------------------------------------------- identification


@njit(cache=True)
def _join(pair_a, pair_b, lo1, n1, lo2, n2, head, after, allowed, vectors, cos_hi, cos_lo, out):
    """The triangles of _catalog_triangles: side ij (both ways) joined to the lists of side ik
    at its first star, side jk checked; written to ``out`` unless it has no rows (then only
    counted). Returns how many."""
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
def _catalog_triangles(
    pair_a, pair_b, pair_angle, vectors, allowed, s_ij, s_ik, s_jk, tol, head, mark
):
    """As pyramid.catalog_triangles, in the same order: rows (a, b, c) with sides ab, ac, bc
    within ``tol`` of the measured ij, ik, jk, of allowed stars only. ``head`` (-1) and
    ``mark`` (False) per catalog row: work space, left as found."""
    lo1 = np.searchsorted(pair_angle, s_ij - tol)
    hi1 = np.searchsorted(pair_angle, s_ij + tol)
    lo2 = np.searchsorted(pair_angle, s_ik - tol)
    hi2 = np.searchsorted(pair_angle, s_ik + tol)
    n1, n2 = hi1 - lo1, hi2 - lo2
    out = np.empty((0, 3), dtype=np.int64)
    if n1 == 0 or n2 == 0:
        return out
    # side ik both ways, as a list per first star in the order of the pairs (entry k of the
    # doubled list: pair lo2 + k, then reversed for k >= n2)
    # only stars that start a side ij can start a triangle: mark them, link side ik's entries
    # (both ways) that start at a marked star into a list per star, in the pairs' order
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
def _identify(bearings, order, pair_a, pair_b, pair_angle, max_angle, sky, tol, radii, max_p,
              parity_known, max_hypotheses):  # fmt: skip
    """As pyramid.match_triangles over Mortari's triangle order of ``order``. Returns
    (status, obs, cat, R, parity, p, hypotheses, proposed, best_p)."""
    vectors = sky[0]
    n_total = len(bearings)
    radius = radii.max()
    field_rad = _field_radius(bearings, radius)
    p_floor = (1.0 - math.cos(radii.min())) / (1.0 - math.cos(field_rad))
    n_radii = len(radii)
    screen2 = _chord(radius) ** 2
    work = np.empty(len(vectors), dtype=np.int64)
    head = np.full(len(vectors), -1, dtype=np.int64)
    mark = np.zeros(len(vectors), dtype=np.bool_)
    cam = np.empty((len(vectors), 3))  # cone stars in the camera frame of a hypothesis
    no_cov = np.zeros((3, 3))
    hypotheses, proposed, best_p = 0, 0, 1.0
    empty = np.empty(0, dtype=np.int64)
    R_none = np.zeros((3, 3))
    n = len(order)
    tri = np.empty((3, 3))
    idx = np.empty(3, dtype=np.int64)
    for dj in range(1, n - 1):
        for dk in range(1, n - dj):
            for i in range(n - dj - dk):
                idx[0], idx[1], idx[2] = order[i], order[i + dj], order[i + dj + dk]
                for k in range(3):
                    tri[k] = bearings[idx[k]]
                s01 = _angle(tri[0], tri[1])
                s02 = _angle(tri[0], tri[2])
                s12 = _angle(tri[1], tri[2])
                if min(s01, s02, s12) < 2.0 * tol or max(s01, s02, s12) > max_angle + tol:
                    continue
                triples = _catalog_triangles(
                    pair_a, pair_b, pair_angle, vectors, sky[6], s01, s02, s12, tol, head, mark
                )
                m = len(triples)
                if m == 0:
                    continue
                det_obs = _det3(tri[0], tri[1], tri[2])
                parities = np.empty(m, dtype=np.int64)
                for h in range(m):
                    det_cat = _det3(
                        vectors[triples[h, 0]], vectors[triples[h, 1]], vectors[triples[h, 2]]
                    )
                    parities[h] = 1 if np.sign(det_obs) == np.sign(det_cat) else -1
                if abs(det_obs) < 3.0 * tol * max(s01, s02, s12):  # too flat to tell
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
                m = len(triples)
                if m == 0:
                    continue
                hypotheses += m
                # screen: points near some catalog star under each hypothesis's attitude
                agree = np.zeros(m, dtype=np.int64)
                Rs = np.empty((m, 3, 3))
                for h in range(m):
                    R = _wahba(tri, vectors[triples[h]], parities[h])
                    Rs[h] = R
                    n_cone = _cone(R[2], _chord(field_rad) ** 2, sky, work)
                    for c in range(n_cone):
                        row = work[c]
                        v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
                        for k in range(3):
                            cam[c, k] = R[k, 0] * v0 + R[k, 1] * v1 + R[k, 2] * v2
                    for b in range(n_total):
                        for c in range(n_cone):
                            dx = bearings[b, 0] - cam[c, 0]
                            if dx * dx >= screen2:
                                continue
                            dy = bearings[b, 1] - cam[c, 1]
                            dz = bearings[b, 2] - cam[c, 2]
                            if dx * dx + dy * dy + dz * dz < screen2:
                                agree[h] += 1
                                break
                for h in np.argsort(-agree, kind="mergesort"):
                    p_best = n_radii * _false_match(n_total, agree[h], 3, p_floor, hypotheses)
                    if p_best > max_p:
                        break
                    proposed += 1
                    R = Rs[h]
                    obs, cat, dist, n_cone, deferred = _match(
                        bearings, R, sky, radius, no_cov, False, field_rad, work
                    )
                    if deferred:
                        return DEFER, empty, empty, R_none, 0, 1.0, hypotheses, proposed, best_p
                    area = 1.0 - math.cos(field_rad)
                    p = _false_match_radii(dist, n_cone, area, n_total, 3, hypotheses, radii)
                    best_p = min(best_p, p)
                    if p > max_p:
                        continue
                    parity = parities[h]
                    if parity_known == 0:
                        # collinear stars verify in the mirror image as well
                        R_m = _wahba(bearings[obs], vectors[cat], -parity)
                        _, _, dist_m, n_cone_m, deferred = _match(
                            bearings, R_m, sky, radius, no_cov, False, field_rad, work
                        )
                        if deferred:
                            return (DEFER, empty, empty, R_none, 0, 1.0, hypotheses, proposed,
                                    best_p)  # fmt: skip
                        p_m = _false_match_radii(
                            dist_m, n_cone_m, area, n_total, 3, hypotheses, radii
                        )
                        if p_m <= max_p:
                            return (AMBIGUOUS, empty, empty, R_none, 0, 1.0, hypotheses,
                                    proposed, best_p)  # fmt: skip
                    return FOUND, obs, cat, R, parity, p, hypotheses, proposed, best_p
                if hypotheses >= max_hypotheses:
                    return NOT_FOUND, empty, empty, R_none, 0, 1.0, hypotheses, proposed, best_p
    return NOT_FOUND, empty, empty, R_none, 0, 1.0, hypotheses, proposed, best_p


@njit(cache=True)
def _cone_rows(axis, radius, sky):
    """Rows of the sky's vectors within ``radius`` (rad) of ``axis``."""
    work = np.empty(len(sky[0]), dtype=np.int64)
    n = _cone(axis, _chord(radius) ** 2, sky, work)
    return work[:n].copy()


@njit(cache=True)
def _prior_stars(bearings, R_prior, match_radius, sigma, sky):
    """As identify.tracking: the catalog stars within the field plus 3 ``sigma`` of the prior
    boresight (a mask over the catalog), and the prior's parity."""
    radius = _field_radius(bearings, match_radius) + 3.0 * sigma
    allowed = np.zeros(len(sky[0]), dtype=np.bool_)
    allowed[_cone_rows(R_prior[2].copy(), radius, sky)] = True
    parity = 1 if _det3(R_prior[0], R_prior[1], R_prior[2]) > 0 else -1
    return allowed, parity


# ---------------------------------------------------------------------------- attitude fit


@njit(cache=True)
def _rotate_by(omega, R0):
    """As attitude.refine.rotate_by: exp([omega]x) @ R0."""
    angle = math.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    if angle < 1e-300:
        return R0.copy()
    k0, k1, k2 = omega[0] / angle, omega[1] / angle, omega[2] / angle
    K = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    return (np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)) @ R0


@njit(cache=True)
def _residuals_jacobian(R, icrs, xy, focal, cx, cy, with_focal):
    """As refine._residuals_and_jacobian at omega = 0 (no distortion): residuals (2n,) u then
    v, Jacobian (2n, 3 or 4)."""
    n = len(xy)
    n_par = 4 if with_focal else 3
    res = np.empty(2 * n)
    J = np.empty((2 * n, n_par))
    for s in range(n):
        c0 = R[0, 0] * icrs[s, 0] + R[0, 1] * icrs[s, 1] + R[0, 2] * icrs[s, 2]
        c1 = R[1, 0] * icrs[s, 0] + R[1, 1] * icrs[s, 1] + R[1, 2] * icrs[s, 2]
        c2 = R[2, 0] * icrs[s, 0] + R[2, 1] * icrs[s, 1] + R[2, 2] * icrs[s, 2]
        u, v = c0 / c2, c1 / c2
        res[s] = cx + focal * u - xy[s, 0]
        res[n + s] = cy + focal * v - xy[s, 1]
        uv = u * v
        J[s, 0], J[s, 1], J[s, 2] = -focal * uv, focal * (1.0 + u * u), -focal * v
        J[n + s, 0], J[n + s, 1], J[n + s, 2] = -focal * (1.0 + v * v), focal * uv, focal * u
        if with_focal:
            J[s, 3], J[n + s, 3] = focal * u, focal * v
    return res, J


@njit(cache=True)
def _cholesky(N):
    """Lower-triangular L with L L^T = N (a few parameters), and whether N was positive
    definite."""
    p = len(N)
    L = np.zeros((p, p))
    for i in range(p):
        for j in range(i + 1):
            s = N[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return L, False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return L, True


@njit(cache=True)
def _cholesky_solve(L, g):
    """x with L L^T x = g."""
    p = len(g)
    y = np.empty(p)
    for i in range(p):
        s = g[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.empty(p)
    for i in range(p - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, p):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x


@njit(cache=True)
def _normal_step(J, res):
    """The least-squares step -(J^T J)^-1 J^T res (3 or 4 parameters), and whether J^T J was
    positive definite."""
    L, definite = _cholesky(J.T @ J)
    if not definite:
        return np.zeros(J.shape[1]), False
    return _cholesky_solve(L, -(J.T @ res)), True


@njit(cache=True)
def _fit(R0, icrs, xy, focal0, cx, cy, fit_focal):
    """As refine.refine_attitude (no distortion; the focal length free when ``fit_focal`` and
    there are 4 stars). Returns (ok, R, residuals (n, 2), rotation covariance, variance_px2,
    leverage (n, 2, 2), rms, sigma boresight / roll arcsec, focal, sigma focal px); ok False
    where the numpy path would turn to Levenberg-Marquardt."""
    n = len(xy)
    free = fit_focal and n >= 4
    n_par = 4 if free else 3
    R = R0.copy()
    focal = focal0
    cost0 = -1.0
    for _ in range(_MAX_STEPS):
        res, J = _residuals_jacobian(R, icrs, xy, focal, cx, cy, free)
        if cost0 < 0:
            cost0 = res @ res
        step, definite = _normal_step(J, res)
        if not definite:
            break
        R = _rotate_by(step[:3], R)
        if free:
            focal = focal * math.exp(step[3])
        if np.max(np.abs(step)) < _STEP_TOL_RAD:
            break
    res, J = _residuals_jacobian(R, icrs, xy, focal, cx, cy, free)
    cost = res @ res
    ok = np.all(np.isfinite(res)) and cost <= cost0
    L, definite = _cholesky(J.T @ J)
    ok = ok and definite
    residuals = np.empty((n, 2))
    residuals[:, 0] = res[:n]
    residuals[:, 1] = res[n:]
    leverage = np.zeros((n, 2, 2))
    if not ok:
        return (False, R, residuals, np.zeros((3, 3)), 0.0, leverage, 0.0, 0.0, 0.0, focal,
                0.0)  # fmt: skip
    s2 = cost / max(2 * n - n_par, 1)
    N_inv = np.empty((n_par, n_par))
    for i in range(n_par):
        unit = np.zeros(n_par)
        unit[i] = 1.0
        N_inv[:, i] = _cholesky_solve(L, unit)
    cov = s2 * N_inv
    for s in range(n):
        for i in range(2):
            row_i = J[s + i * n]
            for j in range(2):
                row_j = J[s + j * n]
                leverage[s, i, j] = row_i @ N_inv @ row_j
    rms = math.sqrt(cost / n)
    sigma_b = math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)) * ARCSEC_PER_RAD
    sigma_r = math.sqrt(max(cov[2, 2], 0.0)) * ARCSEC_PER_RAD
    sigma_f = focal * math.sqrt(max(cov[3, 3], 0.0)) if free else 0.0
    return (True, R, residuals, cov[:3, :3].copy(), s2, leverage, rms, sigma_b, sigma_r, focal,
            sigma_f)  # fmt: skip


@njit(cache=True)
def _studentized(residuals, leverage, sigma_px):
    """As Refinement.studentized."""
    n = len(residuals)
    t = np.zeros(n)
    for s in range(n):
        a = 1.0 + 1e-9 - leverage[s, 0, 0]
        b = -leverage[s, 0, 1]
        c = -leverage[s, 1, 0]
        d = 1.0 + 1e-9 - leverage[s, 1, 1]
        if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(c) and np.isfinite(d)):
            return np.zeros(n)
        det = a * d - b * c
        x, y = residuals[s, 0], residuals[s, 1]
        # r^T inv(spread) r with inv = [[d, -b], [-c, a]] / det
        t[s] = (x * (d * x - b * y) + y * (-c * x + a * y)) / det / sigma_px**2
    return t


@njit(cache=True)
def _bearings(xy, focal, cx, cy):
    """As Camera.pixels_to_bearings (no distortion)."""
    out = np.empty((len(xy), 3))
    for s in range(len(xy)):
        u, v = (xy[s, 0] - cx) / focal, (xy[s, 1] - cy) / focal
        norm = math.sqrt(u * u + v * v + 1.0)
        out[s, 0], out[s, 1], out[s, 2] = u / norm, v / norm, 1.0 / norm
    return out


@njit(cache=True)
def _converge(obs, cat, R, xy, sky, focal, cx, cy, fit_focal, radius, sigma_px, work):
    """As api._Fitter.converge: fit, drop outliers, rematch until the pairs stop changing (each
    fit starts from the focal length given; each match takes the points' bearings from the
    fit's). Returns (ok, obs, cat, fit tuple, n_cone and field radius of the last match)."""
    vectors = sky[0]
    fit = _fit(R, vectors[cat], xy[obs], focal, cx, cy, fit_focal)
    n_cone_last, field_last = 0, 0.0
    if not fit[0]:
        return False, obs, cat, fit, n_cone_last, field_last
    ok, obs, cat, fit = _drop_outliers(obs, cat, fit, xy, vectors, focal, cx, cy, fit_focal,
                                       sigma_px)  # fmt: skip
    if not ok:
        return False, obs, cat, fit, n_cone_last, field_last
    for _ in range(_MAX_REMATCH):
        s2 = fit[4]
        scale = max(1.0, sigma_px**2 / s2) if s2 > 0 else 1.0
        cov = fit[3] * scale
        bearings = _bearings(xy, fit[9], cx, cy)
        field_last = _field_radius(bearings, radius)
        v_obs, v_cat, _, n_cone_last, deferred = _match(
            bearings, fit[1], sky, radius, cov, True, field_last, work
        )
        if deferred:
            return False, obs, cat, fit, n_cone_last, field_last
        same = len(v_obs) == len(obs) and np.all(v_obs == obs) and np.all(v_cat == cat)
        if same or len(v_obs) < len(obs):
            break
        fit = _fit(fit[1], vectors[v_cat], xy[v_obs], focal, cx, cy, fit_focal)
        if not fit[0]:
            return False, obs, cat, fit, n_cone_last, field_last
        ok, obs, cat, fit = _drop_outliers(v_obs, v_cat, fit, xy, vectors, focal, cx, cy,
                                           fit_focal, sigma_px)  # fmt: skip
        if not ok:
            return False, obs, cat, fit, n_cone_last, field_last
    return True, obs, cat, fit, n_cone_last, field_last


@njit(cache=True)
def _drop_outliers(obs, cat, fit, xy, vectors, focal, cx, cy, fit_focal, sigma_px):
    """As api._Fitter.drop_outliers."""
    while len(obs) > _MIN_FIT_STARS:
        t = _studentized(fit[2], fit[5], sigma_px)
        worst = np.argmax(t)
        if t[worst] <= 2.0 * math.log(len(obs) / _OUTLIER_ALPHA):
            break
        keep = np.arange(len(obs)) != worst
        obs, cat = obs[keep], cat[keep]
        fit = _fit(fit[1], vectors[cat], xy[obs], focal, cx, cy, fit_focal)
        if not fit[0]:
            return False, obs, cat, fit
    return True, obs, cat, fit


@njit(cache=True)
def _shared_rms(obs_a, cat_a, res_a, obs_b, cat_b, res_b):
    """As api._shared_rms."""
    sa, sb, n = 0.0, 0.0, 0
    for i in range(len(obs_a)):
        for j in range(len(obs_b)):
            if obs_a[i] == obs_b[j] and cat_a[i] == cat_b[j]:
                sa += res_a[i, 0] ** 2 + res_a[i, 1] ** 2
                sb += res_b[j, 0] ** 2 + res_b[j, 1] ** 2
                n += 1
    if n == 0:
        return np.inf, np.inf
    return math.sqrt(sa / n), math.sqrt(sb / n)


@njit(cache=True)
def _free_focal_step(R, icrs, xy, focal, cx, cy):
    """As refine.free_focal_step: (focal length, its 1-sigma) from one Gauss-Newton step."""
    res, J = _residuals_jacobian(R, icrs, xy, focal, cx, cy, True)
    step, definite = _normal_step(J, res)
    if not definite:
        return focal, np.inf
    left = res + J @ step
    s2 = (left @ left) / max(len(res) - 4, 1)
    L, _ = _cholesky(J.T @ J)
    var = s2 / L[3, 3] ** 2  # (J^T J)^-1 [3, 3]
    f = focal * math.exp(step[3])
    return f, f * math.sqrt(max(var, 0.0))


@njit(cache=True)
def _conclude(obs, cat, R, xy, sky, focal, cx, cy, width, height, fit_focal, radii,
              sigma_px, hypotheses, max_p, min_matched_fraction):  # fmt: skip
    """As api.conclude without distortion. Returns (status, refusal, obs, cat, R, residuals,
    rms, sigma boresight / roll arcsec, p_false, focal and its sigma, focal fitted by the scale
    check, expected)."""
    vectors = sky[0]
    radius = radii.max()
    work = np.empty(len(vectors), dtype=np.int64)
    fail = (DEFER, 0, obs, cat, R, np.zeros((0, 2)), 0.0, 0.0, 0.0, 1.0, focal, 0.0, 0.0, 0)
    ok, obs, cat, fit, n_cone, field = _converge(
        obs, cat, R, xy, sky, focal, cx, cy, fit_focal, radius, sigma_px, work
    )
    if not ok:
        return fail
    bearings = _bearings(xy, fit[9], cx, cy)
    wide_obs, wide_cat, _, _, deferred = _match(
        bearings, fit[1], sky, 3.0 * radius, fit[3], False, _field_radius(bearings, 3.0 * radius),
        work,
    )  # fmt: skip
    if deferred:
        return fail
    if len(wide_obs) > len(obs):
        ok2, obs2, cat2, fit2, n_cone2, field2 = _converge(
            wide_obs, wide_cat, fit[1], xy, sky, focal, cx, cy, fit_focal, radius, sigma_px, work
        )
        if not ok2:
            return fail
        rms_a, rms_b = _shared_rms(obs, cat, fit[2], obs2, cat2, fit2[2])
        if len(obs2) > len(obs) and rms_b <= 1.5 * rms_a + 0.1 * sigma_px:
            obs, cat, fit, n_cone, field = obs2, cat2, fit2, n_cone2, field2
    R, f_fit = fit[1], fit[9]
    bearings = _bearings(xy, f_fit, cx, cy)
    dist = np.empty(len(obs))
    for s in range(len(obs)):
        row = cat[s]
        v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
        d2 = 0.0
        for k in range(3):
            ck = R[k, 0] * v0 + R[k, 1] * v1 + R[k, 2] * v2
            d2 += (bearings[obs[s], k] - ck) ** 2
        dist[s] = math.sqrt(d2)
    area = 1.0 - math.cos(field)
    p_false = _false_match_radii(dist, n_cone, area, len(xy), 3, hypotheses, radii)
    refusal = ACCEPTED
    f_scale = 0.0
    if not fit_focal and len(obs) >= _MIN_STARS_SCALE_CHECK:
        f_scale, sigma = _free_focal_step(R, vectors[cat], xy[obs], focal, cx, cy)
        df = f_scale - focal
        if abs(df) > 5.0 * sigma and abs(df) > _SCALE_TOLERANCE * focal:
            refusal = WRONG_SCALE
    if refusal == ACCEPTED and p_false > max_p:
        refusal = UNCONVINCING
    # catalog stars inside the image (as simulate.project_catalog with the fitted camera)
    half_diagonal = math.atan(
        math.hypot(max(cx, width - cx), max(cy, height - cy)) / f_fit
    )  # as Camera.half_diagonal_rad
    n_front = _cone(R[2], _chord(half_diagonal + 0.01) ** 2, sky, work)
    inside = 0
    limit = math.cos(half_diagonal + 0.01)
    for m in range(n_front):
        row = work[m]
        v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
        c0 = R[0, 0] * v0 + R[0, 1] * v1 + R[0, 2] * v2
        c1 = R[1, 0] * v0 + R[1, 1] * v1 + R[1, 2] * v2
        c2 = R[2, 0] * v0 + R[2, 1] * v1 + R[2, 2] * v2
        if c2 > 0.0 and c2 > limit:
            x, y = cx + f_fit * c0 / c2, cy + f_fit * c1 / c2
            if 0.0 <= x <= width and 0.0 <= y <= height:
                inside += 1
    expected = min(len(xy), inside)
    if refusal == ACCEPTED and len(obs) < min_matched_fraction * expected:
        refusal = TOO_FEW
    return (FOUND, refusal, obs, cat, R, fit[2], fit[6], fit[7], fit[8], p_false, f_fit,
            fit[10], f_scale, expected)  # fmt: skip


# ---------------------------------------------------------------------------- Python side

_LOADED: set[str] = set()  # kernels this process has called (their code is loaded)


def _say_compiling() -> None:
    if "notice" not in _LOADED:  # once per process
        _LOADED.add("notice")
        print(
            "starnav: compiling the solver's machine code (once per installation, ~30 s)",
            file=sys.stderr,
            flush=True,
        )


@contextmanager
def _first_use(kernel: str) -> Iterator[None]:
    """Around a kernel's first call in a process: it loads the cached machine code (~0.1 s),
    or compiles it, the first time after installing (~30 s on 2 cores in all). When the wait
    passes a second, say why on stderr."""
    if kernel in _LOADED:
        yield
        return
    notice = threading.Timer(1.0, _say_compiling)
    notice.daemon = True
    notice.start()
    try:
        yield
    finally:
        notice.cancel()
        _LOADED.add(kernel)


def identify(
    bearings: np.ndarray,
    order: np.ndarray,
    database: PairDatabase,
    settings: MatchSettings,
    *,
    R_prior: np.ndarray | None = None,
    prior_sigma_deg: float = 1.0,
) -> IdentifyOutcome | None:
    """Pyramid identification (or tracking near ``R_prior``), as ``Pyramid().identify`` (or
    ``Tracking(...).identify``) would do it; None when the numpy path must decide."""
    order = np.asarray(order)
    used = order[: settings.max_screen_stars]
    screened = np.ascontiguousarray(bearings[used] if len(used) < len(bearings) else bearings)
    local_order = np.arange(len(used)) if len(used) < len(bearings) else order
    local_order = np.ascontiguousarray(local_order[: settings.max_stars], dtype=np.int64)
    if len(local_order) < 3:
        return IdentifyOutcome(None, "fewer than 3 stars", 0)
    radii = np.asarray(settings.match_radii_rad, dtype=np.float64)
    sky = database_sky(database)
    pairs = (database.pair_a, database.pair_b, database.pair_angle_rad)
    parity = settings.parity or 0
    sky_args = sky.args()
    if R_prior is not None:
        # the catalog stars the prior allows: within the field plus 3 sigma of its boresight
        with _first_use("prior"):
            allowed, parity = _prior_stars(
                screened,
                np.ascontiguousarray(R_prior, dtype=np.float64),
                settings.match_radius_rad,
                math.radians(prior_sigma_deg),
                sky_args,
            )
        sky_args = (*sky_args[:6], allowed)
    with _first_use("identify"):
        status, obs, cat, R, par, p, hypotheses, proposed, best_p = _identify(
            screened,
            local_order,
            *pairs,
            database.max_angle_rad,
            sky_args,
            settings.pair_tol_rad,
            radii,
            settings.max_false_match_probability,
            parity,
            settings.max_hypotheses,
        )
    if status == DEFER:
        return None
    if status == AMBIGUOUS:
        return IdentifyOutcome(
            None,
            "parity ambiguous: the identified stars are nearly collinear (give the parity to "
            "solve)",
            hypotheses,
        )
    if status == NOT_FOUND:
        reason = not_found_reason(hypotheses, proposed, best_p, settings, NO_TRIANGLE)
        return IdentifyOutcome(None, reason, hypotheses)
    if len(used) < len(bearings):
        obs = used[obs]
    found = Identification(obs.astype(np.intp), cat.astype(np.intp), R, int(par), p, hypotheses)
    return IdentifyOutcome(found, "", hypotheses)


@dataclass(frozen=True, eq=False)
class Concluded:
    """The fit of an identification (see api.conclude): matched ``obs`` / ``cat`` rows, the
    attitude, residuals (n, 2, px), rms (px), 1-sigma boresight / roll (arcsec), the final
    false-match probability, the focal length (fitted or given, px) and its 1-sigma, and the
    refusal (``ACCEPTED`` or a code) with the focal length the scale check found and the
    number of stars expected."""

    obs: np.ndarray
    cat: np.ndarray
    R_cam_from_icrs: np.ndarray
    residuals_px: np.ndarray
    rms_px: float
    sigma_boresight_arcsec: float
    sigma_roll_arcsec: float
    false_match_probability: float
    focal_px: float
    sigma_focal_px: float
    refusal: int
    scale_focal_px: float
    expected: int


def conclude(
    found: Identification,
    xy: np.ndarray,
    camera,
    database: PairDatabase,
    settings: MatchSettings,
    *,
    sigma_px: float,
    min_matched_fraction: float,
    fit_focal: bool = False,
) -> Concluded | None:
    """The attitude fit and refusals of ``api.conclude`` for a camera without distortion
    (the focal length fitted with ``fit_focal``); None when the numpy path must decide."""
    with _first_use("conclude"):
        out = _conclude(
            np.ascontiguousarray(found.obs_index, dtype=np.int64),
            np.ascontiguousarray(found.cat_index, dtype=np.int64),
            np.ascontiguousarray(found.R_cam_from_icrs, dtype=np.float64),
            np.ascontiguousarray(xy, dtype=np.float64),
            database_sky(database).args(),
            float(camera.focal_px),
            float(camera.cx),
            float(camera.cy),
            float(camera.width),
            float(camera.height),
            bool(fit_focal),
            np.asarray(settings.match_radii_rad, dtype=np.float64),
            float(sigma_px),
            int(found.hypotheses),
            settings.max_false_match_probability,
            float(min_matched_fraction),
        )
    if out[0] == DEFER:
        return None
    return Concluded(*out[2:12], out[1], *out[12:])
