"""Liebe's triangle method: the published triangle orders, the optimized selection, the
triangle limit. (Identification on simulated frames: test_identify_algorithms.py.)"""

from itertools import combinations

import numpy as np
import pytest

import starnav
from starnav.api import get_database, make_camera
from starnav.camera import Camera
from starnav.errors import StarnavError
from starnav.geometry import attitude_difference_deg
from starnav.identify import MatchSettings, make_identifier
from starnav.identify.triangle import (
    Triangle,
    bad_triangles,
    brightness_triangles,
    select_triangles,
    triangle_shape_px,
)
from starnav.simulate import simulate_frame


def test_brightest_order_is_the_published_one():
    """1-2-3, 1-2-4, ... over the 6 brightest (20 triangles), then the 7th star's, ..."""
    t = brightness_triangles(8).tolist()
    assert [tuple(r) for r in t[:20]] == list(combinations(range(6), 3))
    assert t[:3] == [[0, 1, 2], [0, 1, 3], [0, 1, 4]]
    assert [tuple(r) for r in t[20:35]] == [(i, j, 6) for i, j in combinations(range(6), 2)]
    assert all(r[2] == 7 for r in t[35:])
    assert len(t) == 56 and len({tuple(r) for r in t}) == 56
    assert brightness_triangles(4).tolist() == [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]


def test_triangle_shape_and_badness():
    pts = np.array([[0.0, 0.0], [30.0, 0.0], [0.0, 40.0]])
    shortest, height = triangle_shape_px(pts, np.array([[0, 1, 2]]))
    # sides 30, 40, 50: the height over the longest side is 30 * 40 / 50
    assert shortest[0] == pytest.approx(30.0) and height[0] == pytest.approx(24.0)
    flat = np.array([[0.0, 0.0], [200.0, 0.0], [100.0, 3.9]])
    short = np.array([[0.0, 0.0], [9.9, 0.0], [100.0, 100.0]])
    ok = np.array([[0.0, 0.0], [200.0, 0.0], [100.0, 4.1]])
    tri = np.array([[0, 1, 2]])
    assert bad_triangles(flat, tri)[0] and bad_triangles(short, tri)[0]
    assert not bad_triangles(ok, tri)[0]
    assert not bad_triangles(flat, tri, min_height_px=3.0)[0]


def test_optimized_selection_drops_the_dimmer_double_and_skips_flat_triangles():
    # star 1 is 5 px from the brighter star 0; star 3 lies 2 px off the line 0-2
    pts = np.array([[0.0, 0.0], [5.0, 0.0], [200.0, 0.0], [100.0, 2.0], [50.0, 150.0]])
    brightest, n_good = select_triangles(pts, "brightest")
    assert brightest[0].tolist() == [0, 1, 2] and n_good == len(brightest) == 10
    optimized, n_good = select_triangles(pts, "optimized")
    # kept stars 0, 2, 3, 4: 0-2-3 is flat, so 0-2-4 comes first
    assert optimized[:n_good].tolist() == [[0, 2, 4], [0, 3, 4], [2, 3, 4]]
    # the rest follow as a fallback: every triangle exactly once
    assert sorted(map(tuple, optimized.tolist())) == sorted(map(tuple, brightest.tolist()))


def test_bad_options_are_refused(hip_1991):
    for bad in ({"selection": "dimmest"}, {"max_triangles": 0}, {"max_triangles": 1.5}):
        with pytest.raises(StarnavError):
            Triangle(**bad)
    with pytest.raises(StarnavError, match="dimmest"):
        make_identifier("triangle", selection="dimmest")
    with pytest.raises(StarnavError, match="selection"):
        select_triangles(np.zeros((3, 2)), "dimmest")
    xy = np.array([[10.0, 10.0], [100.0, 300.0], [400.0, 50.0]])
    with pytest.raises(StarnavError):
        starnav.solve(
            xy,
            width=512,
            fov_deg=12.0,
            catalog=hip_1991,
            algorithm="triangle",
            algorithm_options={"selection": "nope"},
        )


def test_max_triangles_limits_the_brightest_search(hip_1991):
    """A false star as the brightest point spoils the first 10 triangles (0-1-2 ... 0-4-5) of
    the brightest order: 10 tries find nothing, 11 reach 1-2-3 and solve."""
    cam = Camera.from_fov(12.0, 512)
    f = simulate_frame(
        hip_1991, cam, ra_deg=120.0, dec_deg=30.0, roll_deg=40.0, noise_px=0.2, seed=7
    )  # seeded: unseeded noise made 1-2-3 miss the verification now and then
    assert len(f.xy) >= 8
    xy = np.vstack([[[317.0, 211.0]], f.xy])  # the false star, listed first = brightest
    camera = make_camera(width=512, height=None, fov_deg=12.0)
    database = get_database(hip_1991, camera)
    settings = MatchSettings(
        pair_tol_rad=1.0 / camera.focal_px,
        match_radius_rad=1.0 / camera.focal_px,
        sigmas_rad=(0.2 / camera.focal_px,),
        pixel_rad=1.0 / camera.focal_px,
    )
    bearings = camera.pixels_to_bearings(xy)
    order = np.arange(len(xy))

    def identify(**options):
        return Triangle(selection="brightest", **options).identify(
            bearings, order, database, settings
        )

    assert identify(max_triangles=10).identification is None
    found = identify(max_triangles=11).identification
    assert found is not None and 0 not in found.obs_index
    assert attitude_difference_deg(found.R_cam_from_icrs, f.R_cam_from_icrs)[0] < 0.05
    assert identify().identification is not None
    # the optimized selection finds it the same way (the false star is not flat or double)
    assert Triangle(max_triangles=11).identify(bearings, order, database, settings).identification
