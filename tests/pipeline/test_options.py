"""One options object for every entry: ``SolveOptions`` checked once, overridden by keywords,
the old entry names kept as deprecated aliases giving the same answers, results that print
short, batch errors as data."""

import math
import warnings

import numpy as np
import pytest

import starnav
from shared_data import CONTEST
from starnav import SolveOptions, StarnavError
from starnav.catalog import load_catalog
from starnav.cli import main
from starnav.starlist import read_star_csv

CATALOG = CONTEST / "catalog.csv"
MAP1 = CONTEST / "images" / "xingtu01.csv"


@pytest.fixture(scope="module")
def map1():
    return read_star_csv(MAP1)


@pytest.mark.parametrize(
    ("fields", "needle"),
    [
        ({"sigma_px": float("nan")}, "sigma_px must be a positive number of pixels, got nan"),
        ({"sigma_px": np.float64(-1.0)}, "got -1.0$"),
        ({"parity": 2}, "parity must be"),
        ({"max_false_match_probability": 1.5}, "max_false_match_probability"),
        ({"min_matched_fraction": -0.1}, "min_matched_fraction"),
        ({"prior_sigma_deg": 0.0}, "prior_sigma_deg"),
        ({"time_budget_s": -1.0}, "time_budget_s"),
        ({"lens": "fishy"}, "unknown lens model 'fishy'"),
        ({"algorithm": "magic"}, "unknown algorithm 'magic'"),
        ({"max_stars": 2}, "max_stars"),
        ({"downsample": 0}, "downsample"),
        ({"camera": 12.0}, "camera must be a camera model or a camera file, got a float"),
    ],
)
def test_bad_options_are_refused_once_with_the_value(fields, needle):
    with pytest.raises(StarnavError, match=needle):
        SolveOptions(**fields)


def test_make_overrides_fields_and_names_an_unknown_option():
    base = SolveOptions(fov_deg=12.0, sigma_px=0.5)
    made = SolveOptions.make(base, sigma_px=0.3)
    assert made.fov_deg == 12.0 and made.sigma_px == 0.3 and base.sigma_px == 0.5
    assert SolveOptions.make(base) is base
    with pytest.raises(StarnavError, match=r"unknown solve option: sigma$"):
        SolveOptions.make(base, sigma=1.0)
    with pytest.raises(StarnavError, match="options must be a SolveOptions"):
        SolveOptions.make({"fov_deg": 12.0})
    with pytest.raises(Exception, match=r"frozen|cannot assign"):
        base.fov_deg = 3.0  # type: ignore[misc]


def test_the_lens_decides_its_own_search_range():
    assert SolveOptions().search_range_deg == (5.0, 40.0)
    assert SolveOptions(lens="equidistant").search_range_deg == (100.0, 200.0)
    assert SolveOptions(lens="equidistant", fov_range_deg=[100, 180]).search_range_deg == (
        100,
        180,
    )
    assert SolveOptions(lens="equisolid").scans_focal and not SolveOptions().scans_focal


def test_one_options_object_gives_what_keywords_give(map1):
    options = SolveOptions(fov_deg=12.0, catalog=CATALOG, sigma_px=0.5)
    a = starnav.solve_stars(map1.xy, options, width=512)
    b = starnav.solve_stars(map1.xy, width=512, fov_deg=12.0, catalog=CATALOG, sigma_px=0.5)
    c = starnav.solve_stars(map1, options, width=512)  # a StarList carries its own labels
    assert a.solution is not None
    for other in (b, c):
        assert [m.catalog_id for m in other.solution.stars] == [
            m.catalog_id for m in a.solution.stars
        ]
        assert np.allclose(other.solution.R_cam_from_icrs, a.solution.R_cam_from_icrs)
    assert [m.label for m in c.solution.stars] == list(map1.labels)
    assert starnav.solve(map1.xy, options, width=512).ra_deg == a.solution.ra_deg


