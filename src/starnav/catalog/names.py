"""Proper names of the bright stars, keyed by Hipparcos number.

``names.csv`` beside this module holds the names the IAU Working Group on Star Names (WGSN)
approved (IAU Catalog of Star Names) for the stars brighter than V = 3.0: 140 stars, Sirius
to Aldhanab. The numbers are Hipparcos (HIP) numbers, the ids of the embedded catalog.
"""

from __future__ import annotations

import csv
from functools import cache
from importlib import resources


@cache
def _names() -> tuple[tuple[int, str], ...]:
    text = resources.files("starnav.catalog").joinpath("names.csv").read_text(encoding="utf-8")
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    rows = list(csv.reader(lines))
    if rows[0] != ["hip", "name"]:
        raise RuntimeError(f"names.csv: expected the header hip,name, got {rows[0]}")
    return tuple((int(hip), name) for hip, name in rows[1:])


def star_names() -> dict[int, str]:
    """IAU proper names of the stars brighter than V = 3.0, {Hipparcos number: name}.

    The file is read once per process; each call returns a new dict the caller may change.
    """
    return dict(_names())
