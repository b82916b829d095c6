"""Real all-sky images (../shared/data/allsky) solved from the file with the CLI options
docs/wide_field.md gives, checked against independent star identifications
(tests/data/allsky/README.md)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from shared_data import ALLSKY, DATA, shared_file
from starnav.catalog.names import star_names
from starnav.detect.circle import find_image_circle
from starnav.detect.read import read_image

pytestmark = pytest.mark.corpus

KHO = ALLSKY / "kho_sony_a7s_20201211_200933.jpg"
STAR_IDS = DATA / "allsky" / "kho_20201211_star_ids.csv"
MATCH_PX = 5.0


def test_image_circle_of_the_kho_fisheye():
    circle = find_image_circle(read_image(shared_file(KHO)))
    # the hand-identified stars fit an equisolid lens centred at (1424.3, 1451.6) px
    assert abs(circle.cx - 1424.3) < 10 and abs(circle.cy - 1451.6) < 25
    assert 1300 < circle.radius_px < 1416


def test_full_frame_has_no_image_circle():
    rng = np.random.default_rng(1)
    assert find_image_circle(rng.normal(100.0, 5.0, (300, 400))) is None


@pytest.mark.slow
def test_kho_sony_solves_and_agrees_with_the_hand_identified_stars(capsys):
    from starnav.cli import main

    args = ["solve", str(shared_file(KHO)), "--lens", "equisolid", "--fov-deg", "180"]
    assert main([*args, "--max-stars", "100", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] is True and out["parity"] == 1
    hip_of = {name: hip for hip, name in star_names().items()}
    solved = [s for s in out["stars"] if s["catalog_id"] is not None]
    xy = np.array([(s["x"], s["y"]) for s in solved])
    agree = wrong = listed = 0
    with STAR_IDS.open() as fh:
        for row in csv.DictReader(fh):
            listed += 1
            ref = np.array([float(row["sony_x0"]), float(row["sony_y0"])]) + 0.5
            d = np.hypot(*(xy - ref).T)
            if d.min() <= MATCH_PX:
                same = solved[int(np.argmin(d))]["catalog_id"] == hip_of[row["name"]]
                agree, wrong = agree + same, wrong + (not same)
    assert listed == 19
    assert wrong == 0
    assert agree >= 0.8 * listed


def test_sky_mask_of_the_kho_frame_keeps_its_stars():
    """The KHO frame's sky mask takes its horizon's rim (a few % of the disc) and none of the
    hand-identified stars; fisheye detection finds nothing where it masks."""
    from starnav.detect.skymask import find_sky_mask
    from starnav.pipeline.image import detect_image

    image = read_image(shared_file(KHO))
    binned = image[:2832, :2832].reshape(1416, 2, 1416, 2).mean(axis=(1, 3))
    mask = find_sky_mask(binned)
    disc = 1.0 - mask.outside
    assert 0.0 < mask.obstacles / disc < 0.08 and mask.glare == 0.0
    with STAR_IDS.open() as fh:
        stars = [(float(r["sony_x0"]) + 0.5, float(r["sony_y0"]) + 0.5) for r in csv.DictReader(fh)]
    ij = (np.array(stars) / 2).astype(int)
    assert not mask.excluded[ij[:, 1], ij[:, 0]].any()
    found = detect_image(binned, lens="equisolid")
    at = found.xy.astype(int)
    assert len(found) == 100 and not mask.excluded[at[:, 1], at[:, 0]].any()
