"""The false-match probability (docs/verification.md): each likelihood ratio has expectation
1 under a wrong hypothesis, so the reported probability is calibrated from above; and it
weighs the evidence the way it should (tight beats loose, more beats fewer, a dense field
counts less, an unmatched point lowers the odds)."""

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import quad

from starnav.identify.base import MatchSettings
from starnav.identify.kernels import evidence as K
from starnav.identify.verify import Verification
from starnav.starlist import StarList

PX = 1.0 / 2435.68  # rad per px of a 12° / 512 px camera
SIGMA = 0.5 * PX
RADIUS = 3.5 * SIGMA
ONE = MatchSettings(1e-3, RADIUS, (SIGMA,))


def _p(distances_px, n_stars, *, n_cone=15, field_area=1e-2, hypotheses=100, settings=ONE):
    dist = np.asarray(distances_px, dtype=float) * PX
    n = len(dist)
    ver = Verification(np.arange(n), np.arange(n), dist, n_cone, field_area)
    return ver.false_match_probability(n_stars, 3, hypotheses, settings)


@pytest.mark.parametrize("n_cone", [1, 15, 200, 5000])
@pytest.mark.parametrize("q", [0.5, 0.0625])
def test_a_points_ratio_has_expectation_one_under_a_wrong_hypothesis(n_cone, q):
    """A wrong hypothesis sees the catalog as a Poisson field: in s = 1 - cos(d) the nearest
    star is exponential of rate n_cone / area (5000 stars: most points have one within the
    radius); the matched part integrates the ratio against that density, the unmatched part
    weighs its ratio by the chance of missing."""
    area = 1e-2
    rho = n_cone / area  # per unit s
    s_r = 1.0 - math.cos(RADIUS)

    def ratio(s):
        out = np.empty(1)
        K.star_log_ratios(np.array([math.sqrt(2.0 * s)]), n_cone, area, SIGMA, q, RADIUS, out)
        return math.exp(out[0])

    matched, _ = quad(lambda s: rho * math.exp(-rho * s) * ratio(s), 0.0, s_r, limit=200)
    miss = K.star_log_ratios(np.empty(0), n_cone, area, SIGMA, q, RADIUS, np.empty(0))
    assert matched + math.exp(-rho * s_r) * math.exp(miss) == pytest.approx(1.0, rel=1e-6)


def test_the_reported_probability_is_calibrated_on_random_fields():
    """Points dropped at random on a Poisson field of stars: P(p <= alpha) <= alpha at every
    alpha (Markov over the product of ratios)."""
    rng = np.random.default_rng(1)
    n_cone, area, n_stars = 40, 1e-3, 8
    s_r = 1.0 - math.cos(RADIUS)
    ps = []
    for _ in range(20000):
        s = rng.exponential(area / n_cone, n_stars)  # each point's nearest star
        dist = np.sqrt(2.0 * s[s <= s_r]) / PX
        ps.append(_p(dist, n_stars, n_cone=n_cone, field_area=area, hypotheses=1))
    ps = np.array(ps)
    for alpha in (0.5, 0.2, 0.05):
        assert np.mean(ps <= alpha) <= alpha


def test_tight_agreement_counts_more_than_loose_and_more_stars_more_than_fewer():
    tight = _p([0.1] * 6, 10)
    loose = _p([1.5] * 6, 10)
    fewer = _p([0.1] * 5, 10)
    assert tight < loose and tight < fewer
    # an unmatched point lowers the odds (by 2 at q = 1/2, a miss near-certain at 3.5 sigma)
    assert 1.0 < _p([0.1] * 6, 11) / tight <= 2.0
    # a denser catalog makes chance agreement likelier: the same pairs count less
    assert _p([0.3] * 6, 10, n_cone=60) > _p([0.3] * 6, 10, n_cone=15)
    # the hypotheses tried multiply it
    assert _p([0.3] * 5, 10, hypotheses=1000) == pytest.approx(10 * _p([0.3] * 5, 10))


def test_an_unknown_sigma_takes_the_best_of_the_grid_and_pays_for_it():
    grid = MatchSettings.for_focal(None, 1.0 / PX)  # tolerances of 1 px, sigmas 1/8 .. 1 px
    assert grid.sigmas_rad == pytest.approx(tuple(f * PX for f in (0.125, 0.25, 0.5, 1.0)))
    assert grid.match_radius_rad == pytest.approx(3.5 * PX)
    told = MatchSettings.for_focal(0.25, 1.0 / PX)
    assert told.sigmas_rad == pytest.approx((0.25 * PX,))
    at_quarter = MatchSettings(1e-3, 3.5 * PX, (0.25 * PX,))
    best = _p([0.2] * 8, 10, settings=grid)
    assert best == pytest.approx(4 * _p([0.2] * 8, 10, settings=at_quarter), rel=1e-9)


