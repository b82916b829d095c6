"""The 8 maps of the 2019 contest: no answer key, so check what can be checked."""

import numpy as np
import pytest

import starnav
from shared_data import CONTEST
from starnav.starlist import read_star_csv

CAMERAS = {n: (512, 12.0) if n <= 6 else (1024, 20.0) for n in range(1, 9)}
# published attitudes of maps 1 and 2 (domain.md section 4)
PUBLISHED = {1: (109.6, 34.5), 2: (43.0, 18.0)}


def _solve(n, catalog):
    stars = read_star_csv(CONTEST / "images" / f"xingtu0{n}.csv")
    width, fov = CAMERAS[n]
    return stars, starnav.solve(
        stars.xy, width=width, fov_deg=fov, labels=stars.labels, catalog=catalog
    )


@pytest.mark.parametrize("n", range(1, 9))
def test_map_identified(contest_catalog, n):
    stars, s = _solve(n, contest_catalog)
    assert s is not None
    assert [m.label for m in s.stars] == list(stars.labels)  # every point answered
    assert s.parity == -1  # the maps are mirrored in our convention
    ids = [m.catalog_id for m in s.stars if m.catalog_id is not None]
    assert len(ids) == len(set(ids)) == s.n_matched
    assert s.n_matched >= max(5, 0.7 * len(stars.xy))
    assert s.false_match_probability < 1e-6
    residuals = np.array([m.residual_px for m in s.stars if m.catalog_id is not None])
    if n == 3:  # the one map with position errors of a few pixels
        assert residuals.max() < 3.0
    else:  # exact projections
        assert s.rms_px < 0.05 and residuals.max() < 0.1
    if n in PUBLISHED:
        ra, dec = PUBLISHED[n]
        assert s.ra_deg == pytest.approx(ra, abs=0.05)
        assert s.dec_deg == pytest.approx(dec, abs=0.05)


def test_repeated_runs_agree(contest_catalog):
    for n in (3, 6):
        _, a = _solve(n, contest_catalog)
        _, b = _solve(n, contest_catalog)
        assert [m.catalog_id for m in a.stars] == [m.catalog_id for m in b.stars]
        assert np.array_equal(a.R_cam_from_icrs, b.R_cam_from_icrs)
