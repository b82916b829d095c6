import numpy as np

from starnav.catalog import Catalog
from starnav.geometry import angle_between
from starnav.identify.database import build_database, cache_dir


def _small_catalog(n=400, seed=3):
    rng = np.random.default_rng(seed)
    ra = rng.uniform(0, 360, n)
    dec = np.degrees(np.arcsin(rng.uniform(-1, 1, n)))
    return Catalog(np.arange(1, n + 1), ra, dec, rng.uniform(0, 6, n), "random")


def test_pairs_complete_and_sorted():
    cat = _small_catalog()
    db = build_database(cat, 20.0, use_cache=False)
    v = cat.vectors
    brute = angle_between(v[:, None, :], v[None, :, :])
    iu = np.triu_indices(len(v), 1)
    expected = np.sort(brute[iu][brute[iu] <= np.radians(20.0)])
    assert np.allclose(db.pair_angle_rad, expected)
    assert np.all(np.diff(db.pair_angle_rad) >= 0)
    a, b = db.pairs_within(np.radians(10.0), np.radians(0.5))
    sep = np.degrees(angle_between(v[a], v[b]))
    assert len(a) > 0 and np.all(np.abs(sep - 10.0) <= 0.5 + 1e-9)


def test_disk_cache_round_trip():
    cat = _small_catalog(seed=4)
    first = build_database(cat, 12.2)
    assert not first.from_cache and first.path is not None and first.path.exists()
    assert first.path.parent == cache_dir()
    again = build_database(cat, 12.4)  # same rounded angle: same file
    assert again.from_cache and again.path == first.path
    assert np.array_equal(again.pair_a, first.pair_a)
    assert again.build_s == first.build_s and again.nbytes == first.nbytes
    other = build_database(_small_catalog(seed=5), 12.2)
    assert other.path != first.path


def test_damaged_cache_is_rebuilt():
    cat = _small_catalog(seed=6)
    first = build_database(cat, 10.0)
    first.path.write_bytes(b"not a numpy file")
    again = build_database(cat, 10.0)
    assert not again.from_cache and np.array_equal(again.pair_b, first.pair_b)
