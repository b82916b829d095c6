"""Solving with the field of view unknown, roughly known or calibrated (centroid level)."""

import itertools
import json

import numpy as np
import pytest

from shared_data import CONTEST
from starnav.api import solve_stars
from starnav.camera import Camera, load_camera, save_camera
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.errors import CameraError, StarnavError
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.identify.pattern4 import catalog_nbytes
from starnav.pipeline.fov import band_grid, band_stars_per_field, load_bands
from starnav.pipeline.image import solve_image
from starnav.pipeline.options import DEFAULT_FOV_RANGE_DEG
from starnav.simulate import simulate_frame
from starnav.simulate.render import RenderSettings, render_frame


@pytest.fixture(scope="module")
def sky():
    return load_catalog(None, mag_limit=7.5)


def test_band_grid_covers_the_range_on_the_fixed_grid():
    bands = band_grid(5.0, 40.0)
    assert bands[0][1] == pytest.approx(40.0) and bands[-1][0] == pytest.approx(5.0)
    for (lo, hi, top), nxt in itertools.pairwise(bands):
        assert nxt[1] == pytest.approx(lo)  # contiguous, widest first
        assert lo < hi <= top
    # any sub-range uses the same grid bands (so their tables are shared)
    tops = {round(t, 6) for _, _, t in bands}
    assert {round(t, 6) for _, _, t in band_grid(11.0, 13.0)} <= tops
    assert len(band_grid(19.0, 21.0)) == 2  # 20° is a grid edge


@pytest.mark.slow
def test_the_10_to_30_degree_tables_fit_in_20_mb():
    """Issue 8: what the search holds in memory for a 10-30° range on a 1024 px square image
    (pattern tables, catalogs, KD-trees) is at most 20 MB; ranges sharing grid bands share
    their tables and catalogs."""
    bands = load_bands(10.0, 30.0, 1024, 1024, None, None)
    assert len(bands) == 4
    for band in bands:
        assert band.catalog is band.database.catalog
        assert band.nbytes == band.table.nbytes + catalog_nbytes(band.database)
    assert sum(band.nbytes for band in bands) <= 20e6
    narrower = load_bands(12.0, 25.0, 1024, 1024, None, None)
    held = {(id(band.table), id(band.catalog)) for band in bands}
    assert {(id(band.table), id(band.catalog)) for band in narrower} <= held


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fov", "width", "seed"), [(8.0, 1024, 1), (20.0, 1024, 2), (33.0, 800, 3)]
)
def test_unknown_fov_is_found_and_fitted(sky, fov, width, seed):
    camera = Camera.from_fov(fov, width, width * 3 // 4)
    hits = 0
    for k in range(3):
        frame = simulate_frame(sky, camera, noise_px=0.2, false_stars=2, seed=seed * 10 + k)
        res = solve_stars(
            frame.xy,
            fov_exact=False,
            width=camera.width,
            height=camera.height,
            brightness=frame.brightness,
        )
        if res.solution is None:
            continue
        s = res.solution
        bore, roll = attitude_difference_deg(s.R_cam_from_icrs, frame.R_cam_from_icrs)
        assert bore < 0.01 and roll < 0.1, (bore, roll)
        assert s.fov_deg == pytest.approx(fov, rel=1e-3)
        assert s.algorithm == "fov-search"
        hits += 1
    assert hits >= 2


def test_given_fov_a_few_percent_off_is_refined(sky):
    camera = Camera.from_fov(15.0, 1024)
    frame = simulate_frame(sky, camera, noise_px=0.1, seed=7)
    res = solve_stars(
        frame.xy, fov_exact=False, width=1024, brightness=frame.brightness, fov_deg=15.0 * 1.03
    )
    assert res.solution is not None
    assert res.solution.fov_deg == pytest.approx(15.0, rel=5e-4)


@pytest.mark.slow
def test_out_of_range_fov_is_not_found(sky):
    camera = Camera.from_fov(20.0, 1024)
    frame = simulate_frame(sky, camera, noise_px=0.1, seed=8)
    res = solve_stars(
        frame.xy, fov_exact=False, width=1024, brightness=frame.brightness, fov_range_deg=(5, 10)
    )
    assert res.solution is None and res.reason


@pytest.mark.slow
def test_random_points_are_not_solved():
    rng = np.random.default_rng(5)
    for _ in range(3):
        xy = rng.uniform(0, 1024, (30, 2))
        assert solve_stars(xy, fov_exact=False, width=1024).solution is None


def test_distortion_is_fitted_on_request(sky):
    camera = Camera(1024, 1024, Camera.from_fov(30.0, 1024).focal_px, k1=-0.06)
    frame = simulate_frame(sky, camera, noise_px=0.1, seed=11)
    res = solve_stars(
        frame.xy,
        fov_exact=False,
        width=1024,
        brightness=frame.brightness,
        fov_range_deg=(25, 35),
        fit_distortion=True,
    )
    s = res.solution
    assert s is not None
    assert s.k1 == pytest.approx(-0.06, abs=0.01)
    assert s.rms_px < 0.3
    bore, _ = attitude_difference_deg(s.R_cam_from_icrs, frame.R_cam_from_icrs)
    assert bore < 0.005


def test_calibrated_camera_takes_the_distortion_out(sky, tmp_path):
    camera = Camera(1024, 768, 1800.0, 520.0, 380.0, k1=-0.05)
    path = tmp_path / "cam.json"
    save_camera(path, camera, rms_px=0.1)
    loaded = load_camera(path)
    assert loaded == camera
    frame = simulate_frame(sky, camera, noise_px=0.1, seed=12)
    s = solve_stars(
        frame.xy, fov_exact=False, width=1024, brightness=frame.brightness, camera=loaded
    ).solution
    assert s is not None and s.k1 == -0.05 and s.rms_px < 0.3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{", "not readable JSON"),
        ("[1]", "JSON object"),
        ('{"width": 10}', "lacks"),
        (
            '{"width": 10, "height": 10, "focal_px": "x", "cx": 5, "cy": 5, "k1": 0, "k2": 0}',
            "focal_px must be a number",
        ),
    ],
)
def test_bad_camera_files_are_one_line_errors(tmp_path, text, message):
    path = tmp_path / "cam.json"
    path.write_text(text)
    with pytest.raises(CameraError, match=message):
        load_camera(path)
    with pytest.raises(CameraError, match="does not exist"):
        load_camera(tmp_path / "missing.json")


