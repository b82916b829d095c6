"""Star catalogs: the embedded Hipparcos default and plain CSV files."""

from starnav.catalog.load import (
    DEFAULT_MAG_LIMIT,
    HIPPARCOS_EPOCH_YEAR,
    Catalog,
    default_epoch_year,
    hipparcos_mags,
    is_embedded,
    load_catalog,
    load_csv,
    load_hipparcos,
)

__all__ = [
    "DEFAULT_MAG_LIMIT",
    "HIPPARCOS_EPOCH_YEAR",
    "Catalog",
    "default_epoch_year",
    "hipparcos_mags",
    "is_embedded",
    "load_catalog",
    "load_csv",
    "load_hipparcos",
]
