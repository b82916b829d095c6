"""The pairings of 4-star patterns (numba kernels): which of the 24 ways to pair an observed
pattern's stars with a catalog pattern's agree edge by edge (``identify.pattern4``'s
``_star_orders`` asks this of every candidate of a look-up).
"""

from __future__ import annotations

import numpy as np

from starnav.attitude.rotation import det3
from starnav.runtime.caching import njit


@njit(cache=True)
def _consistent(dist_sorted, tie_rad, perms, pairs):
    """(p, 24): whether star order ``perms[k]`` of each observed pattern keeps its stars'
    distances from the centroid ``dist_sorted`` (p, 4, ascending) in order, within
    ``tie_rad`` (p,): every pair (i, j) of ``pairs`` at d_i <= d_j + tie."""
    p, n_perm = len(dist_sorted), len(perms)
    out = np.ones((p, n_perm), dtype=np.bool_)
    for q in range(p):
        for k in range(n_perm):
            for e in range(len(pairs)):
                i, j = perms[k, pairs[e, 0]], perms[k, pairs[e, 1]]
                if not dist_sorted[q, i] <= dist_sorted[q, j] + tie_rad[q]:
                    out[q, k] = False
                    break
    return out


@njit(cache=True)
def agreeing_orders(dist_sorted, tie_rad, canon_edges, cand_pat, cat_edges, scale, tol_rad,
                    rel_tol, perms, perm_edges, pairs):  # fmt: skip
    """For candidates (observed pattern ``cand_pat``, catalog edges ``cat_edges`` (m, 6),
    scale ``scale`` (m,) of observed to catalog angles), the pairings whose six edges agree:
    per star order ``k`` of ``perms`` consistent with the observed pattern's centroid
    distances (``_consistent``), in ascending order of k and then of the candidate, the
    candidate ``c``, ``k`` and the largest edge error ``err`` (rad): |canonical edge
    ``perm_edges[k]`` x scale - catalog edge| less ``rel_tol`` x the catalog edge, over the
    scale, at most ``tol_rad``."""
    consistent = _consistent(dist_sorted, tie_rad, perms, pairs)
    m, n_perm, n_edges = len(cand_pat), len(perms), cat_edges.shape[1]
    errs = np.empty((n_perm, m))
    count = 0
    for k in range(n_perm):
        for c in range(m):
            errs[k, c] = np.inf
            if not consistent[cand_pat[c], k]:
                continue
            worst = -np.inf
            for e in range(n_edges):
                obs_e = canon_edges[cand_pat[c], perm_edges[k, e]]
                d = abs(obs_e * scale[c] - cat_edges[c, e]) - rel_tol * cat_edges[c, e]
                worst = max(worst, d)
            errs[k, c] = worst / scale[c]
            count += errs[k, c] <= tol_rad
    c_out = np.empty(count, dtype=np.int64)
    k_out = np.empty(count, dtype=np.int64)
    err_out = np.empty(count)
    n = 0
    for k in range(n_perm):
        for c in range(m):
            if errs[k, c] <= tol_rad:
                c_out[n], k_out[n], err_out[n] = c, k, errs[k, c]
                n += 1
    return c_out, k_out, err_out


@njit(cache=True)
def pairing_parities(obs, pat_h, obs_local, cat_vec, triples):
    """The parity (+1: the sky as seen, -1: mirrored) of each pairing of observed pattern
    ``pat_h`` (its stars ``obs[pat_h]`` in the order ``obs_local``) with catalog stars
    ``cat_vec`` (n, 4, 3), from the observed pattern's best-spread triangle of ``triples``
    (the largest |triple product|), and that triangle's |triple product| (how flat it is)."""
    n = len(pat_h)
    parity = np.empty(n, dtype=np.int64)
    spread = np.empty(n)
    for h in range(n):
        v = obs[pat_h[h]]
        best, d_obs, d_cat = -1.0, 0.0, 0.0
        for t in range(len(triples)):
            i, j, k = triples[t, 0], triples[t, 1], triples[t, 2]
            d = det3(v[obs_local[h, i]], v[obs_local[h, j]], v[obs_local[h, k]])
            if abs(d) > best:
                best = abs(d)
                d_obs = d
                d_cat = det3(cat_vec[h, i], cat_vec[h, j], cat_vec[h, k])
        parity[h] = 1 if np.sign(d_obs) == np.sign(d_cat) else -1
        spread[h] = abs(d_obs)
    return parity, spread
