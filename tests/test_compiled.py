"""The compiled solve path gives the numpy path's answers, piece by piece and whole."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import betainc

import starnav
from starnav import compiled
from starnav.api import get_database
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.fov import solve_fov
from starnav.identify.verify import match_catalog
from starnav.simulate import simulate_frame

CAMERA = Camera.from_fov(12.0, 512)


@pytest.fixture(scope="module")
def hip6():
    return load_catalog(None, mag_limit=6.0)


def _both(frame, catalog, sigma_px=1.0, fov_deg=CAMERA.fov_deg, **kwargs):
    """The compiled and the numpy path's answers for ``frame`` (``fov_deg`` told)."""
    return [
        starnav.solve_verbose(
            frame.xy,
            width=CAMERA.width,
            fov_deg=fov_deg,
            brightness=frame.brightness,
            catalog=catalog,
            sigma_px=sigma_px,
            compiled=flag,
            **kwargs,
        )
        for flag in (True, False)
    ]


def _assert_same(fast, slow):
    assert (fast.solution is None) == (slow.solution is None), (fast.reason, slow.reason)
    assert fast.reason == slow.reason
    assert fast.hypotheses == slow.hypotheses
    if fast.solution is None:
        return
    a, b = fast.solution, slow.solution
    assert [m.catalog_id for m in a.stars] == [m.catalog_id for m in b.stars]
    assert np.abs(a.R_cam_from_icrs - b.R_cam_from_icrs).max() < 1e-10
    assert a.false_match_probability == pytest.approx(b.false_match_probability, rel=1e-6)
    assert a.rms_px == pytest.approx(b.rms_px, rel=1e-6)
    assert a.sigma_boresight_arcsec == pytest.approx(b.sigma_boresight_arcsec, rel=1e-6)
    assert a.sigma_roll_arcsec == pytest.approx(b.sigma_roll_arcsec, rel=1e-6)
    assert a.focal_px == pytest.approx(b.focal_px, rel=1e-12)
    assert a.sigma_focal_px == pytest.approx(b.sigma_focal_px, rel=1e-6, abs=1e-12)
    assert a.algorithm == b.algorithm


@pytest.mark.parametrize(
    ("noise_px", "false_stars", "missing", "mag_limit", "min_solved"),
    [(0.1, 0, 0.0, None, 50), (0.5, 2, 0.1, None, 50), (0.1, 0, 0.0, 4.5, 8)],
    ids=["a-clean", "b-noisy-false-missing", "d-few-stars"],
)
def test_same_answers_as_the_numpy_path(
    hip6, noise_px, false_stars, missing, mag_limit, min_solved
):
    rng = np.random.default_rng(11)
    solved = 0
    for k in range(60):
        f = simulate_frame(
            hip6,
            CAMERA,
            parity=1 if k % 2 else -1,
            mag_limit=mag_limit,
            noise_px=noise_px,
            false_stars=false_stars,
            missing_frac=missing,
            seed=rng,
        )
        if len(f.xy) < 3:
            continue
        fast, slow = _both(f, hip6, max(noise_px, 0.1))
        _assert_same(fast, slow)
        solved += fast.solution is not None
    assert solved >= min_solved


def test_same_answers_when_tracking(hip6):
    rng = np.random.default_rng(12)
    tracked = 0
    for _ in range(40):
        f = simulate_frame(hip6, CAMERA, noise_px=0.3, false_stars=1, seed=rng)
        if len(f.xy) < 3:
            continue
        turn = Rotation.from_rotvec(rng.normal(size=3) * np.radians(0.6)).as_matrix()
        fast, slow = _both(f, hip6, 0.3, prior=turn @ f.R_cam_from_icrs, prior_sigma_deg=1.0)
        _assert_same(fast, slow)
        tracked += fast.solution is not None and fast.solution.algorithm == "tracking"
    assert tracked >= 30


def test_same_answers_with_the_focal_length_fitted(hip6):
    """A field of view given 0.8 % off, the focal length fitted: both paths fit the same
    focal length, attitude and error bars."""
    rng = np.random.default_rng(13)
    fitted = 0
    for k in range(40):
        f = simulate_frame(hip6, CAMERA, parity=1 if k % 2 else -1, noise_px=0.3, seed=rng)
        if len(f.xy) < 3:
            continue
        fast, slow = _both(f, hip6, 0.3, fov_deg=12.1, fit_focal=True)
        _assert_same(fast, slow)
        if fast.solution is not None:
            fitted += 1
            assert fast.solution.focal_px == pytest.approx(CAMERA.focal_px, rel=2e-3)
            assert fast.solution.sigma_focal_px > 0
    assert fitted >= 15  # a pair tolerance of 1.3 px does not cover 0.8 % of 8° for every pair


