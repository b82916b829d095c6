"""Geometric voting (``algorithm="voting"``): the votes and honest hypothesis counting.
(Solve rates and safety: test_identify_algorithms.py.)"""

import numpy as np
import pytest

from starnav.api import get_database, make_camera
from starnav.camera import Camera
from starnav.identify.pyramid import catalog_triangles
from starnav.identify.voting import PairWindows, _triples, pair_votes, triangle_hypotheses
from starnav.simulate import simulate_frame

CAMERA = Camera.from_fov(12.0, 512)


def _frames(catalog, n, seed, **errors):
    rng = np.random.default_rng(seed)
    return [simulate_frame(catalog, CAMERA, seed=rng, **errors) for _ in range(n)]


def test_votes_rank_the_true_star_first(hip_1991):
    """On clean frames (1 px tolerance) the first vote alone names nearly every star."""
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    tol = 1.0 / CAMERA.focal_px
    first = total = 0
    for f in _frames(hip_1991, 8, 3, noise_px=0.1):
        b = CAMERA.pixels_to_bearings(f.xy)[:10]
        w = PairWindows.measure(b, database, tol)
        p, q = np.nonzero(np.triu(w.valid, 1))
        votes = pair_votes(database, w, p, q, len(b), tol)
        truth = hip_1991.rows(f.true_id[: len(b)])
        first += int(np.sum(np.argmax(votes, axis=1) == truth))
        total += len(b)
    assert first >= 0.95 * total


@pytest.mark.parametrize("tol_px", [1.0, 2.12])
def test_hypothesis_count_covers_every_catalog_triangle(hip_1991, tol_px):
    """The count the vote pays for (a union bound over what it chose from) is at least the
    number of catalog triangles agreeing with the measured triangles, enumerated."""
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    tol = tol_px / CAMERA.focal_px
    for f in _frames(hip_1991, 3, 8, noise_px=0.3):
        b = CAMERA.pixels_to_bearings(f.xy)[:7]
        w = PairWindows.measure(b, database, tol)
        t = _triples(len(b))
        estimate = triangle_hypotheses(b, w, t, len(hip_1991), tol, parity_known=False)
        exact = 0
        for i, j, k in t:
            sides = w.angles[[i, i, j], [j, k, k]]
            if not (w.valid[i, j] and w.valid[i, k] and w.valid[j, k]):
                continue
            flat = abs(np.linalg.det(b[[i, j, k]])) < 3.0 * tol * sides.max()
            exact += len(catalog_triangles(database, *sides, tol)) * (2 if flat else 1)
        assert estimate.sum() >= exact > 0