def test_deprecated_names_warn_and_answer_the_same(map1):
    options = {"width": 512, "fov_deg": 12.0, "catalog": CATALOG}
    new = starnav.solve_stars(map1.xy, **options)
    with pytest.warns(DeprecationWarning, match="solve_verbose is deprecated.*solve_stars"):
        old = starnav.solve_verbose(map1.xy, **options)
    assert np.allclose(old.solution.R_cam_from_icrs, new.solution.R_cam_from_icrs)
    with pytest.warns(DeprecationWarning, match="solve_batch"):
        rows = starnav.solve_batch([map1.xy, map1.xy[:2]], workers=1, **options)
    assert rows[0][0] is not None and rows[1][1].startswith("error: need at least 3 stars")
    with pytest.warns(DeprecationWarning, match="solve_fov"):
        searched = starnav.solve_fov(map1.xy, width=512, catalog=CATALOG, fov_deg=12.0)
    # the old function searched near a given FOV: as solve_stars does with fov_exact=False
    near = starnav.solve_stars(map1.xy, width=512, catalog=CATALOG, fov_deg=12.0, fov_exact=False)
    assert searched.solution is not None and near.solution is not None
    assert searched.solution.focal_px == near.solution.focal_px
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new names do not warn
        starnav.solve_stars(map1.xy, **options)


def test_a_result_prints_as_a_short_summary_and_holds_its_catalog(map1):
    result = starnav.solve_stars(map1.xy, width=512, fov_deg=12.0, catalog=CATALOG)
    text = repr(result)
    assert len(text) < 400 and "\n" not in text, text
    assert "RA 109.6" in text and "15/15 stars matched" in text and "catalog.csv" in text
    assert result.catalog is not None and len(result.catalog) > 1000
    assert not hasattr(result, "database")
    refused = starnav.solve_stars(
        np.random.default_rng(1).uniform(0, 512, (8, 2)),
        width=512,
        fov_deg=12.0,
        catalog=CATALOG,
    )
    assert repr(refused).startswith("SolveResult(not solved: ") and len(repr(refused)) < 400


def test_batch_errors_are_data_not_strings():
    catalog = load_catalog(CATALOG)
    good = read_star_csv(MAP1).xy
    results = starnav.solve_stars_batch(
        [good, np.array([[1.0, 2.0]]), good[:5]],
        SolveOptions(fov_deg=12.0, catalog=catalog),
        width=512,
        workers=1,
    )
    assert [r.bad_input for r in results] == [False, True, False]
    assert results[0].solution is not None and results[0].error is None
    assert "need at least 3 stars" in results[1].error and not math.isnan(results[1].time_ms)
    with pytest.raises(StarnavError, match="needs fov_deg or a camera"):
        starnav.solve_stars_batch([good], width=512, catalog=catalog)


def test_fisheye_lens_alone_is_not_refused_for_the_pinhole_range(tmp_path, capsys):
    """`starnav identify --lens equidistant` used to get the pinhole's 5-40° range and exit 2;
    the lens model's own range (100-200°) is searched now."""
    stars = tmp_path / "stars.csv"
    rng = np.random.default_rng(3)
    rows = "\n".join(f"{x:.2f},{y:.2f}" for x, y in rng.uniform(100, 900, (12, 2)))
    stars.write_text("x,y\n" + rows + "\n")
    code = main(
        ["identify", str(stars), "--width", "1024", "--lens", "equidistant", "--time-budget", "1"]
    )
    err = capsys.readouterr().err
    assert code == 1, err  # not solved (random points), not bad input
    assert "fov range must satisfy" not in err


def test_options_a_searched_field_cannot_take_are_refused_not_ignored():
    """The FOV search identifies by its own 4-star patterns on its own catalogs: another
    algorithm or a magnitude limit would be silently unused, so they are refused, for images
    before any detection."""
    blank = np.zeros((64, 64), np.float32)
    for fields in (
        {"algorithm": "triangle"},
        {"mag_limit": 7.0},
        {"fov_deg": 12.0, "algorithm": "voting"},
    ):
        with pytest.raises(StarnavError, match="need fov_deg or a camera taken as exact"):
            starnav.solve_image(blank, **fields)
    with pytest.raises(StarnavError, match="algorithm need fov_deg"):
        starnav.solve_stars(
            np.random.default_rng(0).uniform(0, 500, (9, 2)), width=512, algorithm="triangle"
        )
    # taken as exact, an image's field goes through the chosen algorithm
    assert starnav.solve_image(blank, fov_deg=12.0, fov_exact=True, algorithm="triangle").reason
