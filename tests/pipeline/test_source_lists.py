"""Source lists in any order (starnav.pipeline.plate: XYList, read_xylist): sorted by a named
column (descending as solve-field sorts a flux, ascending for a magnitude), by the first
brightness column a table has when none is named, else taken as given; a list in detection
order (a scan of the image) is known not to be by brightness and is solved without it, its
points spread over the image. The GranaSAT Pleiades frame's list solves sorted, in
detection order with its FLUX column, and without one in detection order or shuffled."""

from __future__ import annotations

import numpy as np
import pytest
from astropy.io import fits

from source_lists import centre_offset_arcmin, plain_xylist, pleiades_sources, siril_xylist
from starnav.errors import StarnavError
from starnav.pipeline.plate import (
    PlateHints,
    XYList,
    brightness_order,
    in_detection_order,
    read_xylist,
    solve_plate,
    uniform_order,
)


def test_sorted_by_a_column():
    flux = [5.0, 9.0, float("nan"), 1.0]
    xy = XYList.make([1, 2, 3, 4], [4, 3, 2, 1], 10, 10, sort_values=flux, sort_name="FLUX")
    assert xy.x.tolist() == [2, 1, 4, 3] and xy.ordered and xy.sorted_by == "FLUX"  # NaN last
    mag = XYList.make([1, 2, 3], [1, 2, 3], 10, 10, sort_values=[7.5, 6.0, 9.0], ascending=True)
    assert mag.x.tolist() == [2, 1, 3]
    with pytest.raises(StarnavError, match="2 values for 3 sources"):
        brightness_order([1.0, 2.0], ascending=False, count=3)


def test_detection_order_is_told_apart():
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 1000, 60), rng.uniform(0, 800, 60)
    by_y = np.argsort(y)
    assert in_detection_order(x[by_y], y[by_y])
    assert in_detection_order(x[np.argsort(-x)], y[np.argsort(-x)])
    assert not in_detection_order(x, y)  # random, as a brightness order looks
    assert not XYList.make(x[by_y], y[by_y], 1000, 800).ordered
    assert XYList.make(x, y, 1000, 800).ordered


def test_uniform_order_spreads_the_first_points():
    rng = np.random.default_rng(4)
    xy = np.column_stack([rng.uniform(0, 1000, 200), rng.uniform(0, 800, 200)])
    xy = xy[np.argsort(xy[:, 1])]  # a scan: the first 20 all in the top strip
    first = xy[uniform_order(xy, 1000, 800)[:20]]
    assert first[:, 1].max() > 400 and np.ptp(first[:, 0]) > 600  # both rows of cells
    assert sorted(uniform_order(xy, 1000, 800)) == list(range(200))


def test_read_xylist_columns(tmp_path):
    x, _, flux, width, height = pleiades_sources()
    siril = read_xylist(siril_xylist(tmp_path / "s.xyls"))  # FLUX found by itself
    assert siril.sorted_by == "FLUX" and (siril.width, siril.height) == (width, height)
    assert siril.x[0] == pytest.approx(x[np.argmax(flux)])
    plain = read_xylist(plain_xylist(tmp_path / "p.xyls"))
    assert plain.sorted_by is None and not plain.ordered  # detection order, no brightness
    few = read_xylist(tmp_path / "s.xyls", sort_column="flux", max_sources=10)
    assert len(few.x) == 10 and few.x[0] == siril.x[0]  # names in any case
    with pytest.raises(StarnavError, match="has no column 'MAG_AUTO'"):
        read_xylist(tmp_path / "s.xyls", sort_column="MAG_AUTO")
    image = tmp_path / "image.fits"
    fits.PrimaryHDU(np.zeros((4, 4), dtype=np.float32)).writeto(image)
    assert read_xylist(image) is None  # an image, not a list


@pytest.mark.slow
def test_pleiades_list_solves_sorted_and_in_detection_order_with_flux(tmp_path):
    for source in (read_xylist(siril_xylist(tmp_path / "s.xyls")),):
        res = solve_plate(source, PlateHints())
        assert res.plate is not None, res.reason
        assert centre_offset_arcmin(res.plate.ra_deg, res.plate.dec_deg) < 3.0


SCALE_HINT = PlateHints(fov_range_deg=(27.07 * 0.9, 27.07 * 1.1))  # the width within ±10 %


@pytest.mark.parametrize("order", ["detection", "shuffled"])
def test_pleiades_list_without_brightness_solves(order):
    """Issue 36.2: the frame's detections with no brightness column, in detection order (by
    y) or shuffled, with the scale as clients send it: solved by the patterns of neighbouring
    points (``pipeline.unordered``), the centre as astrometry.net's, and the solution's
    rows are the list's own points."""
    x, y, _, width, height = pleiades_sources()
    rows = (
        np.arange(len(x)) if order == "detection" else np.random.default_rng(1).permutation(len(x))
    )
    source = XYList.make(x[rows], y[rows], width, height)
    assert source.ordered == (order == "shuffled")  # a shuffled list may be brightest first
    res = solve_plate(source, SCALE_HINT, time_budget_s=10.0)
    assert res.plate is not None, res.reason
    assert centre_offset_arcmin(res.plate.ra_deg, res.plate.dec_deg) < 3.0
    table = res.solution.star_table
    matched = table.catalog_id >= 0
    assert matched.sum() >= 50
    got = {tuple(np.round(p, 6)) for p in table.xy}
    assert got <= {tuple(np.round(p, 6)) for p in source.xy}


def test_random_points_without_brightness_are_not_solved(tmp_path):
    """Points at random over the frame, no brightness: not solved, saying why (never a
    field made up of chance agreements)."""
    from source_lists import random_xylist

    source = read_xylist(random_xylist(tmp_path / "r.xyls"))
    res = solve_plate(source, SCALE_HINT, time_budget_s=1.0)
    assert res.plate is None
    assert "detection order with no brightness column" in res.reason
