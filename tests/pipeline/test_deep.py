"""The deep stage (``starnav.pipeline.deep``): faint stars matched to a deep catalog after
the fit, unresolved doubles, per-star match probabilities, ``--deep-mag-limit``."""

import json

import numpy as np
import pytest

from cli_helpers import run_cli
from starnav import api
from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.errors import StarnavError
from starnav.geometry import attitude_from_radec_roll, unit_to_radec
from starnav.pipeline.deep import DEEP_OFF, deep_match, match_probability
from starnav.pipeline.fov import known_field_depth
from starnav.pipeline.options import SolveOptions
from starnav.results import Solution, StarTable
from starnav.simulate import FALSE_STAR_ID, simulate_frame
from starnav.starlist import StarList

CAMERA = Camera.from_fov(6.0, 1024, 1024)  # a star tracker's field
R = attitude_from_radec_roll(83.8, -5.4, 30.0, 1)
BRIGHT_MAG = 8.0  # the pair table's catalog
DEEP_MAG = 12.0


@pytest.fixture(scope="module")
def frame():
    """A 6° frame of the stars to Hp 10.3, 0.5 px noise, 2 false stars, 10 % missing."""
    deep = load_catalog(None, mag_limit=DEEP_MAG)
    return simulate_frame(
        deep,
        CAMERA,
        R_cam_from_icrs=R,
        mag_limit=10.3,
        noise_px=0.5,
        false_stars=2,
        missing_frac=0.1,
        seed=1,
    )


def _solve(frame, deep_mag_limit):
    return api.solve_stars(
        frame.xy,
        width=1024,
        fov_deg=6.0,
        brightness=frame.brightness,
        mag_limit=BRIGHT_MAG,
        sigma_px=0.5,
        deep_mag_limit=deep_mag_limit,
        time_budget_s=30.0,
    )


@pytest.mark.slow
def test_deep_stage_identifies_stars_fainter_than_the_bright_catalog(frame):
    bright = _solve(frame, "off").solution
    deep = _solve(frame, DEEP_MAG).solution
    true_id = frame.true_id
    real = true_id != FALSE_STAR_ID
    ids = deep.star_table.catalog_id
    cat = load_catalog(None, mag_limit=DEEP_MAG)
    mag = np.where(real, cat.mag[cat.rows(np.where(real, true_id, cat.ids[0]))], np.nan)
    faint = real & (mag > BRIGHT_MAG + 0.5)
    assert faint.sum() > 40
    assert np.all(bright.star_table.catalog_id[faint] == -1)  # not in the bright catalog
    assert np.mean(ids[faint] == true_id[faint]) > 0.97
    assert np.sum((ids >= 0) & (ids != true_id)) == 0  # no wrong id
    assert deep.n_matched == int(np.sum(ids >= 0)) > bright.n_matched
    # the bright identification's stars keep their ids
    held = bright.star_table.catalog_id >= 0
    assert np.array_equal(ids[held], bright.star_table.catalog_id[held])
    p = deep.star_table.match_probability
    assert np.all(np.isnan(p[ids < 0])) and np.all((p[ids >= 0] >= 0) & (p[ids >= 0] <= 1))
    assert np.median(p[ids >= 0]) > 0.99
    stars = deep.to_dict()["stars"]
    assert set(stars[0]) == {
        "label",
        "x",
        "y",
        "catalog_id",
        "residual_px",
        "match_probability",
        "double",
    }
    assert set(bright.to_dict()["stars"][0]) == {"label", "x", "y", "catalog_id", "residual_px"}


