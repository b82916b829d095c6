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


def _near_directions(v, radius, rng):
    """Directions just inside and just outside ``radius`` (rad) of each of ``v``, and on the
    cube's edges and corners, where the near-star grid's faces meet."""
    k = rng.normal(size=v.shape)
    k -= np.sum(k * v, axis=1)[:, None] * v  # a tangent direction per star
    k /= np.linalg.norm(k, axis=1)[:, None]
    out = []
    for f in (0.5, 0.999, 1.001, 1.5):
        a = f * radius
        out.append(np.cos(a) * v + np.sin(a) * k)
    edges = rng.choice([-1.0, 1.0], size=(2000, 3))
    edges[:1000, 0] = rng.uniform(-1, 1, 1000)  # along an edge; the rest: corners
    out.append(edges)
    out = np.vstack(out)
    return out / np.linalg.norm(out, axis=1)[:, None]


def test_the_near_star_grid_answers_as_a_search_of_every_star():
    from starnav.identify.database import near_grid
    from starnav.identify.kernels import sky

    rng = np.random.default_rng(5)
    cat = _small_catalog(n=600)
    # stars on the cube's edges and corners too, where one disk spans two or three faces
    corner = rng.choice([-1.0, 1.0], size=(40, 3)) + rng.normal(0, 1e-3, (40, 3))
    v = np.vstack([cat.vectors, corner / np.linalg.norm(corner, axis=1)[:, None]])
    allowed = np.ones(len(v), dtype=np.bool_)
    allowed[::7] = False  # a star that is not allowed is not near
    for radius_deg in (0.04, 1.0, 8.0, 40.0):  # 40°: one cell per face
        radius = np.radians(radius_deg)
        chord2 = sky.chord(radius) ** 2
        near = near_grid(v, radius)  # as the search builds it: for the match radius
        queries = _near_directions(v, radius, rng)
        got = np.array([sky.near_cell(q, chord2, near, v, allowed) for q in queries])
        d2 = np.sum((queries[:, None, :] - v[None, allowed, :]) ** 2, axis=2)
        expected = np.any(d2 <= chord2, axis=1)
        assert got.sum() > len(v)  # many queries are near a star, many are not
        assert np.array_equal(got, expected), radius_deg
