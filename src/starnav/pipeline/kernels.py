"""The fit policy of a solve as one kernel (numba; plain Python under ``NUMBA_DISABLE_JIT=1``):
from an identification to the reported attitude or the refusal.

Least squares on the image (``attitude.kernels.fit``), outliers dropped by their studentized
residuals, the stars the better attitude brings within range taken in (gated by the attitude's
uncertainty), until the matches stop changing; then a wide search from the result; the final
false-match probability and the refusals. Each rule is written here once, with its constant.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from starnav.attitude.kernels import (
    at_least_sigma,
    fit,
    focal_step,
    focal_system,
    studentized,
    variance_scale,
)
from starnav.camera.kernels import (
    N_INTRINSIC,
    PINHOLE,
    field_cos,
    pixels_to_bearings,
    project,
    sees,
    unproject,
)
from starnav.identify.kernels.evidence import brightness_log_ratio, field_false_match
from starnav.identify.kernels.pairing import pair_catalog
from starnav.identify.kernels.sky import angle, chord, cone
from starnav.runtime.caching import njit

MAX_REMATCH = 5  # fit / rematch rounds
MIN_FIT_STARS = 4  # outliers are only looked for when a fit keeps at least this many stars
OUTLIER_ALPHA = 1e-3  # chance of dropping a right pair somewhere in a frame
WIDE_FACTOR = 3.0  # the wide search from the converged fit, in match radii
# the wide set wins when it explains more stars and its rms on the shared pairs is at most
# WIDE_RMS_FACTOR x the other's + WIDE_RMS_SIGMA x sigma (a point pulled in from far bends the
# fit away from the shared stars instead)
WIDE_RMS_FACTOR = 1.5
WIDE_RMS_SIGMA = 0.1
MIN_STARS_SCALE_CHECK = 6  # the focal length given is tested from this many matched stars on
SCALE_SIGMAS = 5.0  # a focal length this many sigma off ...
SCALE_TOLERANCE = 0.005  # ... and more than this (relative) is refused without --fit-focal
# a pair is contested when another star for its point (or point for its star) fits nearly as
# well, the likelihood ratio under SWAP_RATIO, and taking it would move the attitude beyond
# SWAP_SIGMAS of its error
SWAP_RATIO = 20.0
SWAP_SIGMAS = 3.0
N_USED = 3  # stars a hypothesis is built from (they agree by construction)
N_DISTORTION = 2  # the distortion coefficients a fit may free (k1, k2)
# refusals
ACCEPTED, WRONG_SCALE, UNCONVINCING, TOO_FEW, CONTESTED, BRIGHT_UNSEEN, MISFIT = 0, 1, 2, 3, 4, 5, 6
# with the centroid sigma known, an answer is refused when its residuals' chi-square (sum of
# r^2 / sigma^2 over 2n - fitted degrees of freedom) is beyond what the sigma allows but with
# chance MISFIT_ALPHA: the stars do not fit the camera given (a field of view a few per cent
# off that a close cluster and a false star across the field hold at the given scale)
MISFIT_ALPHA_Z = 3.719  # the normal quantile of MISFIT_ALPHA = 1e-4 (one-sided)
# an answer is refused when the image it predicts holds at least as many catalog stars brighter
# than its brightest matched star by UNSEEN_MARGIN_MAG as it matched, and at least MIN_UNSEEN
# (with the points' brightness known): a right answer's brightest points are its brightest
# stars, so such stars should be among the points
UNSEEN_MARGIN_MAG = 0.5
MIN_UNSEEN = 3
# both counts take the catalog stars in the part of the frame where stars are seen: within
# SKY_RADIUS_FACTOR sqrt(area / points) of a point, the radius within which n points spread
# at random over the frame leave a place empty with chance 1 % (exp(-pi r^2 n / area)):
# stars behind trees, a roof or a cloud bank are not stars the answer should explain
SKY_RADIUS_FACTOR = math.sqrt(math.log(100.0) / math.pi)

# the six edges of a 4-star pattern, as identify.pattern4's _PAIRS
PATTERN_PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))

Converged = namedtuple("Converged", "obs cat fit n_cone field_area")
Concluded = namedtuple(
    "Concluded",
    "refusal obs cat fit false_match_probability scale_focal_px expected",
)


@njit(cache=True)
def _drop_outliers(obs, cat, f, xy, vectors, model, p0, fit_focal, fit_distortion, sigma_px):
    """Drop, one at a time, the pair whose studentized residual is beyond what the told sigma
    allows (chi-square, 2 degrees of freedom, ``OUTLIER_ALPHA`` over all pairs), refitting
    each time. A wide gate can let in a false star near a real one; the fit then bends towards
    it and its plain residual looks small, its studentized residual does not."""
    while len(obs) > MIN_FIT_STARS:
        t = studentized(f.residuals, f.leverage, sigma_px)
        worst = np.argmax(t)
        if t[worst] <= 2.0 * math.log(len(obs) / OUTLIER_ALPHA):  # P(chi2_2 > x) = e^(-x/2)
            break
        keep = np.arange(len(obs)) != worst
        obs, cat = obs[keep], cat[keep]
        f = fit(f.R, vectors[cat], xy[obs], model, p0, fit_focal, fit_distortion)
    return obs, cat, f


@njit(cache=True)
def converge(obs, cat, R, xy, sky, allowed, model, p0, width, height, fit_focal, fit_distortion,
             radius, sigma_px, work):  # fmt: skip
    """Fit, drop outliers, rematch (gated: each catalog star's radius grows with its position
    error under the attitude's covariance, at least the told sigma's) until the pairs stop
    changing. Every fit starts from the camera given (``p0``); every match takes the points'
    bearings through the fitted camera."""
    vectors = sky[0]
    f = fit(R, vectors[cat], xy[obs], model, p0, fit_focal, fit_distortion)
    obs, cat, f = _drop_outliers(obs, cat, f, xy, vectors, model, p0, fit_focal, fit_distortion,
                                 sigma_px)  # fmt: skip
    n_cone, area = 0, 0.0
    for _ in range(MAX_REMATCH):
        scale = variance_scale(f.variance_px2, sigma_px)
        bearings = pixels_to_bearings(model, f.params, xy)
        v = pair_catalog(bearings, f.R, sky, allowed, radius, f.rotation_cov * scale, True, work)
        n_cone, area = v.n_cone, v.field_area
        same = len(v.obs) == len(obs) and np.all(v.obs == obs) and np.all(v.cat == cat)
        if same or len(v.obs) < len(obs):
            break
        f = fit(f.R, vectors[v.cat], xy[v.obs], model, p0, fit_focal, fit_distortion)
        obs, cat, f = _drop_outliers(v.obs, v.cat, f, xy, vectors, model, p0, fit_focal,
                                     fit_distortion, sigma_px)  # fmt: skip
    return Converged(obs, cat, f, n_cone, area)


@njit(cache=True)
def _focal_off(f, sigma, f0):
    """Whether the focal length ``f`` (1-sigma ``sigma``) is off the one given, ``f0`` (px)."""
    return abs(f - f0) > SCALE_SIGMAS * sigma and abs(f - f0) > SCALE_TOLERANCE * f0


@njit(cache=True)
def scale_off(R, icrs, xy, model, p0, sigma_px):
    """(whether the stars put the focal length off the one given, the focal length px they
    fit): off when it is more than ``SCALE_SIGMAS`` sigma (at least ``sigma_px``'s) and
    ``SCALE_TOLERANCE`` away, by all the stars or by all but any one of them. One far star
    can pin the scale: a close group (a cluster such as the Pleiades) fits a focal length a
    few per cent off by itself, and one star across the field matched to a wrong neighbour
    where that scale puts one then holds the joint fit at the focal length given."""
    n = len(xy)
    res, J, N, g = focal_system(R, icrs, xy, model, p0)
    f_all, sigma = focal_step(res, J, N, g, p0[0], sigma_px)
    if _focal_off(f_all, sigma, p0[0]):
        return True, f_all
    for left_out in range(n if n > MIN_STARS_SCALE_CHECK else 0):
        f_scale, sigma = focal_step(res, J, N, g, p0[0], sigma_px, left_out)
        if _focal_off(f_scale, sigma, p0[0]):
            return True, f_scale
    return False, f_all


@njit(cache=True)
def _form(u0, u1, M):
    """u^T M u of the 2-vector (u0, u1) and the 2x2 ``M``."""
    return u0 * (M[0, 0] * u0 + M[0, 1] * u1) + u1 * (M[1, 0] * u0 + M[1, 1] * u1)


@njit(cache=True)
def _swap_matters(e, delta, rest, leverage, sigma2, gate):
    """Whether the alternative whose residual is the pair's plus ``delta`` (px) fits nearly as
    well from the other stars (the pair's deleted residual ``e``, studentized
    e^T (I - H_ii) e / sigma^2; ``rest`` = I - H_ii) and moves the fit by more than
    ``SWAP_SIGMAS`` (a residual change delta moves the parameters by (J^T J)^-1 J_i^T delta:
    delta^T H_ii delta / sigma^2 in their covariance's units)."""
    t = _form(e[0], e[1], rest) / sigma2
    t_other = _form(e[0] + delta[0], e[1] + delta[1], rest) / sigma2
    if t_other > gate or t_other - t > 2.0 * math.log(SWAP_RATIO):
        return False
    return _form(delta[0], delta[1], leverage) / sigma2 > SWAP_SIGMAS**2


@njit(cache=True)
def contested_pair(obs, cat, f, xy, sky, allowed, model, sigma_px, work):
    """Whether a pair of the fit ``f`` could as well be another: its point another catalog
    star (unmatched, of ``allowed``) or its star another unmatched point, nearly as likely
    judged from the other stars (each pair's deleted residual: the fit without it), and the
    attitude would differ beyond its error bars. A far star that alone fixes the roll and sits
    between the two stars of a close double is such a pair: whichever it is given, the fit
    bends to it. ``sigma_px``: the centroid sigma (at least the fit's a-posteriori one)."""
    vectors = sky[0]
    n = len(obs)
    sigma2 = max(f.variance_px2, sigma_px**2)
    gate = 2.0 * math.log(n / OUTLIER_ALPHA)  # the outlier rule's
    matched = np.zeros(len(xy), dtype=np.bool_)
    matched[obs] = True
    J_c = np.empty((2, 3))
    J_p = np.empty((2, N_INTRINSIC))
    e = np.empty(2)
    delta = np.empty(2)
    for i in range(n):
        H = f.leverage[i]
        rest = np.eye(2) - H
        a, b, c, d = rest[0, 0], rest[0, 1], rest[1, 0], rest[1, 1]
        det = a * d - b * c
        if not det > 1e-4:  # the fit rests on this pair alone: the others do not judge it
            continue
        r0, r1 = f.residuals[i, 0], f.residuals[i, 1]
        e[0], e[1] = (d * r0 - b * r1) / det, (-c * r0 + a * r1) / det  # (I - H_ii)^-1 r
        # alternatives as far as the gate reaches from the deleted residual
        reach_px = math.sqrt(e[0] ** 2 + e[1] ** 2) + math.sqrt(gate * sigma2 / det)
        for q in range(len(xy)):
            if not matched[q]:
                delta[0] = xy[obs[i], 0] - xy[q, 0]
                delta[1] = xy[obs[i], 1] - xy[q, 1]
                if delta[0] ** 2 + delta[1] ** 2 <= reach_px**2 and _swap_matters(
                    e, delta, rest, H, sigma2, gate
                ):
                    return True
        row = cat[i]
        here = f.R @ vectors[row]
        x0, y0 = project(model, f.params, here[0], here[1], here[2], J_c, J_p)
        reach_rad = 2.0 * reach_px / f.params[0]
        for m in range(cone(vectors[row], chord(reach_rad) ** 2, sky, allowed, work)):
            other = work[m]
            taken = False
            for k in range(n):
                taken = taken or cat[k] == other
            if taken:
                continue
            c_o = f.R @ vectors[other]
            if model == PINHOLE and c_o[2] <= 0:  # a fisheye sees past 90°, a pinhole not
                continue
            x1, y1 = project(model, f.params, c_o[0], c_o[1], c_o[2], J_c, J_p)
            delta[0], delta[1] = x1 - x0, y1 - y0
            if _swap_matters(e, delta, rest, H, sigma2, gate):
                return True
    return False


@njit(cache=True)
def compare_pairs(obs_a, cat_a, res_a, obs_b, cat_b, res_b):
    """Two fits' pairs (points ``obs``, catalog rows ``cat``, residuals px): the residual rms
    of the pairs they share under each (inf when none), how many they share (pairs are one to
    one: as many as both have means the same pairs), and how many pairs of one give a point
    or a star of the other a different partner."""
    sa, sb, n, conflicts = 0.0, 0.0, 0, 0
    for i in range(len(obs_a)):
        for j in range(len(obs_b)):
            same_point, same_star = obs_a[i] == obs_b[j], cat_a[i] == cat_b[j]
            if same_point and same_star:
                sa += res_a[i, 0] ** 2 + res_a[i, 1] ** 2
                sb += res_b[j, 0] ** 2 + res_b[j, 1] ** 2
                n += 1
            conflicts += same_point != same_star
    if n == 0:
        return np.inf, np.inf, 0, conflicts
    return math.sqrt(sa / n), math.sqrt(sb / n), n, conflicts


@njit(cache=True)
def misfit_limit(dof):
    """The chi-square of ``dof`` degrees of freedom exceeded with chance ``MISFIT_ALPHA``
    (Wilson-Hilferty's cube-root normal approximation: within a few per cent of the exact
    quantile from 3 degrees of freedom on, above it at few)."""
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + MISFIT_ALPHA_Z * math.sqrt(a)) ** 3


@njit(cache=True)
def misfits(residuals, n_fitted, sigma_px):
    """Whether the residuals (n, 2, px) of a fit of ``n_fitted`` parameters are beyond what
    a centroid sigma of ``sigma_px`` allows (``misfit_limit``)."""
    dof = 2 * len(residuals) - n_fitted
    if dof < 1 or sigma_px <= 0.0:
        return False
    chi2 = 0.0
    for i in range(len(residuals)):
        chi2 += (residuals[i, 0] ** 2 + residuals[i, 1] ** 2) / sigma_px**2
    return chi2 > misfit_limit(dof)


@njit(cache=True)
def expected_stars(R, sky, model, p, width, height, xy, rows, depth_mags, mags, work):
    """The stars an answer at attitude ``R`` through the camera ``p``, matching the catalog
    ``rows``, should explain: the catalog stars inside the image, in the sky the points ``xy``
    show (within ``SKY_RADIUS_FACTOR`` sqrt(area / points) px of one), whose ``depth_mags``
    are no fainter than the faintest star matched (how deep the image is shown to reach;
    every one when ``depth_mags`` is empty), but no more than the points; and how many of
    them have ``mags`` brighter than the brightest matched by ``UNSEEN_MARGIN_MAG`` (0 when
    ``mags`` is empty)."""
    some = len(rows) > 0
    as_deep_as = depth_mags[rows].max() if len(depth_mags) > 0 and some else math.inf
    brighter_than = mags[rows].min() - UNSEEN_MARGIN_MAG if len(mags) > 0 and some else math.inf
    vectors = sky[0]
    everything = np.ones(len(vectors), dtype=np.bool_)
    limit = field_cos(model, p, width, height)
    n_front = cone(R[2], chord(math.acos(limit)) ** 2, sky, everything, work)
    J_c = np.empty((2, 3))
    J_p = np.empty((2, N_INTRINSIC))
    near2 = SKY_RADIUS_FACTOR**2 * width * height / max(1, len(xy))
    inside, bright = 0, 0
    for m in range(n_front):
        row = work[m]
        v0, v1, v2 = vectors[row, 0], vectors[row, 1], vectors[row, 2]
        c0 = R[0, 0] * v0 + R[0, 1] * v1 + R[0, 2] * v2
        c1 = R[1, 0] * v0 + R[1, 1] * v1 + R[1, 2] * v2
        c2 = R[2, 0] * v0 + R[2, 1] * v1 + R[2, 2] * v2
        if not sees(model, p, width, height, limit, c0, c1, c2, J_c, J_p):
            continue
        x, y = project(model, p, c0, c1, c2, J_c, J_p)
        seen_sky = False
        for i in range(len(xy)):
            if (xy[i, 0] - x) ** 2 + (xy[i, 1] - y) ** 2 <= near2:
                seen_sky = True
                break
        if not seen_sky:
            continue
        inside += len(depth_mags) == 0 or depth_mags[row] <= as_deep_as
        bright += len(mags) > 0 and mags[row] < brighter_than
    return min(len(xy), inside), bright


@njit(cache=True)
def conclude(obs, cat, R, xy, sky, allowed, model, p0, width, height, fit_focal, fit_distortion,
             radius, sigmas, log_sides, rank, point_mag, mags, depth_mags, bright_drop, sigma_px,
             known_sigma_px, hypotheses, max_p, min_matched_fraction):  # fmt: skip
    """From an identification (pairs ``obs`` / ``cat``, attitude ``R``) to the fitted
    solution and its refusal code (``ACCEPTED`` or why not). ``radius`` (rad): the pairing
    radius; ``sigmas`` (rad): the centroid sigmas the false-match probability takes the best
    of; ``log_sides``: the identification's triangle-side log ratio; ``rank``: the points'
    places in the brightness order, ``point_mag`` their magnitudes, ``mags`` the catalog's
    (empty: the brightness is not known; ``identify.kernels.evidence.field_false_match`` and
    ``brightness_log_ratio``), ``depth_mags`` the catalog's whatever the points' brightness
    (``expected_stars``), ``bright_drop`` of the pairs' brightness scores left out;
    ``sigma_px``: the sigma the outlier and rematch rules use; ``known_sigma_px``: the
    centroid sigma when it is known (0: not), the least the reported covariance is at
    (``at_least_sigma``) and what the residuals are tested against (``misfits``)."""
    vectors = sky[0]
    work = np.empty(len(vectors), dtype=np.int64)
    a = converge(obs, cat, R, xy, sky, allowed, model, p0, width, height, fit_focal,
                 fit_distortion, radius, sigma_px, work)  # fmt: skip
    # a wrong star of a close pair in the first match can bend the fit so that the far stars
    # fall just outside the radius; a wide search from the result finds them
    bearings = pixels_to_bearings(model, a.fit.params, xy)
    wide = pair_catalog(bearings, a.fit.R, sky, allowed, WIDE_FACTOR * radius, a.fit.rotation_cov,
                        False, work)  # fmt: skip
    contested = False
    if len(wide.obs) > len(a.obs):
        b = converge(wide.obs, wide.cat, a.fit.R, xy, sky, allowed, model, p0, width, height,
                     fit_focal, fit_distortion, radius, sigma_px, work)  # fmt: skip
        rms_a, rms_b, n_shared, conflicts = compare_pairs(a.obs, a.cat, a.fit.residuals, b.obs,
                                                          b.cat, b.fit.residuals)  # fmt: skip
        fits = rms_b <= WIDE_RMS_FACTOR * rms_a + WIDE_RMS_SIGMA * sigma_px
        if len(b.obs) > len(a.obs) and fits:
            a = b
            bearings = pixels_to_bearings(model, a.fit.params, xy)
        elif len(b.obs) == len(a.obs) and fits and n_shared < len(a.obs):
            # as many stars, as well fitted, but not the same ones: a point of one answer
            # (a false star far out, say, that bent the roll) is another star's in the
            # other; which is right the stars do not say
            contested = True
        elif len(b.obs) > len(a.obs) and conflicts > 0:
            # more stars, fitting the shared ones worse, and one of this answer's points or
            # stars has another partner there: a false star beside a true one that bent a
            # few-star fit (the shared stars then fit it better than the whole sky does)
            # looks just like a far point pulled in that bends the larger fit
            contested = True
    f = a.fit
    # score the final pairs (the last verification may hold a slightly different set)
    dist = np.empty(len(a.obs))
    for s in range(len(a.obs)):
        row = a.cat[s]
        d2 = 0.0
        for k in range(3):
            ck = (
                f.R[k, 0] * vectors[row, 0]
                + f.R[k, 1] * vectors[row, 1]
                + f.R[k, 2] * vectors[row, 2]
            )
            d2 += (bearings[a.obs[s], k] - ck) ** 2
        dist[s] = math.sqrt(d2)
    # the fitted attitude has the hypothesis's freedom, and the focal length's when fitted
    n_fitted = N_USED + (1 if fit_focal else 0) + (N_DISTORTION if fit_distortion else 0)
    # the field cone's stars again, for their magnitudes (pairing left them elsewhere)
    field_rad = math.acos(1.0 - a.field_area)
    n_cone = cone(f.R[2], chord(field_rad) ** 2, sky, allowed, work)
    log_other = log_sides + brightness_log_ratio(a.obs, a.cat, rank, point_mag, mags, work, n_cone,
                                                 bright_drop)  # fmt: skip
    p_false = field_false_match(dist, a.obs, rank, a.n_cone, a.field_area, n_fitted, hypotheses,
                                sigmas, radius, log_other)  # fmt: skip
    refusal = ACCEPTED
    f_scale = 0.0
    if not fit_focal and len(a.obs) >= MIN_STARS_SCALE_CHECK:
        # a wrong focal length biases the attitude: test the scale, on the stars matched and
        # on those a free focal length finds besides (none if every point is: pairs are 1:1)
        wrong, f_scale = scale_off(f.R, vectors[a.cat], xy[a.obs], model, p0, sigma_px)
        if not wrong and len(a.obs) < len(xy):
            free = converge(a.obs, a.cat, f.R, xy, sky, allowed, model, p0, width, height, True,
                            fit_distortion, radius, sigma_px, work)  # fmt: skip
            if len(free.obs) > len(a.obs):
                wrong, f_scale = scale_off(free.fit.R, vectors[free.cat], xy[free.obs], model,
                                           p0, sigma_px)  # fmt: skip
        if wrong:
            refusal = WRONG_SCALE
    if refusal == ACCEPTED and misfits(f.residuals, n_fitted, known_sigma_px):
        refusal = MISFIT
    if refusal == ACCEPTED and (
        contested or contested_pair(a.obs, a.cat, f, xy, sky, allowed, model, sigma_px, work)
    ):
        refusal = CONTESTED
    if refusal == ACCEPTED and p_false > max_p:
        refusal = UNCONVINCING
    expected, unseen = expected_stars(f.R, sky, model, f.params, width, height, xy, a.cat,
                                      depth_mags, mags, work)  # fmt: skip
    if refusal == ACCEPTED and len(a.obs) < min_matched_fraction * expected:
        refusal = TOO_FEW
    if refusal == ACCEPTED and unseen >= max(MIN_UNSEEN, len(a.obs)):
        refusal = BRIGHT_UNSEEN
    if known_sigma_px > 0:
        f = at_least_sigma(f, known_sigma_px)
    return Concluded(refusal, a.obs, a.cat, f, p_false, f_scale, expected)


@njit(cache=True)
def _pattern_misfit(model, q, xy, cat_edges, focal, v, out):
    """The edge angles (rad) of the pattern of pixels ``xy`` (4, 2) through the camera ``q``
    with focal length ``focal`` (px), less the catalog's ``cat_edges`` (6,), written to
    ``out``; ``v`` (4, 3): work space."""
    q[0] = focal
    for j in range(4):
        unproject(model, q, xy[j, 0], xy[j, 1], v[j])
    for e in range(6):
        a, b = PATTERN_PAIRS[e]
        out[e] = angle(v[a], v[b]) - cat_edges[e]


@njit(cache=True)
def pattern_focals(model, p, xy, cat_edges, focal0, steps, step_rel):
    """Per observed pattern of pixels ``xy`` (h, 4, 2), the focal length (px) at which its six
    edges have the catalog's angles ``cat_edges`` (h, 6): ``steps`` Gauss-Newton steps on log f
    from ``focal0`` (h,), the derivative by central differences of ``step_rel``; and the
    largest edge error (rad) left. ``p``: the camera's other parameters."""
    n = len(xy)
    f_fit = np.empty(n)
    err = np.empty(n)
    q = p.copy()
    v = np.empty((4, 3))
    r = np.empty(6)
    up = np.empty(6)
    down = np.empty(6)
    for i in range(n):
        log_f = math.log(focal0[i])
        for _ in range(steps):
            f = math.exp(log_f)
            _pattern_misfit(model, q, xy[i], cat_edges[i], f, v, r)
            _pattern_misfit(model, q, xy[i], cat_edges[i], f * (1.0 + step_rel), v, up)
            _pattern_misfit(model, q, xy[i], cat_edges[i], f * (1.0 - step_rel), v, down)
            num, den = 0.0, 0.0
            for e in range(6):
                d = (up[e] - down[e]) / (2.0 * step_rel)
                num += r[e] * d
                den += d * d
            log_f -= num / max(den, 1e-300)
        f_fit[i] = math.exp(log_f)
        _pattern_misfit(model, q, xy[i], cat_edges[i], f_fit[i], v, r)
        worst = 0.0
        for e in range(6):
            worst = max(worst, abs(r[e]))
        err[i] = worst
    return f_fit, err
