"""Star lists (centroids) from CSV files and arrays, checked at the boundary.

CSV: a header row; ``x``, ``y`` (pixels, origin top-left) required; ``label`` and one of
``flux`` (larger is brighter) or ``mag`` (smaller is brighter) optional. Columns whose name
starts with ``true_`` carry the truth beside simulated input and are ignored.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.errors import StarListError
from starnav.runtime.csvrows import read_rows

# A centroid may sit a little outside the image (blooming, a star cut by the edge); beyond
# this fraction of the image size it cannot belong to the image.
OUTSIDE_MARGIN_FRAC = 0.1
_KNOWN = {"label", "x", "y", "flux", "mag"}


@dataclass(frozen=True, eq=False)
class StarList:
    """Checked centroids: ``xy`` (n, 2, px), ``labels``, ``brightness`` (n,, larger is
    brighter) or None; ``order`` (rows brightest first), ``rank`` (each row's place in it)
    and ``magnitudes`` are made from them on first use."""

    xy: np.ndarray
    labels: tuple[str, ...]
    brightness: np.ndarray | None

    @functools.cached_property
    def order(self) -> np.ndarray:
        """Rows brightest first (as given when there is no brightness)."""
        if self.brightness is None:
            return np.arange(len(self.xy))
        return np.argsort(-self.brightness, kind="stable")

    @functools.cached_property
    def rank(self) -> np.ndarray:
        """Each row's place in ``order`` (0: the brightest)."""
        rank = np.empty(len(self.xy), dtype=np.int64)
        rank[self.order] = np.arange(len(self.xy))
        return rank

    @functools.cached_property
    def magnitudes(self) -> np.ndarray | None:
        """Magnitudes from the brightness (-2.5 log10; NaN where it is not positive), None
        when there is no brightness."""
        if self.brightness is None:
            return None
        b = np.asarray(self.brightness, dtype=np.float64)
        positive = b > 0.0
        return np.where(positive, -2.5 * np.log10(np.where(positive, b, 1.0)), np.nan)


def read_star_csv(path: str | Path) -> StarList:
    """Read a star list CSV; raise ``StarListError`` naming the problem."""
    path = Path(path)
    header, rows = read_rows(path, what="star list", error=StarListError)
    unknown = [h for h in header if h not in _KNOWN and not h.startswith("true_")]
    if unknown or "x" not in header or "y" not in header:
        raise StarListError(
            f"star list {str(path)!r} has columns {','.join(header)}; expected x,y and "
            f"optionally label, flux or mag"
            + (f" (unknown: {','.join(unknown)})" if unknown else "")
        )
    if "flux" in header and "mag" in header:
        raise StarListError(f"star list {str(path)!r} has both flux and mag; give one")
    col = {name: header.index(name) for name in header}
    bright_col = "flux" if "flux" in col else "mag" if "mag" in col else None
    xy = np.empty((len(rows), 2))
    bright = np.empty(len(rows))
    labels = []
    for n, row in enumerate(rows):
        line = n + 2
        if len(row) != len(header):
            raise StarListError(
                f"star list {str(path)!r} line {line}: {len(row)} fields, header has {len(header)}"
            )
        try:
            xy[n] = float(row[col["x"]]), float(row[col["y"]])
            if bright_col:
                bright[n] = float(row[col[bright_col]])
        except ValueError:
            raise StarListError(
                f"star list {str(path)!r} line {line}: not a number in {','.join(row)!r}"
            ) from None
        labels.append(row[col["label"]].strip() if "label" in col else str(n + 1))
    if len(xy) == 0:
        raise StarListError(f"star list {str(path)!r} has a header but no stars")
    brightness = None
    if bright_col == "flux":
        brightness = bright
    elif bright_col == "mag":
        brightness = brightness_of_mag(bright)
    return StarList(xy, tuple(labels), brightness)


def brightness_of_mag(mag: np.ndarray) -> np.ndarray:
    """The brightness (larger is brighter, flux units of magnitude 0) of magnitudes ``mag``:
    how a star list given as magnitudes is ordered and weighed."""
    return 10.0 ** (-0.4 * np.asarray(mag, dtype=float))


def check_star_list(
    xy: np.ndarray,
    *,
    width: float,
    height: float,
    brightness: np.ndarray | None = None,
    labels: tuple[str, ...] | list[str] | None = None,
) -> StarList:
    """Validate centroids against the image: shape, finiteness, count, position, duplicates."""
    try:
        xy = np.array(xy, dtype=float)
    except (TypeError, ValueError):
        raise StarListError("star positions must be numbers, shape (n, 2)") from None
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise StarListError(f"star positions must have shape (n, 2), got {xy.shape}")
    if not np.isfinite(xy).all():
        row = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
        raise StarListError(f"star {row + 1} has a NaN or infinite position {tuple(xy[row])}")
    if len(xy) < 3:
        raise StarListError(f"need at least 3 stars to identify, got {len(xy)}")
    mx, my = OUTSIDE_MARGIN_FRAC * width, OUTSIDE_MARGIN_FRAC * height
    outside = (
        (xy[:, 0] < -mx) | (xy[:, 0] > width + mx) | (xy[:, 1] < -my) | (xy[:, 1] > height + my)
    )
    if outside.any():
        row = int(np.flatnonzero(outside)[0])
        raise StarListError(
            f"star {row + 1} at ({xy[row, 0]:g}, {xy[row, 1]:g}) px is far outside the "
            f"{width:g} x {height:g} image"
        )
    rounded = np.round(xy, 6)
    order = np.lexsort((rounded[:, 1], rounded[:, 0]))  # stable: first occurrence first
    same = np.flatnonzero((np.diff(rounded[order], axis=0) == 0).all(axis=1))
    if len(same):
        row = int(order[same[0]])
        raise StarListError(f"duplicate star position ({xy[row, 0]:g}, {xy[row, 1]:g}) px")
    if labels is None:
        labels = tuple(str(n + 1) for n in range(len(xy)))
    elif len(labels) != len(xy):
        raise StarListError(f"{len(labels)} labels for {len(xy)} stars")
    if brightness is not None:
        brightness = np.asarray(brightness, dtype=float).reshape(-1)
        if len(brightness) != len(xy):
            raise StarListError(f"{len(brightness)} brightness values for {len(xy)} stars")
        if not np.isfinite(brightness).all():
            row = int(np.flatnonzero(~np.isfinite(brightness))[0])
            raise StarListError(f"star {row + 1} has a NaN or infinite brightness")
    return StarList(xy, tuple(str(label) for label in labels), brightness)


@dataclass(frozen=True, eq=False)
class KnownStars:
    """Stars with known sky position and measured image position (for three-star pointing):
    ``ra_deg``, ``dec_deg`` (n,), and either ``xy`` (n, 2, px) or ``r_px`` (n,)."""

    ra_deg: np.ndarray
    dec_deg: np.ndarray
    xy: np.ndarray | None
    r_px: np.ndarray | None
    labels: tuple[str, ...]


def read_known_stars_csv(path: str | Path) -> KnownStars:
    """CSV with ``ra_deg,dec_deg`` and either ``x,y`` or ``r_px`` (and optionally ``label``)."""
    header, rows = read_rows(path, what="star list", error=StarListError)
    has_xy = "x" in header and "y" in header
    has_r = "r_px" in header
    allowed = {"label", "ra_deg", "dec_deg", "x", "y", "r_px"}
    unknown = [h for h in header if h not in allowed]
    if unknown or "ra_deg" not in header or "dec_deg" not in header or has_xy == has_r:
        raise StarListError(
            f"star list {str(path)!r} has columns {','.join(header)}; expected ra_deg,dec_deg "
            "and either x,y or r_px (optionally label)"
        )
    cols = ["ra_deg", "dec_deg", *(["x", "y"] if has_xy else ["r_px"])]
    values = np.empty((len(rows), len(cols)))
    for n, row in enumerate(rows):
        if len(row) != len(header):
            raise StarListError(
                f"star list {str(path)!r} line {n + 2}: {len(row)} fields, header has {len(header)}"
            )
        try:
            values[n] = [float(row[header.index(c)]) for c in cols]
        except ValueError:
            raise StarListError(
                f"star list {str(path)!r} line {n + 2}: not a number in {','.join(row)!r}"
            ) from None
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise StarListError(f"star list {str(path)!r} line {bad + 2}: NaN or infinite value")
    labels = tuple(
        row[header.index("label")].strip() if "label" in header else str(n + 1)
        for n, row in enumerate(rows)
    )
    return KnownStars(
        ra_deg=values[:, 0],
        dec_deg=values[:, 1],
        xy=values[:, 2:4] if has_xy else None,
        r_px=None if has_xy else values[:, 2],
        labels=labels,
    )