def test_same_answers_with_the_field_of_view_searched(hip6):
    """The FOV search (4-star patterns up to a scale, its own bands and catalogs) ends in the
    compiled fit with the focal length free: the same answers as the numpy fit."""
    rng = np.random.default_rng(14)
    for _ in range(6):
        f = simulate_frame(hip6, CAMERA, noise_px=0.2, seed=rng)
        if len(f.xy) < 6:
            continue
        fast, slow = [
            solve_fov(
                f.xy,
                width=512,
                brightness=f.brightness,
                fov_range_deg=(10.0, 14.0),
                sigma_px=0.2,
                compiled=flag,
            )
            for flag in (True, False)
        ]
        _assert_same(fast, slow)
        assert fast.solution is not None
        assert fast.solution.fov_deg == pytest.approx(12.0, rel=2e-3)


def test_same_refusals(hip6):
    # a field of view 2 % off: both refuse with the same focal length in the message
    f = simulate_frame(hip6, CAMERA, ra_deg=83.8, dec_deg=-5.4, roll_deg=30, noise_px=0.1)
    answers = _both(f, hip6, fov_deg=12.24)
    assert answers[0].solution is None and "focal length" in answers[0].reason
    assert answers[0].reason == answers[1].reason
    # false stars and missing ones, and every point required to agree
    f = simulate_frame(
        hip6, CAMERA, ra_deg=83.8, dec_deg=-5.4, false_stars=3, missing_frac=0.2, seed=5
    )
    answers = _both(f, hip6, min_matched_fraction=0.99)
    assert answers[0].solution is None and "stars agree" in answers[0].reason
    assert answers[0].reason == answers[1].reason


def test_cone_search_equals_the_kd_tree(hip6):
    database = get_database(hip6, CAMERA)
    sky = compiled.database_sky(database).args()
    rng = np.random.default_rng(3)
    axes = [np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])]
    axes += [v / np.linalg.norm(v) for v in rng.normal(size=(60, 3))]
    for n, axis in enumerate(axes):
        radius = [0.001, 0.05, 0.2, 1.0, 2.5][n % 5]
        expected = set(database.cone(axis, radius).tolist())
        assert set(compiled._cone_rows(axis, radius, sky).tolist()) == expected


def test_one_to_one_pairing_equals_scipys(hip6):
    """Points put between close catalog stars, so that points compete for stars and stars
    for points: the pairing must be scipy's least-squares assignment."""
    database = get_database(hip6, CAMERA)
    sky = compiled.database_sky(database).args()
    rng = np.random.default_rng(4)
    work = np.empty(len(hip6), dtype=np.int64)
    contested = 0
    for _ in range(30):
        f = simulate_frame(hip6, CAMERA, noise_px=0.0, seed=rng)
        if len(f.xy) < 3:
            continue
        xy = np.concatenate([f.xy, f.xy[:4] + rng.normal(0, 2.0, (4, 2))])  # near twins
        bearings = CAMERA.pixels_to_bearings(xy)
        radius = 4.0 / CAMERA.focal_px
        field = compiled._field_radius(bearings, radius)
        obs, cat, dist, n_cone, deferred = compiled._match(
            bearings, f.R_cam_from_icrs, sky, radius, np.zeros((3, 3)), False, field, work
        )
        ver = match_catalog(bearings, f.R_cam_from_icrs, database, radius)
        assert not deferred
        assert obs.tolist() == ver.obs_index.tolist()
        assert cat.tolist() == ver.cat_index.tolist()
        assert np.allclose(dist, ver.distance_rad, rtol=1e-9, atol=1e-15)
        assert n_cone == ver.n_cone
        contested += len(xy) - len(obs)
    assert contested > 20  # the twins competed, and lost


def test_binomial_tail_equals_scipys_betainc():
    for trials in (1, 5, 30, 200):
        for extra in range(1, trials + 1, max(1, trials // 7)):
            for p in (1e-6, 1e-3, 0.05, 0.5, 0.97):
                expected = betainc(extra, trials - extra + 1, p)
                assert compiled._binomial_tail(trials, extra, p) == pytest.approx(
                    expected, rel=1e-9, abs=1e-300
                )


def test_a_large_contested_group_is_left_to_the_numpy_path(hip6):
    """Many points on one star make a group too big to settle here: the compiled match says
    so, and solve answers as the numpy path alone does."""
    f = simulate_frame(hip6, CAMERA, ra_deg=83.8, dec_deg=-5.4, roll_deg=30, noise_px=0.1)
    rng = np.random.default_rng(5)
    xy = np.concatenate([f.xy, f.xy[-1] + rng.uniform(-1.0, 1.0, (13, 2))])
    database = get_database(hip6, CAMERA)
    sky = compiled.database_sky(database).args()
    bearings = CAMERA.pixels_to_bearings(xy)
    radius = 3.5 / CAMERA.focal_px
    field = compiled._field_radius(bearings, radius)
    work = np.empty(len(hip6), dtype=np.int64)
    *_, deferred = compiled._match(
        bearings, f.R_cam_from_icrs, sky, radius, np.zeros((3, 3)), False, field, work
    )
    assert deferred
    crowded = SimpleNamespace(xy=xy, brightness=None)
    fast, slow = _both(crowded, hip6, 1.0)
    _assert_same(fast, slow)
    assert fast.solution is not None