def _catalog(px: list[tuple[float, float]], mags: list[float], crowd: int = 0) -> Catalog:
    """Stars at these pixels of ``CAMERA`` at attitude ``R`` (ids 1, 2, ...), then ``crowd``
    Hp 11.5 stars elsewhere in the image (none within 6 px of those) and a few far ones."""
    px = np.asarray(px, dtype=float)
    others = np.random.default_rng(3).uniform(0.0, 1024.0, (crowd, 2))
    apart = np.min(np.linalg.norm(others[:, None] - px[None], axis=2), axis=1) > 6.0
    others = others[apart] if crowd else others
    mags = np.concatenate([mags, np.full(len(others), 11.5)])
    v = CAMERA.pixels_to_bearings(np.concatenate([px, others])) @ R
    ra, dec = unit_to_radec(v)
    ra_deg = np.concatenate([np.degrees(ra) % 360.0, [10.0, 200.0, 300.0]])
    dec_deg = np.concatenate([np.degrees(dec), [40.0, -30.0, 70.0]])
    mag = np.concatenate([mags, [5.0, 5.0, 5.0]])
    ids = np.arange(1, len(mag) + 1)
    return Catalog(ids, ra_deg, dec_deg, mag, "test")


def _unsolved_table(xy: np.ndarray, ids: np.ndarray | None = None) -> Solution:
    """A solution at ``R`` through ``CAMERA`` with points ``xy`` (ids: none, or given)."""
    n = len(xy)
    ids = np.full(n, -1, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64)
    table = StarTable(tuple(str(i + 1) for i in range(n)), xy, ids, np.full(n, np.nan))
    return Solution(
        ra_deg=83.8,
        dec_deg=-5.4,
        roll_deg=30.0,
        parity=1,
        focal_px=CAMERA.focal_px,
        fov_deg=CAMERA.fov_deg,
        rms_px=float("nan"),
        sigma_boresight_arcsec=1.0,
        sigma_roll_arcsec=1.0,
        sigma_focal_px=0.0,
        false_match_probability=1e-9,
        time_ms=0.0,
        R_cam_from_icrs=R,
        star_table=table,
        n_matched=int(np.sum(ids >= 0)),
        algorithm="test",
        catalog="test",
        camera=CAMERA,
    )


def _deep(xy, catalog, ids=None, sigma_px=0.5, mag=None) -> StarTable:
    xy = np.asarray(xy, dtype=float)
    brightness = None if mag is None else 10.0 ** (-0.4 * np.asarray(mag, dtype=float))
    stars = StarList(xy, tuple(str(i + 1) for i in range(len(xy))), brightness)
    return deep_match(_unsolved_table(xy, ids), stars, catalog, sigma_px=sigma_px).star_table


def test_unresolved_double_gets_the_brighter_star_and_the_flag():
    # one point at the photocentre of a 1 px double (Hp 9 and 10.5), one single star
    cat = _catalog([(500.0, 500.0), (501.0, 500.0), (200.0, 300.0)], [9.0, 10.5, 10.0])
    table = _deep([(500.2, 500.0), (200.1, 299.9)], cat)
    assert table.catalog_id.tolist() == [1, 3]
    assert table.double.tolist() == [True, False]
    # the fainter star is nearer the centroid (noise), the brighter still within the rule
    table = _deep([(500.55, 500.0)], cat)
    assert table.catalog_id.tolist() == [1] and table.double.tolist() == [True]


def test_a_point_clearly_on_the_fainter_star_of_a_double_keeps_it():
    # a faint star measured exactly; its brighter neighbour 1.9 px away was not detected
    cat = _catalog([(500.0, 500.0), (501.9, 500.0)], [11.0, 8.5])
    table = _deep([(500.0, 500.05)], cat)
    assert table.catalog_id.tolist() == [1] and table.double.tolist() == [True]


def test_two_points_near_two_stars_2px_apart_are_never_swapped():
    # the brighter star B is the nearer to neither point only by a little: a brightest-star
    # rule applied point by point would give B to both, a greedy nearest one could swap
    cat = _catalog([(500.0, 500.0), (502.0, 500.0)], [10.5, 9.0])
    for p1, p2 in [
        ((500.7, 500.0), (501.3, 500.0)),
        ((500.9, 500.3), (501.2, 499.8)),
        ((499.6, 500.2), (502.4, 499.9)),
    ]:
        table = _deep([p1, p2], cat)
        assert table.catalog_id.tolist() == [1, 2]
        assert table.double.tolist() == [False, False]
    # the same with one of them identified by the bright stage: it keeps its star
    table = _deep([(500.7, 500.0), (501.3, 500.0)], cat, ids=[-1, 2])
    assert table.catalog_id.tolist() == [1, 2]


