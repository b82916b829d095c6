"""The 4-star pattern algorithm (tetra3 / cedar-solve idea): its table and its answers."""

import dataclasses
import math
import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

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
    # 10 bytes a pattern (key 4, code 4, largest edge 2) and the fields, a small part
    assert table.nbytes == 10 * len(table) + table.fields.nbytes
    assert table.fields.nbytes < 0.05 * table.nbytes
    assert table.nbytes < 20e6
    rows = np.random.default_rng(0).choice(len(table), 3000, replace=False)
    stars = table.stars(rows)
    v = vectors[stars]
    edges = np.sort(p4.pattern_edges(v), axis=1)
    step = table.edge_step_rad
    assert step < 2e-5  # about 1 pixel in 15 at this camera's scale
    assert np.all(np.abs(table.largest_edge_steps[rows] * step - edges[:, 5]) <= 0.5001 * step)
    assert edges[:, 5].max() <= database.max_angle_rad
    digits = np.minimum((edges[:, :5] / edges[:, 5:] * table.bins).astype(np.int64), table.bins - 1)
    key = np.zeros(len(rows), dtype=np.int64)
    for d in range(5):
        key = key * table.bins + digits[:, d]
    assert np.array_equal(key, table.keys[rows].astype(np.int64))
    # canonical order: nearest the pattern centroid first
    assert (np.diff(p4.centroid_distances(v), axis=1) >= -1e-12).all()


def test_table_codes_decode_to_distinct_patterns_of_their_fields(database, table):
    """Every pattern once; each is a 4-subset of the brightest stars of the field it names."""
    every = np.sort(table.stars(np.arange(len(table))), axis=1)
    assert len(np.unique(every, axis=0)) == len(table)
    assert every.min() >= 0 and every.max() < len(database.catalog)
    rows = np.random.default_rng(1).choice(len(table), 500, replace=False)
    k = table.fields.shape[1]
    field = table.codes[rows].astype(np.int64) // (math.comb(k, 4) * 24)
    for star_rows, f in zip(table.stars(rows), field, strict=True):
        assert set(star_rows.tolist()) <= set(table.fields[f].tolist())
    # the fields' rows are ascending, padded with the catalog size
    fields, n = table.fields.astype(np.int64), len(database.catalog)
    assert ((np.diff(fields, axis=1) > 0) | (fields[:, 1:] == n)).all()
    assert fields.max() <= n


@pytest.mark.parametrize("scale_range", [None, (0.97, 1.03)])
def test_the_quick_test_on_the_rounded_largest_edge_loses_no_match(
    hip_1991, database, table, scale_range
):
    """The stored largest edge (rounded to a step) only speeds the search: the matches are
    those found with every candidate's exact edges computed (a table whose stored edges pass
    everything), with the scale known and up to a scale."""
    frame = simulate_frame(hip_1991, CAMERA, noise_px=0.1, seed=4)
    bearings = CAMERA.pixels_to_bearings(frame.xy)
    order = np.argsort(-frame.brightness, kind="stable")[:8]
    obs = bearings[order[p4.breadth_first_combinations(8)]]
    tol = 10.0 / CAMERA.focal_px  # loose: many catalog patterns near the limits
    args = (database.catalog.vectors, tol, database.max_angle_rad, None)
    options = {"scale_range": scale_range, "rel_tol": 0.0 if scale_range is None else 0.005}
    hyp = p4.match_patterns(obs, table, *args, **options)
    no_quick_test = dataclasses.replace(
        table, largest_edge_steps=np.zeros_like(table.largest_edge_steps), edge_step_rad=10.0
    )
    ref = p4.match_patterns(obs, no_quick_test, *args, **options)
    assert len(ref.pattern) > 3 * len(obs)
    for name in ("pattern", "obs_local", "cat_rows", "parity"):
        assert np.array_equal(getattr(hyp, name), getattr(ref, name))
    truth = tuple(sorted(hip_1991.rows(frame.true_id[order[:4]]).tolist()))
    assert truth in {tuple(sorted(c.tolist())) for c in hyp.cat_rows[hyp.pattern == 0]}


@pytest.mark.slow
def test_table_holds_the_brightest_patterns_of_simulated_frames(hip_1991, table):
    """The pattern of the 4 brightest stars of a frame is in the table almost always, and some
    pattern of the brightest 6 always (what identification relies on)."""
    held = {tuple(r) for r in np.sort(table.stars(np.arange(len(table))), axis=1)}
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
    for name in ("keys", "codes", "fields", "largest_edge_steps"):
        assert np.array_equal(getattr(again, name), getattr(table, name))
        assert not getattr(again, name).flags.owndata  # memory-mapped, not read whole
    assert again.edge_step_rad == table.edge_step_rad


def test_database_nbytes_counts_table_catalog_and_tree(database, table):
    """The pattern table plus what verification searches (catalog and KD-tree), not pairs."""
    nbytes = make_identifier("pattern4").database_nbytes(database)
    assert nbytes == table.nbytes + p4.catalog_nbytes(database)
    assert nbytes < table.nbytes + database.nbytes


def test_catalog_nbytes_counts_each_array_once(database):
    cat, tree = database.catalog, database.tree
    arrays = cat.ids.nbytes + cat.ra_deg.nbytes + cat.dec_deg.nbytes + cat.mag.nbytes
    # the grid: a start per 1° cell and a row per star, 4 bytes each
    grid = 4 * (180 * 360 + 1) + 4 * len(cat)
    held = arrays + cat.vectors.nbytes + tree.indices.nbytes + 72 * tree.size + grid
    assert np.shares_memory(tree.data, cat.vectors)  # scipy keeps the vectors: no copy
    assert p4.catalog_nbytes(database) == held
    # a tree over a copy of the vectors holds them twice
    copied = dataclasses.replace(database)
    copied.__dict__["tree"] = cKDTree(cat.vectors.copy())  # the tree, made on first use, set
    assert p4.catalog_nbytes(copied) == held + cat.vectors.nbytes


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
    result = starnav.solve_stars(xy, **options)
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
        match_radius_rad=1.0 / CAMERA.focal_px,
        sigmas_rad=(0.3 / CAMERA.focal_px,),
        max_hypotheses=200,
    )
    t0 = time.perf_counter()
    outcome = p4.Pattern4().identify(bearings, np.arange(25), database, settings)
    assert outcome.identification is None
    assert outcome.reason.startswith("gave up")
    assert time.perf_counter() - t0 < 5.0
