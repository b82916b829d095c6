"""Neighbour-sum identification: the features and the table. (Solve rates and safety:
test_identify_algorithms.py.)"""

import numpy as np
import pytest

from starnav.api import get_database, make_camera
from starnav.camera import Camera
from starnav.errors import StarnavError
from starnav.geometry import angle_between
from starnav.identify import make_identifier
from starnav.identify.neighbor_sum import (
    NeighborSum,
    catalog_neighbor_sums,
    observed_neighbor_sums,
)
from starnav.simulate import simulate_frame

ALGORITHM = "neighbor-sum"
CAMERA = Camera.from_fov(12.0, 512)


def test_catalog_features_are_sorted_neighbour_sums(hip_1991):
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    feature, rows = catalog_neighbor_sums(database, 2)
    assert np.all(np.diff(feature) >= 0) and len(np.unique(rows)) == len(rows)
    assert catalog_neighbor_sums(database, 2)[0] is feature  # cached
    vectors = hip_1991.vectors
    for n in np.random.default_rng(1).choice(len(rows), 20, replace=False):
        others = np.delete(np.arange(len(vectors)), rows[n])
        brute = np.sort(angle_between(vectors[rows[n]], vectors[others]))[:2].sum()
        assert feature[n] == pytest.approx(brute, abs=1e-12)
    assert catalog_neighbor_sums(database, 3)[0].mean() > feature.mean()


def test_observed_features_and_edge_margin():
    """A 5 x 5 grid, 100 px apart: the centre star's two neighbours are 100 px away and its
    neighbourhood is inside the point cloud; stars on the border are not, and those next to
    it just not (their neighbours are as far as the border; the projection stretches)."""
    xy = np.array([[56.0 + 100 * i, 56.0 + 100 * j] for j in range(5) for i in range(5)])
    bearings = CAMERA.pixels_to_bearings(xy)
    feature, margin, angles = observed_neighbor_sums(bearings, 2, 0.0)
    assert feature[12] == pytest.approx(angles[12, 7] + angles[12, 11], rel=1e-12)
    assert feature[12] == pytest.approx(200.0 / CAMERA.focal_px, rel=0.01)
    assert margin[12] > 0 and -1e-3 < margin[6] < 0
    assert all(margin[k] < 0 for k in (0, 2, 4, 10, 14, 20, 22, 24))
    few, few_margin, _ = observed_neighbor_sums(bearings[:2], 2, 0.0)
    assert np.all(np.isinf(few)) and np.all(few_margin < 0)


def test_inside_features_agree_with_the_catalog(hip_1991):
    """On noise-free frames the stars whose neighbourhood is inside the field have exactly the
    catalog feature of their true star; that is what makes them the first to try."""
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    feature_sorted, rows = catalog_neighbor_sums(database, 2)
    catalog_feature = np.full(len(hip_1991), np.nan)
    catalog_feature[rows] = feature_sorted
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(20):
        frame = simulate_frame(hip_1991, CAMERA, seed=rng)
        feature, margin, _ = observed_neighbor_sums(CAMERA.pixels_to_bearings(frame.xy), 2, 0.0)
        inside = np.flatnonzero(margin > 0)
        true = catalog_feature[hip_1991.rows(frame.true_id[inside])]
        np.testing.assert_allclose(feature[inside], true, atol=1e-4 / CAMERA.focal_px)
        checked += len(inside)
    assert checked >= 30


def test_database_nbytes_counts_the_feature_table(hip_1991):
    database = get_database(hip_1991, make_camera(width=512, height=None, fov_deg=12.0))
    feature, rows = catalog_neighbor_sums(database, 2)
    assert NeighborSum().database_nbytes(database) == (
        database.nbytes + feature.nbytes + rows.nbytes
    )


def test_bad_options_are_refused():
    for bad in ({"k": 0}, {"k": 1.5}, {"feature_tol_scale": 0.0}, {"feature_tol_scale": np.nan}):
        with pytest.raises(StarnavError):
            NeighborSum(**bad)
    with pytest.raises(StarnavError, match="k"):
        make_identifier(ALGORITHM, k=-1)