def test_a_bright_id_changes_only_when_the_deep_match_is_clearly_better():
    # the bright stage (Hp 8) gave the Hp 7.7 star A to the point of its Hp 9.7 neighbour
    # B, 0.9 px away, which the bright catalog lacks; 8 single stars fit the brightness
    singles = [(100.0 + 90.0 * i, 800.0) for i in range(8)]
    mag = [7.7, 9.7, *np.linspace(6.0, 10.0, 8)]
    cat = _catalog([(500.0, 500.0), (500.9, 500.0), *singles], mag)
    xy = [(500.5, 500.0), (500.4, 500.0), *singles]
    ids = [-1, 1] + [-1] * 8
    # positions alone: either way is as likely, the bright id stays
    assert _deep(xy, cat, ids=ids).catalog_id[:2].tolist() == [2, 1]
    # the brightness says which is which: 20 times more likely (and far more), so changed
    assert _deep(xy, cat, ids=ids, mag=mag).catalog_id[:2].tolist() == [1, 2]


def test_match_probability_high_for_a_clean_match_low_for_a_far_one():
    p = match_probability(np.array([0.05, 0.5, 2.5, np.nan]), 0.5, 3e-4)
    assert np.all((p[:3] >= 0) & (p[:3] <= 1)) and np.isnan(p[3])
    assert p[0] > 0.999 and p[1] > 0.99 and p[2] < 0.05
    # through the stage: a star 0.1 px off and one 1.9 px off (sigma 0.5 px, circle 2 px)
    # in a crowded field (3 stars per 1000 px^2)
    cat = _catalog([(300.0, 300.0), (700.0, 700.0)], [10.0, 10.0], crowd=3000)
    table = _deep([(300.1, 300.0), (701.9, 700.0)], cat)
    assert table.catalog_id.tolist() == [1, 2]
    assert table.match_probability[0] > 0.99 and table.match_probability[1] < 0.5
    assert table.match_probability[1] < table.match_probability[0]


def test_bad_deep_mag_limit_is_a_one_line_error():
    xy = np.arange(10.0).reshape(5, 2)
    with pytest.raises(StarnavError, match="deep_mag_limit"):
        api.solve_stars(xy, width=512, fov_deg=6.0, deep_mag_limit=99.0)


@pytest.mark.slow
def test_cli_deep_mag_limit(capsys, tmp_path, frame):
    path = tmp_path / "stars.csv"
    points = zip(frame.xy, frame.mag, strict=True)
    rows = "".join(f"{x:.3f},{y:.3f},{m:.3f}\n" for (x, y), m in points)
    path.write_text("x,y,mag\n" + rows)
    base = ["identify", str(path), "--fov-deg", "6", "--width", "1024", "--sigma-px", "0.5"]
    base += ["--mag-limit", str(BRIGHT_MAG), "--time-budget", "30"]
    code, out, err = run_cli(capsys, *base, "--deep-mag-limit", "12", "--json")
    assert code == 0, err
    result = json.loads(out)
    ids = np.array([-1 if s["catalog_id"] is None else s["catalog_id"] for s in result["stars"]])
    real = frame.true_id != FALSE_STAR_ID
    assert np.mean(ids[real] == frame.true_id[real]) > 0.97
    assert all(0.0 <= s["match_probability"] <= 1.0 for s in result["stars"] if s["catalog_id"])
    code, out, _ = run_cli(capsys, *base, "--deep-mag-limit", "12")
    assert code == 0 and "match_probability" in out
    for bad in ("abc", "40"):
        code, out, err = run_cli(capsys, *base, "--deep-mag-limit", bad)
        assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
        assert "deep-mag-limit" in err or "deep_mag_limit" in err


def test_cli_solve_takes_deep_mag_limit(capsys, tmp_path):
    image = tmp_path / "frame.png"
    image.write_bytes(b"")  # never read: the bad value is refused first
    code, out, err = run_cli(capsys, "solve", str(image), "--deep-mag-limit", "abc")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "--deep-mag-limit" in err


