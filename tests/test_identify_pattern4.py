"""The 4-star pattern algorithm (tetra3 / cedar-solve idea): its table and its answers."""

import math
import time

import numpy as np
import pytest

import starnav
from starnav.api import get_database
from starnav.camera import Camera
from starnav.catalog import Catalog
from starnav.errors import StarnavError
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll, unit_to_radec
from starnav.identify import MatchSettings, make_identifier
from starnav.identify import pattern4 as p4
from starnav.simulate import simulate_frame

CAMERA = Camera.from_fov(12.0, 512)


@pytest.fixture(scope="module")
def database(hip_1991):
    return get_database(hip_1991, CAMERA)


@pytest.fixture(scope="module")
def table(database):
    return p4.Pattern4().table(database)


def test_breadth_first_order_exhausts_the_brightest_stars_first():
    c = p4.breadth_first_combinations(8)
    assert len(c) == math.comb(8, 4) and len({tuple(r) for r in c}) == len(c)
    assert (np.diff(c, axis=1) > 0).all()
    for m in range(4, 9):
        assert c[: math.comb(m, 4)].max() == m - 1  # every subset of the first m, no other


def test_table_keys_order_and_size(database, table):
    vectors = database.catalog.vectors
    assert len(table) > 100_000
    assert np.all(np.diff(table.keys.astype(np.int64)) >= 0)
    assert table.nbytes < 20e6
    rows = np.random.default_rng(0).choice(len(table), 3000, replace=False)
    v = vectors[table.stars[rows].astype(np.intp)]
    edges = np.sort(p4.pattern_edges(v), axis=1)
    assert np.allclose(table.largest_edge_rad[rows], edges[:, 5], rtol=1e-6)
    assert edges[:, 5].max() <= database.max_angle_rad
    digits = np.minimum((edges[:, :5] / edges[:, 5:] * table.bins).astype(np.int64), table.bins - 1)
    key = np.zeros(len(rows), dtype=np.int64)
    for d in range(5):
        key = key * table.bins + digits[:, d]
    assert np.array_equal(key, table.keys[rows].astype(np.int64))
    # canonical order: nearest the pattern centroid first
    assert (np.diff(p4.centroid_distances(v), axis=1) >= -1e-12).all()


def test_table_holds_the_brightest_patterns_of_simulated_frames(hip_1991, table):
    """The pattern of the 4 brightest stars of a frame is in the table almost always, and some
    pattern of the brightest 6 always (what identification relies on)."""
    held = {tuple(r) for r in np.sort(table.stars.astype(np.int64), axis=1)}
    rng = np.random.default_rng(26)
    first = any_of_6 = tried = 0
    for _ in range(40):
        f = simulate_frame(hip_1991, CAMERA, seed=rng)
        if len(f.xy) < 6:
            continue
        tried += 1
        rows = hip_1991.rows(f.true_id[:6])
        subsets = [tuple(sorted(rows[c])) for c in p4.breadth_first_combinations(6)]
        first += subsets[0] in held
        any_of_6 += any(s in held for s in subsets)
    assert tried >= 30
    assert first >= 0.85 * tried and any_of_6 == tried


def test_table_is_cached_in_memory_and_on_disk(database, table, monkeypatch):
    assert p4.Pattern4().table(database) is table
    assert table.path is not None and table.path.exists()
    monkeypatch.setattr(p4, "_TABLES", {})
    again = p4.Pattern4().table(database)
    assert again.from_cache and again is not table
    assert np.array_equal(again.keys, table.keys) and np.array_equal(again.stars, table.stars)


def test_database_nbytes_counts_table_catalog_and_tree(database, table):
    """The pattern table plus what verification searches (vectors and KD-tree), not pairs."""
    nbytes = make_identifier("pattern4").database_nbytes(database)
    assert nbytes == table.nbytes + database.verification_nbytes
    assert database.verification_nbytes > 2 * database.catalog.vectors.nbytes
    assert nbytes < table.nbytes + database.nbytes


def test_bad_options_are_refused():
    with pytest.raises(StarnavError, match="pattern_stars"):
        p4.Pattern4(pattern_stars=3)
    with pytest.raises(StarnavError, match="field_radius_fraction"):
        p4.Pattern4(field_radius_fraction=1.5)


def test_collinear_stars_refused_for_ambiguous_parity(hip_1991):
    """Stars on one line match the sky and its mirror image: no answer unless the parity is
    given (the pattern is too flat to orient, so both parities are tested)."""
    R = attitude_from_radec_roll(40.0, 20.0, 30.0)
    xs = np.array([40.0, 95, 170, 230, 300, 350, 420, 480])
    xy = np.column_stack([xs, np.full(8, 120.0)])
    ra, dec = unit_to_radec(CAMERA.pixels_to_bearings(xy) @ R)
    far = hip_1991.vectors @ R[2] < np.cos(np.radians(12.0))  # empty the rest of the field
    cat = Catalog(
        np.arange(far.sum() + 8),
        np.r_[hip_1991.ra_deg[far], np.degrees(ra)],
        np.r_[hip_1991.dec_deg[far], np.degrees(dec)],
        np.r_[hip_1991.mag[far], np.linspace(3.0, 4.0, 8)],
        "a line of stars",
    )
    options = dict(width=512, fov_deg=12.0, catalog=cat, sigma_px=0.3, algorithm="pattern4")
    result = starnav.solve_verbose(xy, **options)
    assert result.solution is None and "parity ambiguous" in result.reason
    s = starnav.solve(xy, parity=1, **options)
    assert s is not None and attitude_difference_deg(s.R_cam_from_icrs, R)[0] < 0.01


def test_hypothesis_budget_bounds_the_search(hip_1991, database, table):
    """A huge tolerance makes many catalog patterns agree: the search stops at the budget."""
    rng = np.random.default_rng(25)
    xy = rng.uniform(0, 512, (25, 2))
    bearings = CAMERA.pixels_to_bearings(xy)
    settings = MatchSettings(
        pair_tol_rad=40.0 / CAMERA.focal_px,
        match_radii_rad=(1.0 / CAMERA.focal_px,),
        max_hypotheses=200,
    )
    t0 = time.perf_counter()
    outcome = p4.Pattern4().identify(bearings, np.arange(25), database, settings)
    assert outcome.identification is None
    assert outcome.reason.startswith("gave up")
    assert time.perf_counter() - t0 < 5.0
