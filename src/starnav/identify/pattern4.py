"""Lost-in-space identification by 4-star patterns hashed on their edge ratios.

The idea of tetra3 (G. Pettersson, ESA) and its descendants cedar-solve and tetra3rs: four
stars span six angular edges; sorted and divided by the largest, they give five ratios that do
not depend on the attitude (nor on the parity). The database holds, for catalog patterns that
a camera can see among its brightest stars, those five ratios quantised into bins as one
integer key; identification computes the ratios of observed 4-star patterns, looks up every
bin the measurement tolerance reaches, and keeps the catalog patterns whose six edges agree.
The stars of a pattern are stored in a canonical order (by distance from the pattern's
centroid), so the observed stars, put in the same order, pair with them directly.

Which patterns (cedar-solve's lattice fields): field centres spread evenly over the sky (a
Fibonacci lattice, oversampled so that every pointing is close to some centre); in each
circular field the brightest ``stars_per_field`` catalog stars; every 4-subset of them is a
pattern. Observed patterns are formed from the brightest measured stars in the same
"brightest first" order, so they are the ones the database holds. Dense clusters cannot flood
the table: each field contributes at most C(stars_per_field, 4) patterns.

Every match proposes a hypothesis (4 measured stars paired with 4 catalog stars, and a parity
from the orientation of the pattern), verified on the whole field by ``HypothesisTester``.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.errors import CatalogError, StarnavError, shown
from starnav.geometry import angle_between, chord_from_angle
from starnav.identify.base import IdentifyOutcome, MatchSettings, screen_stars_only
from starnav.identify.database import PairDatabase, load_cached, save_cached
from starnav.identify.verify import HypothesisTester
from starnav.runtime.budget import Deadline, expired
from starnav.runtime.caches import process_cache
from starnav.runtime.caching import cache_dir

_FORMAT_VERSION = 2  # 2: stars as (field, subset, order) codes, largest edge in uint16 steps
# the six edges of a pattern (star pairs) and its four triangles
_PAIRS = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
_TRIPLES = np.array([(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)])
# the 24 ways to pair 4 observed stars with 4 catalog stars (the identity first), and for each
# the observed edge that corresponds to each catalog edge
_PERMS = np.array(list(itertools.permutations(range(4))))
_EDGE_INDEX = {(int(i), int(j)): e for e, (i, j) in enumerate(_PAIRS)}
_EDGE_INDEX.update({(j, i): e for (i, j), e in list(_EDGE_INDEX.items())})
_PERM_EDGES = np.array([[_EDGE_INDEX[(int(p[i]), int(p[j]))] for i, j in _PAIRS] for p in _PERMS])
_MAX_PROBES = 200_000  # bin look-ups per batch of observed patterns (bounds memory)
_MAX_CANDIDATES = 500_000  # table rows per batch (bounds memory and the work between deadlines)
_BUILD_BLOCK = 4096  # lattice fields expanded at once while building
_MAX_PATTERN_ROWS = 5e7  # patterns expanded before removing duplicates (about 0.4 GB)
_EDGE_STEPS = 65535  # the table's largest edge in uint16 steps
FIELD_RADIUS_FRACTION = 0.85  # lattice field radius / half the field diagonal


@functools.cache
def breadth_first_combinations(n: int) -> np.ndarray:
    """Every 4-subset of ``range(n)``, shape (C(n, 4), 4), in tetra3's breadth-first order:
    all subsets of the first m stars come before any subset holding star m, so the brightest
    stars are exhausted first and a false star costs only the subsets that hold it."""
    c = np.array(list(itertools.combinations(range(n), 4)), dtype=np.intp).reshape(-1, 4)
    return c[np.lexsort((c[:, 0], c[:, 1], c[:, 2], c[:, 3]))]


def pattern_edges(v: np.ndarray) -> np.ndarray:
    """The six edge angles (radians) of 4-star patterns ``v`` (..., 4, 3), pairs as ``_PAIRS``."""
    d = np.take(v, _PAIRS[:, 0], axis=-2) - np.take(v, _PAIRS[:, 1], axis=-2)
    # from the chord: accurate for small angles, where the arccos of a dot product is not
    return 2.0 * np.arcsin(np.minimum(0.5 * np.sqrt(np.einsum("...i,...i->...", d, d)), 1.0))


def centroid_distances(v: np.ndarray) -> np.ndarray:
    """Angle (radians) of each star of patterns ``v`` (..., 4, 3) from the pattern centroid
    (the normalised mean direction): the canonical order sorts stars by it."""
    c = v.sum(axis=-2)
    c /= np.linalg.norm(c, axis=-1, keepdims=True)
    return angle_between(v, c[..., None, :])


def fibonacci_lattice(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (golden-angle spiral), shape (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


@dataclass(frozen=True, eq=False)
class PatternTable:
    """4-star catalog patterns sorted by their edge-ratio key.

    ``keys`` (m,) ascending: the five sorted edge ratios (each edge / the largest), quantised
    into ``bins`` bins each, as the base-``bins`` number with the smallest ratio most
    significant. ``fields`` (f, k): the lattice fields the patterns come from, each as its
    ``k = stars_per_field`` brightest catalog rows, ascending (padded with the catalog size
    where a field holds fewer stars). ``codes`` (m,): which stars, as the number
    ``(field * C(k, 4) + subset) * 24 + order``: the 4-subset ``subset`` (a row of
    ``breadth_first_combinations(k)``) of field ``field``, put in canonical order (ascending
    distance from the pattern centroid) by the permutation ``order`` (a row of ``_PERMS``).
    ``stars(rows)`` decodes them. ``largest_edge_steps`` (m,) uint16: each pattern's largest
    edge in steps of ``edge_step_rad`` (radians; the largest edge of the table / 65535),
    rounded: a quick first test, within half a step; the exact edges are recomputed from the
    catalog vectors. ``build_s``: seconds the build took; ``from_cache``, ``path``: as for
    ``PairDatabase``.
    """

    keys: np.ndarray
    codes: np.ndarray
    fields: np.ndarray
    largest_edge_steps: np.ndarray
    edge_step_rad: float
    bins: int
    build_s: float
    from_cache: bool
    path: Path | None

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays held (keys, codes, fields, largest edges)."""
        return int(
            self.keys.nbytes
            + self.codes.nbytes
            + self.fields.nbytes
            + self.largest_edge_steps.nbytes
        )

    def __len__(self) -> int:
        return len(self.keys)

    def stars(self, rows: np.ndarray) -> np.ndarray:
        """Catalog rows (len(rows), 4) of the patterns at table ``rows``, canonical order."""
        k = self.fields.shape[1]
        ordered = ordered_subsets(k)
        field, which = np.divmod(self.codes[rows].astype(np.intp), len(ordered))
        # ``take``: several times faster than fancy indexing on these sizes
        index = ordered.take(which, axis=0)
        index += field[:, None] * k
        return self.fields.ravel().take(index).astype(np.intp)


