"""Cone searches on the catalog's sky grids (numba kernels).

The sky grid ``sky = (vectors, start, rows, n_dec, n_ra, step_rad)``: cell ``i * n_ra + j``
(Dec band i from the south pole, RA column j) holds catalog rows ``rows[start[c]:start[c+1]]``
(``identify.database.sky_grid``); the screen asks instead one cell of a cube's faces whether a
star is near (``near = (start, rows, n)``, ``identify.database.near_grid``). Searches see only
the rows where ``allowed`` is True (tracking: the stars near the prior, ``prior_mask``).
"""

from __future__ import annotations

import math

import numpy as np

from starnav.runtime.caching import njit

PRIOR_SIGMAS = 3.0  # tracking allows the catalog stars within the field plus this many sigma


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


@njit(cache=True)
def field_radius(bearings, radius):
    """Half-angle (rad) of the cone about the boresight holding every bearing, grown by
    ``radius``: the field the chance of agreement is reckoned over."""
    zmin = 1.0
    for n in range(len(bearings)):
        zmin = min(zmin, bearings[n, 2])
    return math.acos(max(-1.0, min(1.0, zmin))) + radius


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
