"""An unsolved searched image tried again from its middle (``pipeline.image._solve_middle``),
and the stars an answer must explain: those as bright as its faintest match, where stars are
seen (``pipeline.kernels.expected_stars``)."""

import numpy as np
import pytest

import starnav.pipeline.image as image
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.image import MIDDLE_FRACTIONS, solve_image
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.stars import solve_stars
from starnav.simulate import simulate_frame
from starnav.simulate.render import RenderSettings, render_frame

R_ORION = attitude_from_radec_roll(83.8, -5.4, 30.0)


def _frame_with_bright_junk_round_the_edge(n_junk: int = 40, seed: int = 1) -> np.ndarray:
    """A rendered 20° frame with ``n_junk`` star-shaped sources brighter than any star placed
    outside its middle (hot spots, a lamp's reflections): the brightest points are not stars."""
    camera = Camera.from_fov(20.0, 1024, 768)
    frame = render_frame(load_catalog(None, mag_limit=7.5), camera, R_ORION, RenderSettings(seed=5))
    img = np.array(frame.image, dtype=np.float64)
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:768, 0:1024]
    edge = (1.0 - MIDDLE_FRACTIONS[0]) / 2.0
    placed = 0
    while placed < n_junk:
        x, y = rng.uniform(5, 1019), rng.uniform(5, 763)
        if (
            edge * 1024 - 10 < x < (1 - edge) * 1024 + 10
            and edge * 768 - 10 < y < (1 - edge) * 768 + 10
        ):
            continue
        img += 40000.0 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 1.2**2))
        placed += 1
    return np.clip(img, 0, 65535).astype(np.uint16)


def test_a_frame_whose_brightest_points_are_junk_round_the_edge_is_solved_from_its_middle(
    monkeypatch,
):
    img = _frame_with_bright_junk_round_the_edge()
    result = solve_image(img, fov_range_deg=(15.0, 25.0), time_budget_s=5.0)
    s = result.solution
    assert s is not None, result.reason
    bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R_ORION)
    assert bore < 0.01 and roll < 0.05, (bore, roll)
    assert s.fov_deg == pytest.approx(20.0, rel=2e-3)
    assert s.camera.width == 1024 and s.camera.height == 768  # the whole frame's pixels
    assert s.algorithm == "fov-search (middle)"
    # without the second look the junk takes the pattern stars' places: not solved
    monkeypatch.setattr(
        image, "_solve_middle", lambda pixels, xy, options, budget_s, failed, fraction: failed
    )
    again = solve_image(img, fov_range_deg=(15.0, 25.0), time_budget_s=5.0)
    assert again.solution is None


def test_a_shallow_list_is_held_to_the_stars_as_bright_as_its_faintest_match():
    """The 12 brightest stars of a 20° field (Hp <= 7 holds ~100 there) and 14 false points:
    before, 12 of min(26, 100) was under half and refused; the image reaches only as deep as
    the 12th star, which is all it is asked to explain."""
    catalog = load_catalog(None, mag_limit=7.0)
    camera = Camera.from_fov(20.0, 1024, 1024)
    truth = simulate_frame(catalog, camera, R_cam_from_icrs=R_ORION, seed=2)
    bright = np.argsort(truth.mag)[:12]
    assert truth.n_in_view >= 30
    rng = np.random.default_rng(3)
    xy = np.vstack([truth.xy[bright], rng.uniform(0, 1024, (14, 2))])
    options = SolveOptions(camera=camera, mag_limit=7.0, time_budget_s=30.0)
    result = solve_stars(xy, options, ranked=False)
    s = result.solution
    assert s is not None, result.reason
    assert attitude_difference_deg(s.R_cam_from_icrs, R_ORION)[0] < 0.01
    assert s.n_matched == 12


def test_stars_where_no_point_is_seen_are_not_held_against_an_answer():
    """Every star of the top quarter of a 20° field (trees hide the rest) and as many false
    points there, plus two: the whole frame's stars were held against it (under half of
    the points agree with them, refused); only those near the points now are."""
    catalog = load_catalog(None, mag_limit=7.0)
    camera = Camera.from_fov(20.0, 1024, 1024)
    truth = simulate_frame(catalog, camera, R_cam_from_icrs=R_ORION, seed=2)
    top = truth.xy[(truth.xy[:, 1] < 256) & (truth.true_id >= 0)]
    assert len(top) >= 15 and truth.n_in_view >= 3 * len(top)
    rng = np.random.default_rng(4)
    false = rng.uniform((0, 0), (1024, 256), (len(top) + 2, 2))
    options = SolveOptions(camera=camera, mag_limit=7.0, time_budget_s=30.0)
    result = solve_stars(np.vstack([top, false]), options, ranked=False)
    s = result.solution
    assert s is not None, result.reason
    assert attitude_difference_deg(s.R_cam_from_icrs, R_ORION)[0] < 0.01
    assert s.n_matched == len(top)