@functools.cache
def ordered_subsets(n: int) -> np.ndarray:
    """Row ``subset * 24 + order``: the 4-subset ``subset`` of ``range(n)`` (a row of
    ``breadth_first_combinations(n)``) permuted by ``_PERMS[order]``, shape (C(n, 4) * 24, 4)."""
    return breadth_first_combinations(n)[:, _PERMS].reshape(-1, 4)


_KDTREE_NODE_BYTES = 72  # scipy's ckdtreenode: nine 8-byte fields


def catalog_nbytes(database: PairDatabase) -> int:
    """Bytes of what verification searches, each array once: the catalog's arrays (ids,
    positions, magnitudes, unit vectors), its KD-tree (indices and nodes; the tree's data
    is the unit vectors themselves unless scipy had to copy them) and its RA / Dec grid."""
    catalog, tree = database.catalog, database.tree
    arrays = (catalog.ids, catalog.ra_deg, catalog.dec_deg, catalog.mag, catalog.vectors)
    data = 0 if np.shares_memory(tree.data, catalog.vectors) else tree.data.nbytes
    return int(
        sum(a.nbytes for a in arrays)
        + data
        + tree.indices.nbytes
        + tree.size * _KDTREE_NODE_BYTES
        + database.grid_nbytes
    )


def _key_dtype(bins: int) -> type:
    return np.uint32 if bins**5 <= np.iinfo(np.uint32).max else np.uint64


