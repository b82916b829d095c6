"""Lists in no brightness order (starnav.pipeline.unordered): the catalog depth follows the
list's density, the catalog's patterns are each star's neighbourhood, the points' each
point's with its nearest. The real photograph's list solving, and random points not, are
tested through solve_plate (tests/pipeline/test_source_lists.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from starnav.catalog import hipparcos_mags, load_catalog
from starnav.errors import StarnavError
from starnav.identify.database import catalog_only
from starnav.identify.pattern4 import build_pattern_table
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.unordered import (
    CATALOG_SHARE,
    MAG_STEP,
    density_mag_limit,
    image_sr,
    neighbour_patterns,
    solve_unordered,
)


def test_depth_follows_the_density():
    mags = hipparcos_mags()
    sr = image_sr(27.0, 1280, 960)
    depths = [density_mag_limit(n, sr, mags) for n in (60, 200, 600)]
    assert depths == sorted(depths) and depths[0] < depths[-1]
    for n, mag in zip((60, 200, 600), depths, strict=True):
        in_image = np.searchsorted(mags, mag, "right") * sr / (4.0 * math.pi)
        # the share of the points, within the rounding of the depth (0.5 mag: about x1.4-2)
        assert CATALOG_SHARE * n / 2.5 < in_image < CATALOG_SHARE * n * 2.5
        assert mag % MAG_STEP == 0.0
    deepest = density_mag_limit(10**6, sr, mags)  # no deeper than the catalog
    assert mags[-1] - MAG_STEP <= deepest <= mags[-1]


def test_local_table_holds_each_neighbourhood():
    cat = load_catalog(None, mag_limit=4.0)
    database = catalog_only(cat, math.radians(30.0))
    table = build_pattern_table(database, stars_per_field=5, local=True, use_cache=False)
    held = {tuple(sorted(row)) for row in table.stars(np.arange(len(table))).tolist()}
    from scipy.spatial import cKDTree

    _, near = cKDTree(cat.vectors).query(cat.vectors, k=5)
    for row in near[::25]:  # a star and its 3 nearest: one of its neighbourhood's patterns
        assert tuple(sorted(row[:4].tolist())) in held
    assert len(held) == len(table)  # each pattern once


def test_neighbour_patterns():
    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 500, (40, 2))
    rows = neighbour_patterns(xy, np.arange(40), 5)
    assert len({tuple(sorted(r)) for r in rows.tolist()}) == len(rows)  # each set once
    assert rows[0, 0] == 0  # the first point's patterns first
    far = np.linalg.norm(xy[rows[:, 1:]] - xy[rows[:, :1]], axis=2).max()
    assert far < 250.0  # neighbours, not points across the field
    assert len(neighbour_patterns(xy[:3], np.arange(3), 5)) == 0


def test_a_portrait_list_takes_the_narrowest_field_of_its_shape():
    """A 1080 x 1920 px list (0.5° across) is searched at its width, as its image is (0.625°
    along the longer side); the same width on a landscape list is refused in one line."""
    xy = np.random.default_rng(3).uniform((0, 0), (1080, 1920), (40, 2))
    options = SolveOptions(fov_deg=0.5, fov_exact=False, time_budget_s=1.0)
    res = solve_unordered(xy, options, width=1080, height=1920)
    assert res.solution is None and "fov_deg must be within" not in res.reason
    with pytest.raises(StarnavError, match=r"0\.625° along the image's longer side"):
        solve_unordered(xy[:, ::-1], options, width=1920, height=1080)
