"""Match-group identification (``algorithm="angle"``): honest hypothesis counting and row
mapping. (Solve rates and safety: test_identify_algorithms.py.)"""

import numpy as np

from starnav.api import get_database, make_camera
from starnav.camera import Camera
from starnav.identify import MatchSettings
from starnav.identify.angle import AngleMatch
from starnav.identify.pyramid import catalog_triangles
from starnav.identify.voting import PairWindows
from starnav.simulate import simulate_frame

CAMERA = Camera.from_fov(12.0, 512)


def _frames(catalog, n, seed, **errors):
    rng = np.random.default_rng(seed)
    return [simulate_frame(catalog, CAMERA, seed=rng, **errors) for _ in range(n)]


def _settings(sigma_px, **options):
    px = 1.0 / CAMERA.focal_px
    return MatchSettings(
        pair_tol_rad=max(3.0 * np.sqrt(2.0) * sigma_px, 1.0) * px,
        match_radius_rad=max(3.5 * sigma_px, 1.0) * px,
        sigmas_rad=(sigma_px * px,),
        pixel_rad=px,
        **options,
    )


def test_count_covers_the_triangles_of_the_reference_star(hip_1991):
    """Solved at the first reference star, the count is at least the number of catalog
    triangles agreeing with any triangle of that star and two of its neighbours (the set the
    vote chose from), enumerated."""
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    settings = _settings(0.3)
    tol = settings.pair_tol_rad
    checked = 0
    for f in _frames(hip_1991, 6, 31, noise_px=0.3):
        b = CAMERA.pixels_to_bearings(f.xy)
        if len(b) < 6:
            continue
        outcome = AngleMatch(max_reference_stars=1).identify(
            b, np.arange(len(b)), database, settings
        )
        assert outcome.identification is not None
        w = PairWindows.measure(b[: settings.max_stars], database, tol)
        nbrs = np.flatnonzero(w.valid[0])
        exact = 0
        for x, j in enumerate(nbrs):
            for k in nbrs[x + 1 :]:
                if not w.valid[j, k]:
                    continue
                sides = w.angles[[0, 0, j], [j, k, k]]
                flat = abs(np.linalg.det(b[[0, j, k]])) < 3.0 * tol * sides.max()
                exact += len(catalog_triangles(database, *sides, tol)) * (2 if flat else 1)
        assert outcome.hypotheses >= exact > 0
        checked += 1
    assert checked >= 4


def test_screen_stars_map_back_to_the_input_rows(hip_1991):
    """With only the first 8 stars screened, the matches still name the input rows."""
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    settings = _settings(0.3, max_screen_stars=8)
    rng = np.random.default_rng(4)
    for f in _frames(hip_1991, 10, 17, noise_px=0.3):
        if len(f.xy) < 12:
            continue
        perm = rng.permutation(len(f.xy))
        b = CAMERA.pixels_to_bearings(f.xy[perm])
        order = np.argsort(perm)  # the original (brightness) order of the shuffled rows
        found = AngleMatch().identify(b, order, database, settings).identification
        assert found is not None
        assert set(found.obs_index) - set(order[:8]) == set()
        ids = hip_1991.ids[found.cat_index]
        assert np.array_equal(ids, f.true_id[perm][found.obs_index])