def _bright(cat, point_mag, mags, n_used=0, rank=None):
    """``brightness_log_ratio`` of points 0..n-1 paired with rows ``cat``, the whole
    ``mags`` the field cone."""
    n = len(cat)
    rank = np.arange(len(point_mag)) if rank is None else rank
    point_mag = np.asarray(point_mag, dtype=float)
    cone = np.arange(len(mags))
    return K.brightness_log_ratio(np.arange(n), np.asarray(cat), rank, point_mag, mags, cone,
                                  len(mags), n_used)  # fmt: skip


def test_brightness_ratio_has_expectation_at_most_one_and_weighs_magnitudes():
    rng = np.random.default_rng(3)
    mags = np.sort(rng.uniform(1.0, 6.0, 12))  # the field cone's stars
    points = np.array([2.1, 3.4, 3.9])  # instrumental magnitudes, any zero point
    # a wrong hypothesis pairs each point with any star of the field (independently): the
    # mean over every pairing, exactly, is at most 1 (1 but for the zero points left out)
    for n in (1, 2):
        pairings = itertools.product(range(12), repeat=n)
        means = [math.exp(_bright(c, points[:n], mags)) for c in pairings]
        assert 0.3 < np.mean(means) <= 1.0 + 1e-12
    # a right one: the stars' magnitudes are the points' plus one zero point (which costs:
    # it is known to the width of the field's magnitudes, 5 mag, and found to ~0.1 mag)
    right = np.concatenate([points + 1.7, mags])
    assert _bright([0, 1, 2], points, right) > math.log(10.0)
    assert _bright([0, 1, 2], points, right) <= K.brightness_log_bound(3, 0, 15, True)
    # the stars that built a hypothesis from tables of bright stars are left out
    assert _bright([0, 1, 2], points, right, n_used=1) < _bright([0, 1, 2], points, right)
    assert _bright([0, 1, 2], points, right, n_used=3) == 0.0
    # no magnitudes, or not measured: no evidence; a point out of the order is not scored
    assert _bright([0, 1, 2], [], right) == 0.0
    assert _bright([0, 1, 2], [np.nan] * 3, right) == 0.0
    assert _bright([0], points, right, rank=np.array([-1, 0, 1])) == 0.0
    # magnitudes that disagree cost at most the no-evidence weight's factor
    wrong_order = np.concatenate([points[::-1] + 1.7, mags])
    assert _bright([0, 1, 2], [2.1, 3.4, 3.9], wrong_order) >= math.log(K.NO_BRIGHTNESS_WEIGHT)
    assert _bright([0, 1, 2], [2.1, 3.4, 3.9], wrong_order) < _bright([0, 1, 2], points, right)


def test_side_ratio_has_expectation_at_most_one():
    # the sides: a catalog triangle's side uniform within the tolerance window (one side moved,
    # the two exact ones taken out at their bound, a third of the triangle's each)
    tol = 3.0 * math.sqrt(2.0) * SIGMA
    tri = np.eye(3)
    exact_side = K.side_log_bound(SIGMA, tol) / 3.0
    ratios = []
    for d in np.linspace(-tol, tol, 4001):
        cat = np.eye(3)
        cat[1] = [math.cos(0.5 * math.pi + d), math.sin(0.5 * math.pi + d), 0.0]
        ratios.append(math.exp(K.side_log_ratio(tri, cat, SIGMA, tol) - 2.0 * exact_side))
    assert 0.99 < np.mean(ratios) <= 1.0  # the Gaussian's mass within +-3 sigma
    assert K.side_log_ratio(tri, tri, SIGMA, tol) == pytest.approx(3.0 * exact_side)
    assert K.side_log_ratio(tri, tri, SIGMA, 0.0) == 0.0


def test_point_magnitudes_come_from_the_brightness():
    xy = np.zeros((4, 2))
    stars = StarList(xy, ("a", "b", "c", "d"), np.array([1.0, 100.0, 0.0, -3.0]))
    mags = stars.magnitudes
    assert mags[:2] == pytest.approx([0.0, -5.0])
    assert np.isnan(mags[2:]).all()  # no flux: no magnitude
    assert StarList(xy, stars.labels, None).magnitudes is None
