"""Star catalogs: the embedded Hipparcos default, the embedded Gaia DR3 (narrow fields) and
users' CSV or FITS tables."""

from starnav.catalog.load import (
    DEFAULT_MAG_LIMIT,
    GAIA,
    GAIA_EPOCH_YEAR,
    GAIA_MAG_LIMIT,
    HIPPARCOS_EPOCH_YEAR,
    Catalog,
    default_epoch_year,
    hipparcos_mags,
    is_embedded,
    is_gaia,
    load_catalog,
    load_csv,
    load_gaia,
    load_hipparcos,
)

__all__ = [
    "DEFAULT_MAG_LIMIT",
    "GAIA",
    "GAIA_EPOCH_YEAR",
    "GAIA_MAG_LIMIT",
    "HIPPARCOS_EPOCH_YEAR",
    "Catalog",
    "default_epoch_year",
    "hipparcos_mags",
    "is_embedded",
    "is_gaia",
    "load_catalog",
    "load_csv",
    "load_gaia",
    "load_hipparcos",
]
