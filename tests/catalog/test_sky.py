"""The sky over a site at a time (catalog.sky): stars above the horizon, and the planets."""

import numpy as np
import pytest

from starnav.catalog import load_catalog
from starnav.catalog.sky import (
    MIN_ALTITUDE_DEG,
    PLANET_IDS,
    Site,
    altitudes_deg,
    planet_name,
    planets,
    sky_at,
)
from starnav.errors import StarnavError

KHO = Site(78.148, 16.043, 520.0)  # the Kjell Henriksen Observatory, Svalbard
UTC = "2020-12-21T16:00:00"  # the great conjunction of Jupiter and Saturn


def test_sky_at_keeps_the_stars_above_the_horizon_and_adds_the_planets_up():
    cat = load_catalog(None, mag_limit=5.0)
    sky = sky_at(cat, KHO, UTC)
    alt = altitudes_deg(sky, KHO, UTC)
    assert np.all(alt >= MIN_ALTITUDE_DEG - 1e-9)
    assert 0.4 * len(cat) < len(sky) < 0.6 * len(cat)  # half the sphere, give or take
    assert np.all(np.diff(sky.mag) >= 0)  # brightest first
    stars = sky.ids[sky.ids > 0]
    assert set(stars) <= set(cat.ids)
    every = planets(KHO, UTC)
    alt = altitudes_deg(every, KHO, UTC)
    up = {int(i) for i, a in zip(every.ids, alt, strict=True) if a >= MIN_ALTITUDE_DEG}
    assert set(int(i) for i in sky.ids if i < 0) == up


def test_the_planets_are_where_the_ephemeris_puts_them():
    p = planets(KHO, UTC)
    jupiter = p.ids.tolist().index(PLANET_IDS["jupiter"])
    saturn = p.ids.tolist().index(PLANET_IDS["saturn"])
    # 0.1° apart at the conjunction, near RA 20h 10m, Dec -20.5°
    assert abs(p.ra_deg[jupiter] - 302.5) < 1.0 and abs(p.dec_deg[jupiter] + 20.5) < 1.0
    sep = np.hypot(
        (p.ra_deg[jupiter] - p.ra_deg[saturn]) * np.cos(np.radians(p.dec_deg[saturn])),
        p.dec_deg[jupiter] - p.dec_deg[saturn],
    )
    assert sep < 0.2
    assert planet_name(PLANET_IDS["mars"]) == "Mars" and planet_name(5447) is None


@pytest.mark.parametrize(
    "site, word",
    [((91.0, 0.0), "latitude"), ((0.0, float("nan")), "longitude"), ((0.0, 0.0, 1e6), "height")],
)
def test_a_bad_site_is_a_one_line_error(site, word):
    with pytest.raises(StarnavError, match=word):
        Site(*site)


def test_a_time_that_cannot_be_read_is_a_one_line_error():
    from starnav.catalog.sky import parse_utc

    with pytest.raises(StarnavError, match="is not an ISO 8601 time"):
        parse_utc("yesterday evening")