def _field_patterns(
    database: PairDatabase,
    stars_per_field: int,
    field_radius_rad: float,
    oversampling: float,
    region: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct 4-subsets of the brightest ``stars_per_field`` stars of every lattice
    field of radius ``field_radius_rad`` (centred within ``region``, a unit vector and a
    radius in rad, when given): the fields (f, stars_per_field), catalog rows ascending,
    padded with the catalog size; and for each distinct pattern one field holding it and its
    subset number (a row of ``breadth_first_combinations(stars_per_field)``)."""
    catalog = database.catalog
    n_cat = len(catalog)
    # the number of fields: ``oversampling`` times the number of field-sized squares on the sky
    n_fields = max(1, math.ceil(oversampling * 4.0 * np.pi / (2.0 * field_radius_rad) ** 2))
    centres = fibonacci_lattice(n_fields)
    if region is not None:
        centres = centres[centres @ region[0] >= math.cos(region[1])]
        n_fields = len(centres)
    rank = np.empty(n_cat, dtype=np.intp)
    rank[np.argsort(catalog.mag, kind="stable")] = np.arange(n_cat)
    sets = []
    for f0 in range(0, n_fields, _BUILD_BLOCK):
        lists = database.tree.query_ball_point(
            centres[f0 : f0 + _BUILD_BLOCK], chord_from_angle(field_radius_rad)
        )
        counts = np.fromiter(map(len, lists), dtype=np.intp, count=len(lists))
        members = np.fromiter(itertools.chain.from_iterable(lists), np.intp, int(counts.sum()))
        field = np.repeat(np.arange(len(lists)), counts)
        # members of each field brightest first, then the first stars_per_field of each
        o = np.lexsort((rank[members], field))
        members, field = members[o], field[o]
        pos = np.arange(len(members)) - np.repeat(np.cumsum(counts) - counts, counts)
        keep = pos < stars_per_field
        top = np.full((len(lists), stars_per_field), n_cat, dtype=np.int64)  # n_cat: empty
        top[field[keep], pos[keep]] = members[keep]
        sets.append(np.sort(top, axis=1))
    # neighbouring fields of an oversampled lattice mostly hold the same stars
    return _distinct_patterns(_unique(np.concatenate(sets)), stars_per_field, n_cat)


def _local_patterns(
    database: PairDatabase, group: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct 4-subsets of every catalog star's neighbourhood: the star and its
    ``group - 1`` nearest (``_field_patterns``' return, a neighbourhood as a field). They
    do not depend on the brightness order of the stars within reach, nor on the field of
    view: what a list of points in no brightness order is matched against
    (``starnav.pipeline.unordered``)."""
    n_cat = len(database.catalog)
    k = min(group, n_cat)
    _, rows = database.tree.query(database.catalog.vectors, k=k)
    top = np.full((n_cat, group), n_cat, dtype=np.int64)
    top[:, :k] = np.asarray(rows, dtype=np.int64).reshape(n_cat, k)
    return _distinct_patterns(_unique(np.sort(top, axis=1)), group, n_cat)


def _distinct_patterns(
    top: np.ndarray, stars_per_field: int, n_cat: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_field_patterns``' answer for the fields ``top`` (f, stars_per_field: catalog rows
    ascending, padded with ``n_cat``): the fields some pattern points to, and for each
    distinct 4-subset one field holding it and its subset number."""
    combos = breadth_first_combinations(stars_per_field)
    if len(top) * len(combos) > _MAX_PATTERN_ROWS:
        raise CatalogError(
            f"{len(top)} distinct fields of {stars_per_field} stars make up to "
            f"{len(top) * len(combos):.2g} 4-star patterns (limit {_MAX_PATTERN_ROWS:.0e}): use "
            "fewer stars per field or a brighter magnitude limit"
        )
    # rows ascending in each field, so every subset comes out ascending and duplicates are
    # equal: one number per subset (its four rows), sorted and deduplicated, then for each
    # distinct pattern one (field, subset) that makes it
    bits = max(1, math.ceil(math.log2(n_cat + 1)))
    if 4 * bits > 64:  # a catalog too large for 16-bit rows: whole rows compared
        p = top[:, combos].reshape(-1, 4)
        valid = np.flatnonzero(p[:, 3] < n_cat)
        first = np.unique(p[valid], axis=0, return_index=True)[1]
        field, subset = np.divmod(valid[first], len(combos))
    else:
        code = top[:, combos[:, 0]].astype(np.uint64)
        for k in (1, 2, 3):
            code = (code << np.uint64(bits)) | top[:, combos[:, k]].astype(np.uint64)
        distinct = _unique(code[top[:, combos[:, 3]] < n_cat])
        which = np.full(len(distinct), -1, dtype=np.int64)
        for f0 in range(0, len(top), _BUILD_BLOCK):
            block = code[f0 : f0 + _BUILD_BLOCK].ravel()
            flat = np.arange(f0 * len(combos), f0 * len(combos) + len(block))
            pos = np.searchsorted(distinct, block)
            hit = (pos < len(distinct)) & (distinct[np.minimum(pos, len(distinct) - 1)] == block)
            which[pos[hit]] = flat[hit]  # any field holding the pattern will do
        field, subset = np.divmod(which, len(combos))
    used, field = np.unique(field, return_inverse=True)  # only fields some pattern points to
    return top[used], field, subset


def _unique(a: np.ndarray) -> np.ndarray:
    """Distinct values (1-d) or rows (2-d) of ``a``, sorted (a sort and a comparison of
    neighbours: faster than ``np.unique`` on millions of integers)."""
    if a.ndim == 1:
        a = np.sort(a)
        return a[np.concatenate([[True], a[1:] != a[:-1]])] if len(a) else a
    a = a[np.lexsort(a.T[::-1])]
    return a[np.concatenate([[True], (a[1:] != a[:-1]).any(axis=1)])] if len(a) else a


# the row of ``_PERMS`` of a permutation (p0, p1, p2, p3), looked up at 64 p0 + 16 p1 + 4 p2 + p3
_PERM_ROW = np.zeros(256, dtype=np.int64)
_PERM_ROW[_PERMS @ np.array([64, 16, 4, 1])] = np.arange(len(_PERMS))


def _pattern_keys(
    vectors: np.ndarray, fields: np.ndarray, field: np.ndarray, subset: np.ndarray, bins: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keys, codes (see ``PatternTable``) and largest edges (radians) of the patterns
    ``subset`` of ``fields[field]``, sorted by key."""
    combos = breadth_first_combinations(fields.shape[1])
    keys, codes, largest = [], [], []
    for k in range(0, len(field), 200_000):  # bounds the memory of the (m, 4, 3) vectors
        f, s = field[k : k + 200_000], subset[k : k + 200_000]
        p = fields[f[:, None], combos[s]]
        v = vectors[p]
        edges = np.sort(pattern_edges(v), axis=1)
        ratios = edges[:, :5] / edges[:, 5:]
        digits = np.minimum((ratios * bins).astype(np.int64), bins - 1)
        key = np.zeros(len(p), dtype=np.int64)
        for d in range(5):
            key = key * bins + digits[:, d]
        keys.append(key)
        # canonical order: nearest the centroid first (the largest projection on the mean)
        closeness = np.einsum("mki,mi->mk", v, v.sum(axis=1))
        order = _PERM_ROW[np.argsort(-closeness, axis=1) @ np.array([64, 16, 4, 1])]
        codes.append((f * len(combos) + s) * len(_PERMS) + order)
        largest.append(edges[:, 5])
    if not keys:  # a catalog too sparse for any pattern
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
    key = np.concatenate(keys)
    order = np.argsort(key, kind="stable")
    return key[order], np.concatenate(codes)[order], np.concatenate(largest)[order]


_TABLES = process_cache("4-star pattern tables")


def build_pattern_table(
    database: PairDatabase,
    *,
    stars_per_field: int = 10,
    field_radius_fraction: float = FIELD_RADIUS_FRACTION,
    oversampling: float = 100.0,
    bins: int = 50,
    use_cache: bool = True,
    region: tuple[np.ndarray, float] | None = None,
    local: bool = False,
) -> PatternTable:
    """The pattern table for ``database``'s catalog and field (its ``max_angle_rad`` is the
    field diagonal). Lattice fields have a radius of ``field_radius_fraction`` times half the
    diagonal (0.85: a little larger than the circle inscribed in a square field, 0.71).
    ``region``: (unit vector, radius in rad): only the lattice fields centred within it (a
    table of the sky near a position hint; never cached). ``local``: the patterns of each
    star's neighbourhood of ``stars_per_field`` (``_local_patterns``) instead of the lattice
    fields' brightest (``field_radius_fraction``, ``oversampling`` and ``region`` unused).

    Kept in memory per (catalog, angle, options) and cached on disk next to the pair
    databases.
    """
    use_cache = use_cache and region is None
    catalog = database.catalog
    options = (stars_per_field, round(field_radius_fraction, 6), round(oversampling, 6), bins)
    if local:  # (the lattice tables' keys as they were)
        options = ("local", stars_per_field, bins)
    mem_key = (catalog.fingerprint, round(float(np.degrees(database.max_angle_rad)), 3), options)
    if local:  # a neighbourhood does not depend on the field
        mem_key = (catalog.fingerprint, options)
    if use_cache and mem_key in _TABLES:
        return _TABLES[mem_key]
    key = hashlib.sha1(f"{_FORMAT_VERSION}|{mem_key}".encode()).hexdigest()[:20]
    path = cache_dir() / f"pattern4-{key}.npz"
    data = load_cached(path) if use_cache else None
    names = {"keys", "codes", "fields", "largest_edge_steps", "edge_step_rad", "bins", "build_s"}
    if data is not None and names <= data.keys():
        table = PatternTable(
            data["keys"],
            data["codes"],
            data["fields"],
            data["largest_edge_steps"],
            float(data["edge_step_rad"]),
            int(data["bins"]),
            float(data["build_s"]),
            True,
            path,
        )
        _TABLES[mem_key] = table
        return table
    t0 = time.perf_counter()
    radius = 0.5 * field_radius_fraction * database.max_angle_rad
    if local:
        fields, field, subset = _local_patterns(database, stars_per_field)
    else:
        fields, field, subset = _field_patterns(
            database, stars_per_field, radius, oversampling, region
        )
    keys, codes, largest = _pattern_keys(catalog.vectors, fields, field, subset, bins)
    step = float(largest.max()) / _EDGE_STEPS if len(largest) and largest.max() > 0 else 1.0
    steps = np.rint(largest / step).astype(np.uint16)
    # 16-bit rows when they (and the padding, the catalog size) fit
    fields = fields.astype(np.uint16 if len(catalog) <= np.iinfo(np.uint16).max else np.int32)
    n_codes = len(fields) * math.comb(stars_per_field, 4) * len(_PERMS)
    codes = codes.astype(np.uint32 if n_codes <= np.iinfo(np.uint32).max + 1 else np.int64)
    keys = keys.astype(_key_dtype(bins))
    build_s = time.perf_counter() - t0
    arrays = {"keys": keys, "codes": codes, "fields": fields, "largest_edge_steps": steps}
    saved = (
        save_cached(path, **arrays, edge_step_rad=step, bins=bins, build_s=build_s)
        if use_cache
        else None
    )
    table = PatternTable(keys, codes, fields, steps, step, bins, build_s, False, saved)
    if use_cache:
        _TABLES[mem_key] = table
    return table


@dataclass(frozen=True)
class PatternMatches:
    """Matches of a batch of observed patterns: for hypothesis h, observed pattern
    ``pattern[h]``, its stars ``obs_local[h]`` (positions 0-3 in the pattern) paired with
    catalog rows ``cat_rows[h]``, and the ``parity``; grouped by pattern, best first."""

    pattern: np.ndarray
    obs_local: np.ndarray
    cat_rows: np.ndarray
    parity: np.ndarray


def _no_matches() -> PatternMatches:
    e = np.empty(0, dtype=np.intp)
    return PatternMatches(e, np.empty((0, 4), dtype=np.intp), np.empty((0, 4), dtype=np.intp), e)


def concat_matches(parts: list[PatternMatches], offsets: list[int]) -> PatternMatches:
    """The matches of consecutive batches of observed patterns as one batch's (``offsets``:
    where each batch starts)."""
    return PatternMatches(
        np.concatenate([h.pattern + o for h, o in zip(parts, offsets, strict=True)]),
        np.concatenate([h.obs_local for h in parts]),
        np.concatenate([h.cat_rows for h in parts]),
        np.concatenate([h.parity for h in parts]),
    )


def match_patterns(
    obs: np.ndarray,
    table: PatternTable,
    vectors: np.ndarray,
    tol_rad: float,
    max_angle_rad: float,
    parity: int | None,
    *,
    scale_range: tuple[float, float] | None = None,
    rel_tol: float = 0.0,
    deadline: Deadline | None = None,
) -> PatternMatches:
    """Catalog patterns agreeing with the observed patterns ``obs`` (p, 4, 3), each edge
    within ``tol_rad`` (radians) of the measured one; ``vectors``: catalog unit vectors.
    Patterns are matched in halves while their table look-ups or candidates are too many
    (``_MAX_PROBES``, ``_MAX_CANDIDATES``: memory and time), and no further half is matched
    once ``deadline`` has passed (the caller then drops what was found).

    With ``scale_range`` (lo, hi) the observed angles are known only up to a scale: a catalog
    pattern agrees when its largest edge is lo..hi times the observed one and its edges agree
    with the observed ones times that factor, within ``tol_rad`` plus ``rel_tol`` times the
    edge (the field of view is unknown and the bearings were made with a guessed one)."""
    p = len(obs)
    if expired(deadline):
        return _no_matches()
    edges = pattern_edges(obs)
    largest = edges.max(axis=1)
    lo, hi, n_prefix = _probe_bins(
        edges, largest, table.bins, tol_rad, max_angle_rad, scale_range, rel_tol
    )
    found = None
    if n_prefix.sum() <= _MAX_PROBES or p == 1:
        found = _table_candidates(table, lo, hi, n_prefix, None if p == 1 else _MAX_CANDIDATES)
    if found is None:  # too many: in halves
        half = p // 2
        more = {"scale_range": scale_range, "rel_tol": rel_tol, "deadline": deadline}
        parts = [
            match_patterns(obs[sub], table, vectors, tol_rad, max_angle_rad, parity, **more)
            for sub in (slice(None, half), slice(half, None))
        ]
        return concat_matches(parts, [0, half])
    cand_pat, cand_row = found
    if len(cand_pat) == 0:
        return _no_matches()
    cand_pat, cat_stars, cat_vec, cat_edges, cat_largest = _largest_edge_candidates(
        table, vectors, cand_pat, cand_row, largest, tol_rad, scale_range, rel_tol
    )
    if len(cand_pat) == 0:
        return _no_matches()
    # observed edges are multiplied by this to compare with the catalog's
    scale = np.ones(len(cand_pat)) if scale_range is None else cat_largest / largest[cand_pat]
    canon, c, k, err = _star_orders(obs, largest, cand_pat, cat_edges, scale, tol_rad, rel_tol)
    if len(c) == 0:
        return _no_matches()
    pat_h = cand_pat[c]
    obs_local = canon[pat_h[:, None], _PERMS[k]]  # observed star paired with catalog star k
    return _with_parity(
        obs, largest, pat_h, obs_local, cat_stars[c], cat_vec[c], err, tol_rad, parity
    )


def _probe_bins(
    edges: np.ndarray,
    largest: np.ndarray,
    bins: int,
    tol_rad: float,
    max_angle_rad: float,
    scale_range: tuple[float, float] | None,
    rel_tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bins the five edge ratios of each observed pattern may fall in, lowest and
    highest (p, 5), and the number of key prefixes (bins of the first four ratios) to look
    up per pattern (0 for a pattern that cannot match: an edge too short to measure, or the
    largest too long for the table)."""
    lo_scale = scale_range[0] if scale_range is not None else 1.0
    usable = (edges.min(axis=1) >= 2.0 * tol_rad) & (largest * lo_scale <= max_angle_rad + tol_rad)
    # the ratio e / L of edges measured within tol: off by at most tol (1 + e/L) / (L - tol)
    ratios = np.sort(edges, axis=1)[:, :5] / largest[:, None]
    slack = tol_rad * (1.0 + ratios) / np.maximum(largest - tol_rad, tol_rad)[:, None]
    slack = slack + 2.0 * rel_tol
    lo = np.clip(np.floor((ratios - slack) * bins), 0, bins - 1).astype(np.int64)
    hi = np.clip(np.floor((ratios + slack) * bins), 0, bins - 1).astype(np.int64)
    span = hi - lo + 1
    # the bins of the first four ratios are enumerated; the fifth is a contiguous key range
    n_prefix = np.where(usable, np.prod(span[:, :4], axis=1), 0)
    return lo, hi, n_prefix


def _table_candidates(
    table: PatternTable,
    lo: np.ndarray,
    hi: np.ndarray,
    n_prefix: np.ndarray,
    most: int | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Every (observed pattern, table row) whose key lies in the pattern's bins: each of its
    ``n_prefix`` prefixes, then the key range of the fifth ratio's bins; None when they are
    more than ``most``."""
    total = int(n_prefix.sum())
    empty = np.empty(0, dtype=np.intp)
    if total == 0:
        return empty, empty
    B = table.bins
    span = hi - lo + 1
    pat = np.repeat(np.arange(len(n_prefix)), n_prefix)
    rest = np.arange(total) - np.repeat(np.cumsum(n_prefix) - n_prefix, n_prefix)
    prefix = np.zeros(total, dtype=np.int64)
    place = np.ones(total, dtype=np.int64)
    for d in (3, 2, 1, 0):
        s = span[pat, d]
        prefix += (lo[pat, d] + rest % s) * place
        rest //= s
        place *= B
    key_lo = (prefix * B + lo[pat, 4]).astype(table.keys.dtype)
    key_hi = (prefix * B + hi[pat, 4]).astype(table.keys.dtype)
    start = np.searchsorted(table.keys, key_lo, side="left")
    count = np.searchsorted(table.keys, key_hi, side="right") - start
    n_cand = int(count.sum())
    if most is not None and n_cand > most:
        return None
    if n_cand == 0:
        return empty, empty
    cand_pat = np.repeat(pat, count)
    cand_row = np.repeat(start, count) + (
        np.arange(n_cand) - np.repeat(np.cumsum(count) - count, count)
    )
    return cand_pat, cand_row


def _largest_edge_candidates(
    table: PatternTable,
    vectors: np.ndarray,
    cand_pat: np.ndarray,
    cand_row: np.ndarray,
    largest: np.ndarray,
    tol_rad: float,
    scale_range: tuple[float, float] | None,
    rel_tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The candidates (observed pattern ``cand_pat``, table row ``cand_row``) whose largest
    edge agrees with the observed one (``_largest_agrees``): their observed pattern, catalog
    stars (m, 4), star vectors (m, 4, 3), edges (m, 6) and largest edge (m,)."""
    # the stored largest edge (within half a step) is a quick first test; the same test on
    # the exact edges, recomputed from the catalog vectors, follows
    step = table.edge_step_rad
    near = table.largest_edge_steps[cand_row] * step
    ok = _largest_agrees(near, largest[cand_pat], tol_rad, step, scale_range, rel_tol)
    cand_pat, cand_row = cand_pat[ok], cand_row[ok]
    cat_stars = table.stars(cand_row)
    cat_vec = vectors.take(cat_stars, axis=0)
    cat_edges = pattern_edges(cat_vec)
    # the largest of six columns: faster than ``max(axis=1)``, which loops over short rows
    cat_largest = functools.reduce(np.maximum, cat_edges.T)
    ok = _largest_agrees(cat_largest, largest[cand_pat], tol_rad, 0.0, scale_range, rel_tol)
    if not ok.all():  # only those within half a step of a limit are left out here
        cand_pat, cat_stars, cat_vec = cand_pat[ok], cat_stars[ok], cat_vec[ok]
        cat_edges, cat_largest = cat_edges[ok], cat_largest[ok]
    return cand_pat, cat_stars, cat_vec, cat_edges, cat_largest


def _largest_agrees(
    cat_largest: np.ndarray,
    obs_largest: np.ndarray,
    tol_rad: float,
    margin_rad: float,
    scale_range: tuple[float, float] | None,
    rel_tol: float,
) -> np.ndarray:
    """Whether catalog largest edges, known within ``margin_rad``, agree with the observed
    ones: within ``tol_rad``, or with ``scale_range``, lo..hi times them (with ``rel_tol``)."""
    if scale_range is None:
        return np.abs(cat_largest - obs_largest) <= tol_rad + margin_rad
    lo_scale, hi_scale = scale_range
    return (cat_largest + margin_rad >= lo_scale * (obs_largest - tol_rad) * (1.0 - rel_tol)) & (
        cat_largest - margin_rad <= hi_scale * (obs_largest + tol_rad) * (1.0 + rel_tol)
    )


def _star_orders(
    obs: np.ndarray,
    largest: np.ndarray,
    cand_pat: np.ndarray,
    cat_edges: np.ndarray,
    scale: np.ndarray,
    tol_rad: float,
    rel_tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairings of observed with catalog stars whose six edges agree: the observed stars
    in canonical order ``canon`` (p, 4) and, for each agreeing pairing, its candidate ``c``,
    the row ``k`` of ``_PERMS`` that reorders ``canon`` to the catalog pattern, and its
    largest edge error ``err`` (radians)."""
    # the observed stars in canonical order; where centroid distances are closer than their
    # error allows to tell apart, every order consistent with them is tried
    dist = centroid_distances(obs)
    canon = np.argsort(dist, axis=1)
    dist_sorted = np.take_along_axis(dist, canon, axis=1)
    canon_edges = pattern_edges(np.take_along_axis(obs, canon[:, :, None], axis=1))
    # a distance from the centroid is off by at most two star errors (the star's and the
    # centroid's), each below tol / sqrt(2): a difference of two by 2 sqrt(2) tol
    tie_rad = 3.0 * tol_rad + 2.0 * rel_tol * largest
    from starnav.identify.kernels import patterns  # numba: loaded on first use

    c, k, err = patterns.agreeing_orders(
        np.ascontiguousarray(dist_sorted),
        np.ascontiguousarray(tie_rad, dtype=np.float64),
        np.ascontiguousarray(canon_edges),
        np.ascontiguousarray(cand_pat, dtype=np.int64),
        np.ascontiguousarray(cat_edges, dtype=np.float64),
        np.ascontiguousarray(scale, dtype=np.float64),
        float(tol_rad),
        float(rel_tol),
        _PERMS,
        _PERM_EDGES,
        _PAIRS,
    )
    return canon, c.astype(np.intp), k.astype(np.intp), err


def _with_parity(
    obs: np.ndarray,
    largest: np.ndarray,
    pat_h: np.ndarray,
    obs_local: np.ndarray,
    cat_rows: np.ndarray,
    cat_vec: np.ndarray,
    err: np.ndarray,
    tol_rad: float,
    parity: int | None,
) -> PatternMatches:
    """The matches with their parity, from the orientation of each pattern's best-spread
    triangle (both parities where it is too flat to tell), those of another ``parity`` left
    out, grouped by observed pattern with the closest edge agreement first."""
    from starnav.identify.kernels import patterns  # numba: loaded on first use

    par, spread = patterns.pairing_parities(
        np.ascontiguousarray(obs, dtype=np.float64),
        np.ascontiguousarray(pat_h, dtype=np.int64),
        np.ascontiguousarray(obs_local, dtype=np.int64),
        np.ascontiguousarray(cat_vec, dtype=np.float64),
        _TRIPLES,
    )
    flat = spread < 3.0 * tol_rad * largest[pat_h]
    if flat.any():  # too flat to tell the orientation: both
        f = np.flatnonzero(flat)
        pat_h = np.concatenate([pat_h, pat_h[f]])
        obs_local = np.concatenate([obs_local, obs_local[f]])
        cat_rows = np.concatenate([cat_rows, cat_rows[f]])
        par = np.concatenate([par, -par[f]])
        err = np.concatenate([err, err[f]])
    if parity is not None:
        keep = par == parity
        pat_h, obs_local, cat_rows, par, err = (
            pat_h[keep],
            obs_local[keep],
            cat_rows[keep],
            par[keep],
            err[keep],
        )
    # grouped by observed pattern, the closest edge agreement first
    o = np.lexsort((err, pat_h))
    return PatternMatches(pat_h[o], obs_local[o], cat_rows[o], par[o])


class Pattern4:
    """4-star patterns hashed on their edge ratios (tetra3 / cedar-solve), verified on the
    whole field.

    Options: ``pattern_stars``: observed patterns are made of the brightest this many stars
    (tetra3's "pattern checking stars"; also capped by ``MatchSettings.max_stars``);
    ``stars_per_field``, ``field_radius_fraction``, ``oversampling``, ``bins``: how the
    pattern table is built (see ``build_pattern_table``).
    """

    name = "pattern4"

    def __init__(
        self,
        *,
        pattern_stars: int = 15,
        stars_per_field: int = 10,
        field_radius_fraction: float = FIELD_RADIUS_FRACTION,
        oversampling: float = 100.0,
        bins: int = 50,
    ) -> None:
        checks = (
            ("pattern_stars", pattern_stars, pattern_stars >= 4),
            ("stars_per_field", stars_per_field, stars_per_field >= 4),
            ("field_radius_fraction", field_radius_fraction, 0.0 < field_radius_fraction <= 1.0),
            ("oversampling", oversampling, oversampling > 0.0),
            ("bins", bins, 2 <= bins <= 6000),
        )
        for name, value, ok in checks:
            if not ok:
                raise StarnavError(f"{name}={shown(value)} is out of range")
        self.pattern_stars = pattern_stars
        self.table_options = {
            "stars_per_field": stars_per_field,
            "field_radius_fraction": field_radius_fraction,
            "oversampling": oversampling,
            "bins": bins,
        }

    def table(self, database: PairDatabase) -> PatternTable:
        """The pattern table for ``database``'s catalog and field (built on first use)."""
        return build_pattern_table(database, **self.table_options)

    def database_nbytes(self, database: PairDatabase) -> int:
        """Bytes of the pattern table and of the catalog and KD-tree (``catalog_nbytes``; the
        pair table is not used)."""
        return self.table(database).nbytes + catalog_nbytes(database)

    @screen_stars_only
    def identify(
        self,
        bearings: np.ndarray,
        order: np.ndarray,
        database: PairDatabase,
        settings: MatchSettings,
    ) -> IdentifyOutcome:
        """Identify camera-frame ``bearings`` (n, 3); ``order`` lists rows best-first."""
        order = np.asarray(order)[: min(settings.max_stars, self.pattern_stars)]
        if len(order) < 4:
            return IdentifyOutcome(None, "fewer than 4 stars", 0)
        table = self.table(database)
        vectors = database.catalog.vectors
        tester = HypothesisTester(bearings, database, settings, order=order)
        combos = breadth_first_combinations(len(order))
        # batches end where a new star joins (C(m, 4) for m = 5, 7, 9, ...): most fields are
        # identified by the first few patterns, so the first batch is small
        ends = [math.comb(m, 4) for m in range(5, len(order), 2)] + [len(combos)]
        start = 0
        for end in ends:
            if end <= start:
                continue
            rows = order[combos[start:end]]  # (p, 4) bearing rows of each observed pattern
            hyp = match_patterns(
                bearings[rows],
                table,
                vectors,
                settings.pair_tol_rad,
                database.max_angle_rad,
                settings.parity,
            )
            start = end
            if len(hyp.pattern) == 0:
                continue
            bounds = np.flatnonzero(np.diff(hyp.pattern)) + 1
            for group in np.split(np.arange(len(hyp.pattern)), bounds):
                tester.count(len(group))  # every hypothesis of the pattern, before testing
                for h in group:
                    outcome = tester.test(
                        rows[hyp.pattern[h], hyp.obs_local[h]],
                        hyp.cat_rows[h],
                        int(hyp.parity[h]),
                    )
                    if outcome is not None:
                        return outcome
                    if tester.exhausted:
                        return tester.outcome()
        return tester.outcome("no 4-star pattern matches the catalog")