@pytest.mark.parametrize("bad", [(40, 5), (0.1, 10), ("a", 3), (5,)])
def test_bad_fov_range(bad):
    with pytest.raises(StarnavError, match="fov"):
        solve_stars(np.zeros((5, 2)) + 10, width=100, fov_range_deg=bad)


@pytest.mark.slow
def test_identify_command_without_fov_matches_the_known_fov_answer(capsys):
    base = [
        "identify",
        str(CONTEST / "images" / "xingtu01.csv"),
        *("--width", "512", "--catalog", str(CONTEST / "catalog.csv"), "--json"),
    ]
    assert main(base) == 0
    unknown = json.loads(capsys.readouterr().out)
    assert main([*base, "--fov-deg", "12"]) == 0
    known = json.loads(capsys.readouterr().out)
    assert unknown["fov_deg"] == pytest.approx(12.0, rel=1e-4)
    assert unknown["algorithm"] == "fov-search"
    ids = {s["label"]: s["catalog_id"] for s in unknown["stars"]}
    assert ids == {s["label"]: s["catalog_id"] for s in known["stars"]}


def test_a_catalog_too_sparse_for_any_pattern_is_a_one_line_error(tmp_path, capsys):
    cat = tmp_path / "three.csv"
    cat.write_text("id,ra_deg,dec_deg,mag\n" + "".join(f"{k},{10 * k},5,{k}\n" for k in range(3)))
    stars = tmp_path / "stars.csv"
    stars.write_text("x,y\n10,10\n100,50\n300,200\n400,400\n250,100\n")
    code = main(["identify", str(stars), "--width", "512", "--catalog", str(cat)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no 4-star pattern" in err


@pytest.mark.slow
def test_csv_catalog_sets_its_own_band_depths(capsys):
    # the contest catalog (to mag 6) for a 20° map searched over 15-40°: every band's depth
    # comes from this catalog's own counts
    args = ["identify", str(CONTEST / "images" / "xingtu07.csv"), "--width", "1024"]
    args += ["--catalog", str(CONTEST / "catalog.csv"), "--fov-range", "15", "40", "--json"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fov_deg"] == pytest.approx(20.0, rel=1e-4)


def test_a_diagonal_beyond_the_search_limit_is_refused():
    with pytest.raises(StarnavError, match="diagonal"):
        xy = np.column_stack([np.full(5, 50.0), np.arange(5) * 300.0 + 10])
        solve_stars(xy, fov_exact=False, width=100, height=2000, fov_range_deg=(50, 100))


MAP1 = str(CONTEST / "images" / "xingtu01.csv")


@pytest.mark.parametrize(
    "args",
    [
        ["render", "-o", "{tmp}/a.png", "--truth", "{tmp}/missing/dir/t.csv", "--seed", "1"],
        ["render", "-o", "{tmp}/a.png", "--fov-deg", "0"],
        ["identify", MAP1, "--width", "512", "--mag-limit", "5"],
    ],
)
def test_more_bad_input_is_one_line_exit_2(tmp_path, capsys, args):
    code = main([a.format(tmp=tmp_path) for a in args])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err


def test_narrow_bands_take_fewer_stars_per_field_and_the_default_range_none_of_them():
    """Issue 15: tables below 10° take one pattern star fewer per grid step, so each stays
    within 30-50 MB; the default range reaches none of them (no narrow table is built)."""
    assert [band_stars_per_field(d) for d in (56.57, 20.0, 10.0, 7.0711, 5.0, 3.5355)] == [
        10,
        10,
        10,
        9,
        8,
        7,
    ]
    lo, hi = DEFAULT_FOV_RANGE_DEG
    diag = [v * 2**0.5 for v in (lo, hi)]  # a square image, small-angle diagonal
    assert min(top for _, _, top in band_grid(*diag)) == pytest.approx(10.0)


@pytest.mark.slow
def test_a_3_degree_rendered_field_is_solved_with_the_fov_unknown():
    """Issue 15: a 3° field (1024 px, stars detected to about Hp 9.5, fainter than the band
    catalog's Hp 8.5) solved with the FOV searched over 3-3.5° (the 5° grid band)."""
    camera = Camera.from_fov(3.0, 1024)
    R = attitude_from_radec_roll(84.0, -2.0, 30.0)  # Orion, galactic latitude -17°
    settings = RenderSettings(exposure_s=0.5, seed=3)
    frame = render_frame(load_catalog(None, mag_limit=9.5), camera, R, settings)
    res = solve_image(frame.image, fov_range_deg=(3.0, 3.5))
    s = res.solution
    assert s is not None, res.reason
    bore, roll = attitude_difference_deg(s.R_cam_from_icrs, R)
    assert bore * 3600 < 5.0 and roll < 0.05, (bore, roll)
    assert s.fov_deg == pytest.approx(3.0, rel=1e-3)
    assert s.parity == 1 and len(s.stars) >= 8


def test_a_field_below_the_limit_is_a_one_line_error_saying_why(capsys):
    code = main(["identify", MAP1, "--width", "512", "--fov-range", "0.5", "10"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "narrower than 0.625°" not in err and "0.625° along the image's longer side" in err
    assert "Gaia DR3" in err
    xy = np.zeros((5, 2)) + 10
    for fov in ({"fov_range_deg": (0.6, 10)}, {"fov_deg": 0.5}):
        with pytest.raises(StarnavError, match="embedded Gaia DR3 catalog, G <= 10, holds"):
            solve_stars(xy, fov_exact=False, width=100, **fov)


def test_a_band_searches_a_quarter_step_into_the_next_wider_one():
    """A field at the bottom of a band has half the pattern stars of the band's table fields;
    the next narrower band's deeper table finds it: its focal-length cells reach
    ``BAND_OVERLAP`` (2^0.25) above its own top (a 6.1° star-tracker frame at Polaris was
    solved only with --fov-range 3 40 before)."""
    from starnav.camera import focal_px_from_fov
    from starnav.pipeline.fov_search import BAND_OVERLAP, _cells

    width, height = 1392, 1040
    bands = load_bands(*DEFAULT_FOV_RANGE_DEG, width, height, None, None)
    focal_range = (focal_px_from_fov(40.0, width), focal_px_from_fov(5.0, width))
    narrowest = bands[-1]
    cells = _cells(narrowest, width, np.hypot(width, height) / 2, focal_range)
    f_low_edge = min(f * np.exp(-d) for f, d, _ in cells)
    assert f_low_edge == pytest.approx(
        focal_px_from_fov(narrowest.fov_hi_deg * BAND_OVERLAP, width), rel=1e-9
    )
    assert narrowest.fov_hi_deg * BAND_OVERLAP > 6.08 > narrowest.fov_hi_deg


def test_a_wide_field_outside_the_default_range_is_found_next():
    """With no range given, 40-70° is searched when 5-40° finds nothing (then 0.625-5°), in what
    the budget left; with a range given, only that range is."""
    sky = load_catalog(None, mag_limit=7.0)
    camera = Camera.from_fov(50.0, 1024, 768)
    R = attitude_from_radec_roll(83.8, -5.4, 30.0, 1)
    frame = render_frame(sky, camera, R, RenderSettings(seed=3))
    res = solve_image(frame.image)
    assert res.solution is not None, res.reason
    assert res.solution.fov_deg == pytest.approx(50.0, rel=2e-3)
    bore, _ = attitude_difference_deg(res.solution.R_cam_from_icrs, R)
    assert bore * 3600 < 30
    given = solve_image(frame.image, fov_range_deg=DEFAULT_FOV_RANGE_DEG)
    assert given.solution is None and "40-70" not in given.reason
    assert given.failure is not None
