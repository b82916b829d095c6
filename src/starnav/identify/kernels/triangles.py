"""The catalog triangle join (numba kernels): the catalog star triples whose sides agree with
a measured triangle's, found on the pair table sorted by angle.
"""

from __future__ import annotations

import math

import numpy as np

from starnav.runtime.caching import njit


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
