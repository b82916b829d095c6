"""Reading the small CSV files starnav takes (star lists, catalogs) into header and rows."""

from __future__ import annotations

import csv
from pathlib import Path


def read_rows(
    path: str | Path, *, what: str, error: type[Exception]
) -> tuple[list[str], list[list[str]]]:
    """(header names, data rows) of a CSV file with a header row; blank rows are skipped.

    Names are stripped and lower-cased; a byte-order mark is ignored. ``what`` names the file
    in messages ("star list", "catalog"); problems raise ``error`` with a one-line message.
    """
    try:
        with Path(path).open(newline="", encoding="utf-8-sig") as fh:
            rows = [r for r in csv.reader(fh) if any(cell.strip() for cell in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise error(f"cannot read {what} {str(path)!r}: {exc}") from None
    if not rows:
        raise error(f"{what} {str(path)!r} is empty")
    header = [h.strip().lower() for h in rows[0]]
    if "" in header:
        raise error(f"{what} {str(path)!r} has an empty column name in its header")
    if len(header) != len(set(header)):
        raise error(f"{what} {str(path)!r} repeats a column name")
    return header, rows[1:]
