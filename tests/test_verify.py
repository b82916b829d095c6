import numpy as np
import pytest

from starnav.identify.verify import Verification, false_match_probability


def _ver(distances_rad, n_cone=15, field_area=1e-2):
    n = len(distances_rad)
    return Verification(
        np.arange(n), np.arange(n), np.asarray(distances_rad, dtype=float), n_cone, field_area
    )


def test_binomial_tail_and_bonferroni():
    # 2 extra agreements of 5 trials at p = 0.01: P(X >= 2) = 1 - 0.99^5 - 5*0.01*0.99^4
    exact = 1 - 0.99**5 - 5 * 0.01 * 0.99**4
    assert false_match_probability(8, 5, 3, 0.01, 1) == pytest.approx(exact, rel=1e-10)
    assert false_match_probability(8, 5, 3, 0.01, 10) == pytest.approx(10 * exact, rel=1e-10)
    assert false_match_probability(8, 3, 3, 0.01, 1) == 1.0  # no extra agreement: no evidence


def test_tight_agreement_counts_more_than_loose():
    """Five stars agreeing within 1 px are stronger evidence than within 3.5 px; the best
    radius wins, paid for with a factor of the number of radii."""
    px = 1.0 / 2435.68
    radii = (0.5 * px, 1.0 * px, 3.5 * px)
    tight = _ver([0.3 * px] * 5 + [3.0 * px])
    loose = _ver([3.0 * px] * 6)
    p_tight = tight.false_match_probability(10, 3, 100, radii)
    p_loose = loose.false_match_probability(10, 3, 100, radii)
    assert p_tight < p_loose
    single = tight.false_match_probability(10, 3, 100, radii[2:])
    at_half_px = false_match_probability(10, 5, 3, tight.p_chance(radii[0]), 100)
    assert p_tight == pytest.approx(3 * min(single, at_half_px), rel=1e-9)