# ---------------------------------------------------------------------------------------------
# the depths a known field gets by default (``pipeline.fov.known_field_depth``)


@pytest.mark.parametrize(
    ("fov_deg", "width", "height", "expected"),
    [
        (6.1, 1392, 1040, (8.5, DEEP_MAG)),  # a Kelvins-format star tracker
        (6.0, 1024, 1024, (8.25, DEEP_MAG)),
        (8.0, 1024, 1024, (7.5, None)),  # 1 point in 110 would land on a chance Hp 12 star
        (10.0, 1024, 1024, (7.25, None)),  # Hp 6: 11 stars in an average image
        (12.0, 512, 512, (6.0, None)),  # Hp 6: 16 stars, enough
        (60.0, 1024, 1024, (6.0, None)),
    ],
)
def test_known_field_depth_follows_the_field(fov_deg, width, height, expected):
    camera = Camera.from_fov(fov_deg, width, height)
    assert known_field_depth(camera, SolveOptions(fov_deg=fov_deg)) == expected


def test_known_field_depth_keeps_what_it_is_told():
    camera = Camera.from_fov(6.1, 1392, 1040)
    told = SolveOptions(fov_deg=6.1, mag_limit=7.0, deep_mag_limit=DEEP_OFF)
    assert known_field_depth(camera, told) == (7.0, DEEP_OFF)
    catalog = load_catalog(None, mag_limit=6.0)
    assert known_field_depth(camera, SolveOptions(fov_deg=6.1, catalog=catalog)) == (None, None)
    # a coarser centroid told: a wider match circle, no deep stage by default
    assert known_field_depth(camera, SolveOptions(fov_deg=6.1, sigma_px=3.0))[1] is None


@pytest.fixture(scope="module")
def tracker_frame():
    """A Kelvins-format frame: 1392 x 1040 px, 6.1°, the stars to Hp 10.3, 0.3 px and
    0.3 mag noise, 3 false stars, 10 % missing."""
    return simulate_frame(
        load_catalog(None, mag_limit=10.3),
        Camera.from_fov(6.1, 1392, 1040),
        R_cam_from_icrs=attitude_from_radec_roll(210.0, 40.0, 75.0, 1),  # far from the plane
        noise_px=0.3,
        mag_noise=0.3,
        false_stars=3,
        missing_frac=0.1,
        seed=35,
    )


def test_a_6_degree_tracker_is_solved_at_default_options(tracker_frame):
    """Given only the field, the catalog depths follow it; told the old defaults (Hp 6, no
    deep stage) the same frame holds too few catalog stars to be solved."""
    f = tracker_frame
    s = api.solve_stars(f.xy, width=1392, height=1040, fov_deg=6.1, brightness=f.brightness)
    assert s.solution is not None, s.reason
    table = s.solution.star_table
    assert table.deep
    real = f.true_id != FALSE_STAR_ID
    assert np.mean(table.catalog_id[real] == f.true_id[real]) > 0.97
    assert not np.any(table.catalog_id[~real] != -1)  # no false star named
    right = table.catalog_id[real] == f.true_id[real]
    assert np.all(table.match_probability[real][right] > 0.5)
    old = api.solve_stars(
        f.xy, width=1392, height=1040, fov_deg=6.1, brightness=f.brightness,
        mag_limit=6.0, deep_mag_limit="off",
    )  # fmt: skip
    assert old.solution is None


def test_cli_deep_mag_limit_off(capsys, tmp_path, tracker_frame):
    path = tmp_path / "stars.csv"
    path.write_text("x,y\n" + "".join(f"{x:.3f},{y:.3f}\n" for x, y in tracker_frame.xy))
    base = ["identify", str(path), "--fov-deg", "6.1", "--width", "1392", "--height", "1040"]
    code, out, err = run_cli(capsys, *base, "--json")
    assert code == 0, err
    assert all("match_probability" in s for s in json.loads(out)["stars"])
    code, out, err = run_cli(capsys, *base, "--deep-mag-limit", "OFF", "--json")
    assert code in (0, 1), err
    assert not any("match_probability" in s for s in json.loads(out)["stars"])
