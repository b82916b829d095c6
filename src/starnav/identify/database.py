"""Star-pair database: every catalog pair closer than the field diagonal, sorted by angle.

Built once per (catalog, largest angle) and cached on disk as ``.npz`` under
``$STARNAV_CACHE_DIR`` (default ``~/.cache/starnav``), keyed by a hash of the catalog content,
the angle and the format version. The catalog's KD-tree (the cone searches of the algorithms
that use one) is built on first use: a few milliseconds, and scipy.spatial loaded only then.
"""

from __future__ import annotations

import functools
import hashlib
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from starnav.catalog import Catalog
from starnav.geometry import angle_between, chord_from_angle
from starnav.runtime.caching import cache_dir, load_cached, save_cached

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

_FORMAT_VERSION = 2
GRID_STEP_DEG = 1.0  # cells of the RA / Dec grid the cone searches of the kernels use
NEAR_CELLS_PER_STAR = 2.0  # the near-star grid has about this many cells per catalog star
_ANGLE_STEP_DEG = 0.5  # databases are built for max angles rounded up to this step


@dataclass(frozen=True, eq=False)
class PairDatabase:
    """Catalog star pairs with their angular separation, sorted by angle.

    ``pair_a``, ``pair_b``: catalog row indices (a < b); ``pair_angle_rad`` ascending;
    ``pair_stars``: the pairs join the brightest this many catalog stars (all of them but
    in wide fields; the verification always searches the whole catalog).
    ``build_s``: seconds the build took (kept in the cache file, so also shown when loaded);
    ``from_cache``: whether it was loaded from disk; ``path``: the cache file, if any.
    """

    catalog: Catalog
    max_angle_rad: float
    pair_a: np.ndarray
    pair_b: np.ndarray
    pair_angle_rad: np.ndarray
    build_s: float
    from_cache: bool
    path: Path | None
    pair_stars: int = 0

    @property
    def nbytes(self) -> int:
        """Size in bytes of the pair arrays, the catalog vectors and the KD-tree's arrays held
        in memory."""
        return (
            int(self.pair_a.nbytes + self.pair_b.nbytes + self.pair_angle_rad.nbytes)
            + self.verification_nbytes
        )

    @property
    def verification_nbytes(self) -> int:
        """Bytes of what every verification searches: catalog vectors, their KD-tree (its
        copy of the vectors counted only when it is one) and the RA / Dec grid's arrays."""
        shared = np.shares_memory(self.tree.data, self.catalog.vectors)
        data = 0 if shared else self.tree.data.nbytes
        return int(self.catalog.vectors.nbytes + data + self.tree.indices.nbytes + self.grid_nbytes)

    @functools.cached_property
    def tree(self) -> cKDTree:
        """The KD-tree of the catalog vectors (built on first use, a few ms for 5000 stars)."""
        from scipy.spatial import cKDTree

        return cKDTree(self.catalog.vectors)

    @property
    def grid_nbytes(self) -> int:
        """Bytes of the RA / Dec grid's own arrays (its vectors are the catalog's)."""
        _, start, rows, *_ = self.sky
        return int(start.nbytes + rows.nbytes)

    @functools.cached_property
    def sky(self) -> tuple:
        """The RA / Dec grid of the catalog the kernels search (``sky_grid``; ~2 ms for
        5000 stars, built on first use)."""
        return sky_grid(self.catalog.vectors)

    def near(self, radius_rad: float) -> tuple:
        """The near-star grid of the catalog for ``radius_rad`` (``near_grid``; built on first
        use per radius, ~2 ms and ~60 KB for 5000 stars; not in ``nbytes``, which is the same
        whichever searches ran)."""
        grids = self._near_grids
        if radius_rad not in grids:
            grids[radius_rad] = near_grid(self.catalog.vectors, radius_rad)
        return grids[radius_rad]

    @functools.cached_property
    def _near_grids(self) -> dict[float, tuple]:
        return {}

    @functools.cached_property
    def everything(self) -> np.ndarray:
        """A mask allowing every catalog row (the ``allowed`` of unrestricted searches)."""
        return np.ones(len(self.catalog), dtype=np.bool_)

    @functools.cached_property
    def mags(self) -> np.ndarray:
        """The catalog rows' magnitudes as the kernels take them (contiguous float64; the
        catalog's own column may be a strided view of its table)."""
        return np.ascontiguousarray(self.catalog.mag, dtype=np.float64)

    def pairs_within(self, angle_rad: float, tol_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """Catalog pairs (a, b) whose separation is within ``tol_rad`` of ``angle_rad``."""
        lo, hi = np.searchsorted(self.pair_angle_rad, [angle_rad - tol_rad, angle_rad + tol_rad])
        return self.pair_a[lo:hi], self.pair_b[lo:hi]

    def cone(self, axis: np.ndarray, radius_rad: float) -> np.ndarray:
        """Catalog row indices within ``radius_rad`` of the unit vector ``axis``."""
        from starnav.identify.kernels.sky import cone  # numba: loaded on first use

        work = np.empty(len(self.catalog), dtype=np.int64)
        n = cone(
            np.ascontiguousarray(axis, dtype=np.float64),
            chord_from_angle(radius_rad) ** 2,
            self.sky,
            self.everything,
            work,
        )
        return np.sort(work[:n]).astype(np.intp)


def sky_grid(vectors: np.ndarray, step_deg: float = GRID_STEP_DEG) -> tuple:
    """The RA / Dec grid of unit ``vectors`` (n, 3) with cells of ``step_deg``:
    ``(vectors, start, rows, n_dec, n_ra, step_rad)``, cell ``i * n_ra + j`` (Dec band i
    from the south pole, RA column j) holding rows ``rows[start[c]:start[c + 1]]``."""
    vectors = np.ascontiguousarray(vectors, dtype=np.float64)
    step = math.radians(step_deg)
    n_dec, n_ra = round(180.0 / step_deg), round(360.0 / step_deg)
    dec = np.arcsin(np.clip(vectors[:, 2], -1.0, 1.0))
    ra = np.arctan2(vectors[:, 1], vectors[:, 0]) % (2.0 * np.pi)
    i = np.clip(np.floor((dec + 0.5 * np.pi) / step).astype(np.int64), 0, n_dec - 1)
    j = np.clip(np.floor(ra / step).astype(np.int64), 0, n_ra - 1)
    cell = i * n_ra + j
    rows = np.argsort(cell, kind="stable").astype(np.int32)
    start = np.searchsorted(cell[rows], np.arange(n_dec * n_ra + 1)).astype(np.int32)
    return (vectors, start, rows, n_dec, n_ra, step)


def near_grid(vectors: np.ndarray, radius_rad: float) -> tuple:
    """A grid that answers "is a star within ``radius_rad`` of this direction?" from one
    cell, without trigonometry: ``(start, rows, n)``. The sphere is split into the six faces
    of a cube (a direction's face: its largest component and that component's sign), each face
    into n x n cells of its gnomonic plane (u, w = the next two components over the largest's
    magnitude, in [-1, 1]); cell ``(face * n + i) * n + j`` holds rows
    ``rows[start[c]:start[c + 1]]``: every star whose disk of ``radius_rad`` reaches into it.
    The gnomonic map stretches an angle by at most 1 / d^2 where the direction's component
    along the face's axis is d, and within ``radius_rad`` of a face d is at least
    cos(atan(sqrt 2) + radius): a star within the radius of a direction is within
    e = radius / d_min^2 of it in (u, w) on the direction's face, so a star is listed in every
    cell its box u +- e, w +- e meets, on every face whose square grown by e holds it. The
    cells are at least 2 e wide (a star is in at most 4 per face); e is taken a millionth wider,
    so a chord of ``radius_rad`` (its angle exact but for rounding) is covered. A radius over
    ~30°: every star in the one cell of every face."""
    vectors = np.ascontiguousarray(vectors, dtype=np.float64)
    index = np.arange(len(vectors))
    d_min = math.cos(math.atan(math.sqrt(2.0)) + radius_rad)
    if d_min < 0.1:  # a radius over ~30°: one cell per face, holding every star
        n_stars = len(vectors)
        start = np.arange(7, dtype=np.int32) * n_stars
        return (start, np.tile(index, 6).astype(np.int32), 1)
    e = radius_rad / d_min**2 * (1.0 + 1e-6) + 1e-12
    per_face = round(math.sqrt(NEAR_CELLS_PER_STAR * len(vectors) / 6.0))
    n = int(max(1, min(math.floor(1.0 / e), per_face)))
    cells, rows = [], []
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        d = sign * vectors[:, axis]
        ok = d > 0.0
        u = vectors[ok, (axis + 1) % 3] / d[ok]
        w = vectors[ok, (axis + 2) % 3] / d[ok]
        inside = (np.abs(u) <= 1.0 + e) & (np.abs(w) <= 1.0 + e)
        u, w, star = u[inside], w[inside], index[ok][inside]
        i_lo, i_hi, j_lo, j_hi = (
            np.clip(np.floor((c + 1.0) * 0.5 * n), 0, n - 1).astype(np.int64)
            for c in (u - e, u + e, w - e, w + e)
        )
        for di in (0, 1):
            for dj in (0, 1):
                keep = (i_lo + di <= i_hi) & (j_lo + dj <= j_hi)
                cells.append((face * n + i_lo[keep] + di) * n + j_lo[keep] + dj)
                rows.append(star[keep])
    cell, row = np.concatenate(cells), np.concatenate(rows)
    order = np.argsort(cell, kind="stable")
    start = np.searchsorted(cell[order], np.arange(6 * n * n + 1)).astype(np.int32)
    return (start, row[order].astype(np.int32), n)


def catalog_only(catalog: Catalog, max_angle_rad: float) -> PairDatabase:
    """A database without pairs, for searches that only verify (the catalog and its
    KD-tree; ``max_angle_rad`` still bounds the field)."""
    none = np.empty(0, dtype=np.int32)
    return PairDatabase(catalog, max_angle_rad, none, none, np.empty(0), 0.0, False, None)


def database_angle_deg(max_angle_deg: float) -> float:
    """The largest pair angle a database for ``max_angle_deg`` is built with (rounded up)."""
    return float(np.ceil(max_angle_deg / _ANGLE_STEP_DEG - 1e-9) * _ANGLE_STEP_DEG)


def build_pairs(vectors: np.ndarray, max_angle_rad: float):
    """Pairs (a, b) of the unit ``vectors`` closer than ``max_angle_rad``, sorted by angle,
    and their angles (radians)."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(vectors).query_pairs(chord_from_angle(max_angle_rad), output_type="ndarray")
    angles = angle_between(vectors[pairs[:, 0]], vectors[pairs[:, 1]])
    order = np.argsort(angles, kind="stable")
    # 16-bit indices when they fit: half the memory, and numpy radix-sorts them
    index_type = np.uint16 if len(vectors) <= np.iinfo(np.uint16).max else np.int32
    return (
        pairs[order, 0].astype(index_type),
        pairs[order, 1].astype(index_type),
        angles[order],
    )


def brightest_pairs(catalog: Catalog, max_angle_rad: float, n_stars: int):
    """``build_pairs`` among the brightest ``n_stars`` of ``catalog``, as catalog rows."""
    rows = np.sort(np.argsort(catalog.mag, kind="stable")[:n_stars])
    a, b, ang = build_pairs(catalog.vectors[rows], max_angle_rad)
    index_type = a.dtype if len(catalog) <= np.iinfo(np.uint16).max else np.int32
    return rows[a].astype(index_type), rows[b].astype(index_type), ang  # rows ascending: a < b


def build_database(
    catalog: Catalog,
    max_angle_deg: float,
    *,
    use_cache: bool = True,
    pair_stars: int | None = None,
) -> PairDatabase:
    """The pair database of ``catalog`` for pairs up to ``max_angle_deg`` (rounded up),
    among its brightest ``pair_stars`` (default all).

    Loaded from the disk cache when an identical one was built before.
    """
    max_angle_deg = database_angle_deg(max_angle_deg)
    max_angle_rad = float(np.radians(max_angle_deg))
    n_pair = len(catalog) if pair_stars is None else min(int(pair_stars), len(catalog))
    subset = "" if n_pair == len(catalog) else f"|{n_pair}"
    key = hashlib.sha1(
        f"{_FORMAT_VERSION}|{catalog.fingerprint}|{max_angle_deg:.3f}{subset}".encode()
    ).hexdigest()[:20]
    path = cache_dir() / f"pairs-{key}.npz"
    data = load_cached(path) if use_cache else None
    if data is not None and {"a", "b", "angle", "build_s"} <= data.keys():
        return PairDatabase(
            catalog,
            max_angle_rad,
            data["a"],
            data["b"],
            data["angle"],
            float(data["build_s"]),
            True,
            path,
            n_pair,
        )
    t0 = time.perf_counter()
    if subset:
        a, b, ang = brightest_pairs(catalog, max_angle_rad, n_pair)
    else:
        a, b, ang = build_pairs(catalog.vectors, max_angle_rad)
    build_s = time.perf_counter() - t0
    saved = save_cached(path, a=a, b=b, angle=ang, build_s=build_s) if use_cache else None
    return PairDatabase(catalog, max_angle_rad, a, b, ang, build_s, False, saved, n_pair)
