"""The small CSV files starnav reads (star lists, catalogs) and writes (simulated frames,
rendered truth): header and rows."""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from pathlib import Path

from starnav.errors import StarnavError


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


def write_rows(path: str | Path, header: Sequence[str], rows: Iterable[Sequence[object]]) -> None:
    """Write a CSV file: the ``header`` row, then ``rows``; a file that cannot be written
    raises ``StarnavError`` with a one-line message."""
    try:
        with Path(path).open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            writer.writerows(rows)
    except OSError as exc:
        raise StarnavError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
