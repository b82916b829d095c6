"""The kernels of a clean star-tracker frame's detection (numba): its background on tiles,
its sources (sep's 3 x 3 matched filter, a threshold, 8-connected pixels split at their
saddles) and each source's photometry against its own annulus. ``starnav.detect.tracker``
is their Python face; they are imported on first use (numba takes ~0.2 s to load). Two of
them give sep's own numbers without its cost per call, for either path's unmasked images:
the windowed centroid (``windowed_centroids``, ``sep.winpos``) and the half-light radius
(``half_light_radii``, ``sep.flux_radius``), which ``starnav.detect.stars`` and
``starnav.detect.psf`` call; ``plateau`` is every image's saturation test.

Pixel coordinates here are sep's: pixel centres at integers.
"""

from __future__ import annotations

import math

import numpy as np

from starnav.runtime.caching import njit

CLIPPED_GAUSSIAN_STD = 0.98664  # the std of a Gaussian clipped at 3 sigmas, in sigmas
_MAD_TO_SIGMA = 1.4826
_START_SAMPLES = 17  # a tile's clipping starts from the median of this many of its pixels
_MAD_BINS = 256  # of the histogram a tile's median absolute deviation is read from
# sep's deblending, as ``starnav.detect.stars`` calls it: 16 levels, contrast 0.005
DEBLEND_LEVELS = 16
DEBLEND_CONTRAST = 0.005
# SExtractor's windowed centroid (``windowed_centroids``)
WINDOW_SIGMAS = 4.0
_WINDOW_STEPS = 16
_WINDOW_OFFSET_MIN_PX = 1e-4
_WINDOW_GAIN = 2.0
_CHUNK_PX = 64  # a row's stretch checked at once for pixels over a threshold
# sep.flux_radius's annuli (``half_light_radii``): how many, and how close (px) to an edge a
# pixel's centre must come to be split into samples
_RADIUS_BINS = 64
_BIN_MARGIN_PX = 0.7072
_REACH_MARGIN_PX = 0.01
# status of ``find_sources``
FOUND, TOO_MANY_PIXELS, PLATEAU = 0, 1, 2


@njit(cache=True)
def _select(values, n, k):
    """The k-th smallest of ``values[:n]``, reordering them in place (quickselect, the
    smaller ones left below k). Each pass splits the range at the median of its ends and
    middle by a partition without branches (every element swapped, the split point moved by
    the comparison's outcome): the branches of a classic partition go either way at random,
    and their mispredictions cost most of its time (a 140-pixel annulus's median 2x faster).
    A pivot that is the range's least is split off with its equals. (NaN values: some value
    or NaN, and an end.)"""
    lo, hi = 0, n - 1
    while lo < hi:
        a, b, c = values[lo], values[(lo + hi) // 2], values[hi]
        pivot = max(min(a, b), min(max(a, b), c))
        store = lo
        for i in range(lo, hi + 1):
            v = values[i]
            values[i] = values[store]
            values[store] = v
            store += v < pivot
        if k < store:
            hi = store - 1
        elif store > lo:
            lo = store
        else:  # nothing below the pivot: its equals next, then what lies above
            for i in range(lo, hi + 1):
                v = values[i]
                values[i] = values[store]
                values[store] = v
                store += v <= pivot
            if k < store or store == lo:  # none equal: a NaN pivot, which is the answer
                return pivot
            lo = store
    return values[k]


@njit(cache=True)
def _median(values, n):
    """The median of ``values[:n]`` (n >= 1), reordering them in place."""
    high = _select(values, n, n // 2)
    if n % 2:
        return high
    low = values[0]
    for i in range(1, n // 2):  # the largest of the lower half, which select left below
        low = max(low, values[i])
    return 0.5 * (low + high)


@njit(cache=True)
def _level_rms(values, dx, dy, n, scratch):
    """(level, rms) of ``values[:n]`` at offsets (``dx``, ``dy``) from the tile's centre: a
    plane fitted to the values within 3 sigmas of it, clipped three times from the median
    and median absolute deviation of ``_START_SAMPLES`` of them spread over the n (the
    clipping's sigma the std about the plane over that of a clipped Gaussian); the level is
    the plane at the centre, the rms the median absolute deviation about it x 1.4826, as the
    real-sky mesh has it (a gradient of vignetting or moonlight is not noise), or the std
    where that is 0. (The median of all of them would need a selection, whose unpredictable
    branches cost 4x the whole.) With ``dx`` and ``dy`` zeros, a constant instead of a
    plane. ``scratch``: ``_START_SAMPLES`` values."""
    k = min(n, _START_SAMPLES)
    every = n // k
    for i in range(k):
        scratch[i] = values[i * every]
    level = _median(scratch, k)
    for i in range(k):
        scratch[i] = abs(values[i * every] - level)
    rms = _MAD_TO_SIGMA * _median(scratch, k)
    if not rms > 0:
        rms = values[:n].std()
    gx, gy = 0.0, 0.0
    for _ in range(3):
        count, sx, sy, sxx, syy, total, tx, ty, squares = _clipped_sums(
            values[:n], dx[:n], dy[:n], level, gx, gy, 3.0 * rms
        )
        if count < 4:
            break
        # the plane's correction, as if the kept samples were symmetric about their mean
        mx, my, mean = sx / count, sy / count, total / count
        vx, vy = sxx - sx * mx, syy - sy * my
        cx = (tx - mean * sx) / vx if vx > 0 else 0.0
        cy = (ty - mean * sy) / vy if vy > 0 else 0.0
        spread = squares / count - mean * mean - cx * (tx / count - mean * mx)
        spread -= cy * (ty / count - mean * my)
        gx, gy = gx + cx, gy + cy
        level += mean - cx * mx - cy * my
        rms = math.sqrt(max(spread, 0.0)) / CLIPPED_GAUSSIAN_STD
    # as the real-sky mesh measures it: the median absolute deviation about the plane of the
    # values within 3 sigmas, x 1.4826 (on a sky clipped or skewed near the black level it
    # differs from the std, and the threshold with it)
    mad = _abs_median(values, dx, dy, n, level, gx, gy, 3.0 * rms)
    if mad > 0:
        rms = _MAD_TO_SIGMA * mad
    return level, rms


@njit(cache=True, fastmath={"reassoc", "nsz"})
def _clipped_sums(values, dx, dy, level, gx, gy, limit):
    """Over the ``values`` within ``limit`` of the plane level + gx dx + gy dy, their residual
    d from it: the sums of 1, dx, dy, dx², dy², d, d dx, d dy, d², added in whatever order
    the compiler vectorizes them in (``_level_rms``'s clipping; the order changes the sums
    in their last bits only)."""
    count, sx, sy, sxx, syy = 0.0, 0.0, 0.0, 0.0, 0.0
    total, tx, ty, squares = 0.0, 0.0, 0.0, 0.0
    for i in range(len(values)):
        d = values[i] - level - gx * dx[i] - gy * dy[i]
        kept = 1.0 if abs(d) <= limit else 0.0
        count += kept
        sx += kept * dx[i]
        sy += kept * dy[i]
        sxx += kept * dx[i] * dx[i]
        syy += kept * dy[i] * dy[i]
        total += kept * d
        tx += kept * d * dx[i]
        ty += kept * d * dy[i]
        squares += kept * d * d
    return count, sx, sy, sxx, syy, total, tx, ty, squares


@njit(cache=True)
def _abs_median(values, dx, dy, n, level, gx, gy, limit):
    """The median of |v - plane| over the values within ``limit`` of the plane level + gx
    dx + gy dy: from a histogram of ``_MAD_BINS`` bins up to ``limit``, linear within the
    median's bin (to ~1/1000 of ``limit``: a selection's unpredictable branches cost more);
    0 for none."""
    counts = np.zeros(_MAD_BINS + 1, dtype=np.int64)  # whole numbers: a shorter latency
    scale = _MAD_BINS / limit if limit > 0 else 0.0
    for i in range(n):
        bin_ = min(int(abs(values[i] - level - gx * dx[i] - gy * dy[i]) * scale), _MAD_BINS)
        counts[bin_] += 1
    kept = float(counts[:_MAD_BINS].sum())
    if kept == 0.0 or scale == 0.0:
        return 0.0
    below = 0.0
    for b in range(_MAD_BINS):
        count = float(counts[b])
        if below + count >= 0.5 * kept:
            return (b + (0.5 * kept - below) / count) / scale
        below += count
    return limit


@njit(cache=True)
def tile_statistics(data, tile_px, stride, low):
    """Per tile of ``tile_px`` px a side (the last row and column of tiles may be shorter),
    from every other pixel of every ``stride``-th row (a row's pixels share cache lines):
    (level, pixel rms, white rms, samples at ``low``). level and rms: ``_level_rms`` of the
    pixels; white rms, on every other tile each way (NaN on the others): the rms of the
    differences of horizontally adjacent pixels over sqrt 2 (noise only: a smooth gradient
    or the smoothing of JPEG compression does not change from one pixel to the next); the
    last: how many samples in all equal ``low`` (a sky clipped at the black level)."""
    height, width = data.shape
    ny, nx = -(-height // tile_px), -(-width // tile_px)
    level = np.empty((ny, nx))
    rms = np.empty((ny, nx))
    white = np.empty((ny, nx))
    at_low = 0
    most = -(-tile_px // stride) * -(-tile_px // 2)
    values = np.empty(most)
    dx = np.empty(most)
    dy = np.empty(most)
    steps = np.empty(most)
    flat = np.zeros(most)
    scratch = np.empty(_START_SAMPLES)
    for i in range(ny):
        for j in range(nx):
            n = 0
            m = 0
            yc = 0.5 * (i * tile_px + min((i + 1) * tile_px, height))
            xc = 0.5 * (j * tile_px + min((j + 1) * tile_px, width))
            for y in range(i * tile_px + stride // 2, min((i + 1) * tile_px, height), stride):
                for x in range(j * tile_px, min((j + 1) * tile_px, width), 2):
                    v = data[y, x]
                    values[n] = v
                    dx[n], dy[n] = x + 0.5 - xc, y + 0.5 - yc
                    n += 1
                    if v == low:
                        at_low += 1
                    if x + 1 < width:
                        steps[m] = data[y, x + 1] - v
                        m += 1
            if n == 0:  # a tile narrower than half the stride: its first pixel
                values[0] = data[min(i * tile_px, height - 1), min(j * tile_px, width - 1)]
                dx[0], dy[0] = 0.0, 0.0
                n = 1
            level[i, j], rms[i, j] = _level_rms(values, dx, dy, n, scratch)
            white[i, j] = np.nan
            if m > 1 and i % 2 == 0 and j % 2 == 0:
                white[i, j] = _level_rms(steps, flat, flat, m, scratch)[1] / math.sqrt(2.0)
    return level, rms, white, at_low


@njit(cache=True)
def median_3x3(mesh):
    """The median of each cell's 3 x 3 neighbourhood of a finite ``mesh``, the edge cells
    repeated beyond it (``scipy.ndimage.median_filter(mesh, size=3, mode="nearest")``'s
    numbers; both detection paths' tile meshes)."""
    ny, nx = mesh.shape
    out = np.empty((ny, nx))
    window = np.empty(9)
    for i in range(ny):
        for j in range(nx):
            k = 0
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    window[k] = mesh[min(max(i + di, 0), ny - 1), min(max(j + dj, 0), nx - 1)]
                    k += 1
            out[i, j] = _select(window, 9, 4)
    return out


@njit(cache=True)
def _tile_centres(n, tile_px, tiles):
    """The centres (px, corner origin) of the tiles along an axis of ``n`` px: the middle
    of each tile's pixels (the last tile may be shorter)."""
    centre = np.empty(tiles)
    for k in range(tiles):
        centre[k] = 0.5 * (k * tile_px + min((k + 1) * tile_px, n))
    return centre


@njit(cache=True)
def _interpolated(values, centre, n, out):
    """``values`` given at ``centre``s interpolated linearly to the centres of ``n`` pixels
    (constant beyond the outer centres), into ``out``."""
    tiles = len(values)
    # pixels c with c + 0.5 <= centre[k]: the first ``edge[k]``
    edge = np.empty(tiles, dtype=np.int64)
    for k in range(tiles):
        edge[k] = min(n, max(0, math.floor(centre[k] - 0.5) + 1))
    for c in range(edge[0]):
        out[c] = values[0]
    for k in range(tiles - 1):
        slope = (values[k + 1] - values[k]) / (centre[k + 1] - centre[k])
        base = values[k] + slope * (0.5 - centre[k])
        for c in range(edge[k], edge[k + 1]):
            out[c] = base + slope * c
    for c in range(edge[tiles - 1], n):
        out[c] = values[tiles - 1]


@njit(cache=True)
def _across(level, tile_px, height, width):
    """(each row of tiles' values interpolated across the ``width`` columns, the tile rows'
    centres): the first half of ``_map_row``'s bilinear interpolation."""
    ny, nx = level.shape
    across = _tile_centres(width, tile_px, nx)
    rows = np.empty((ny, width))
    for i in range(ny):
        _interpolated(level[i], across, width, rows[i])
    return rows, _tile_centres(height, tile_px, ny)


@njit(cache=True)
def _map_row(rows, down, r, out):
    """Row ``r`` of a tile map interpolated bilinearly between tile centres (constant beyond
    the outer ones), from ``_across``'s (rows, down), into ``out``."""
    ny = len(down)
    at = r + 0.5
    k = 0
    while k < ny - 1 and down[k + 1] <= at:
        k += 1
    lower = rows[k]
    if at <= down[k] or k == ny - 1:
        out[:] = lower
        return
    upper = rows[k + 1]
    w = (at - down[k]) / (down[k + 1] - down[k])
    for c in range(len(out)):
        out[c] = lower[c] + w * (upper[c] - lower[c])


@njit(cache=True)
def background_subtracted(data, level, tile_px, above, out):
    """``data`` less its background, into ``out`` (float32, its shape): the tile ``level``s
    interpolated bilinearly between tile centres (constant beyond the outer ones); returns
    the flat indices, in raster order, of its pixels over ``above``: the candidates
    ``starnav.detect.hot`` judges."""
    height, width = data.shape
    rows, down = _across(level, tile_px, height, width)
    back = np.empty(width)
    over = np.empty(max(1024, height * width // 256), dtype=np.int64)  # grown when full
    n = 0
    limit = np.empty(width, dtype=np.float32)
    limit[:] = above
    for r in range(height):
        _map_row(rows, down, r, back)
        row = out[r]
        for c in range(width):
            row[c] = data[r, c] - back[c]
        for start in range(0, width, _CHUNK_PX):
            stop = min(width, start + _CHUNK_PX)
            if _count_over(row[start:stop], limit[start:stop]) == 0:
                continue
            if n + stop - start > len(over):
                over = np.concatenate((over, np.empty_like(over)))
            # every index written, the count moved by the test: no branch to mispredict
            for c in range(start, stop):
                over[n] = r * width + c
                n += row[c] > above
    return over[:n].copy()


@njit(cache=True, inline="always")
def _count_over(values, limits):
    """How many ``values`` exceed their ``limits``: a loop without branches, which the
    compiler vectorizes, so that the pixels over a threshold (few) are looked for only in
    the stretches of a row that hold some."""
    count = 0
    for c in range(len(values)):
        count += values[c] > limits[c]
    return count


@njit(cache=True, inline="always")
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True, inline="always")
def _row_sums(data, r, out):
    """[1 2 1] along row ``r`` of ``data`` (zero beyond the edges; a row outside: zeros)."""
    height, width = data.shape
    if r < 0 or r >= height:
        out[:] = 0.0
        return
    row = data[r]
    two = np.float32(2.0)
    for c in range(1, width - 1):
        out[c] = row[c - 1] + two * row[c] + row[c + 1]
    out[0] = two * row[0] + (row[1] if width > 1 else np.float32(0.0))
    if width > 1:
        out[width - 1] = row[width - 2] + two * row[width - 1]


@njit(cache=True)
def _pixels_above(data, threshold, tile_px, capacity):
    """The pixels whose 3 x 3 filtered value ([1 2 1] x [1 2 1] / 16, zero beyond the
    edges) exceeds the ``threshold`` map (per tile of ``tile_px`` px, interpolated as the
    background is), in raster order: (rows, columns, filtered values, their 8-connected
    group's root, count); count -1 when more than ``capacity``."""
    height, width = data.shape
    rows = np.empty(capacity, dtype=np.int32)
    cols = np.empty(capacity, dtype=np.int32)
    values = np.empty(capacity, dtype=np.float32)
    parent = np.empty(capacity, dtype=np.int64)
    index = np.empty((2, width), dtype=np.int64)
    stamp = np.full((2, width), -2, dtype=np.int64)
    above = np.empty(width, dtype=np.float32)
    here = np.empty(width, dtype=np.float32)
    below = np.empty(width, dtype=np.float32)
    filtered = np.empty(width, dtype=np.float32)
    level = np.empty(width)
    maps, down = _across(threshold, tile_px, height, width)
    constant = threshold.min() == threshold.max()  # its interpolation: that value everywhere
    level[:] = threshold[0, 0]
    _row_sums(data, -1, above)
    _row_sums(data, 0, here)
    n = 0
    for r in range(height):
        _row_sums(data, r + 1, below)
        two, sixteenth = np.float32(2.0), np.float32(1.0 / 16.0)
        for c in range(width):
            filtered[c] = (above[c] + two * here[c] + below[c]) * sixteenth
        if not constant:
            _map_row(maps, down, r, level)
        now, before = r % 2, (r + 1) % 2
        for start in range(0, width, _CHUNK_PX):
            stop = min(width, start + _CHUNK_PX)
            if _count_over(filtered[start:stop], level[start:stop]) == 0:
                continue
            for c in range(start, stop):
                f = filtered[c]
                if not f > level[c]:
                    continue
                if n == capacity:
                    return rows, cols, values, parent, -1
                rows[n], cols[n], values[n], parent[n] = r, c, f, n
                # 8-connected neighbours seen before: left, and the three above
                if c > 0 and stamp[now, c - 1] == r:
                    _join(parent, n, index[now, c - 1])
                for dc in (-1, 0, 1):
                    cc = c + dc
                    if 0 <= cc < width and stamp[before, cc] == r - 1:
                        _join(parent, n, index[before, cc])
                index[now, c], stamp[now, c] = n, r
                n += 1
        above, here, below = here, below, above
    for i in range(n):
        parent[i] = _find(parent, i)
    return rows, cols, values, parent, n


@njit(cache=True, inline="always")
def _join(parent, a, b):
    ra, rb = _find(parent, a), _find(parent, b)
    if ra != rb:
        parent[max(ra, rb)] = min(ra, rb)


@njit(cache=True)
def _deblended(rows, cols, values, threshold, min_area):
    """Each pixel's object in one group of connected pixels (local indices 0..m-1): the
    pixels flooded from the brightest down (filtered ``values``), a branch kept as an object
    of its own where it meets a brighter one, as sep's deblending keeps it, when one of its
    ``DEBLEND_LEVELS`` levels (exponentially spaced from ``threshold`` to the group's peak)
    lies between the saddle and the branch's peak, and the branch has ``min_area`` pixels
    and ``DEBLEND_CONTRAST`` of the group's filtered flux."""
    m = len(rows)
    obj = np.arange(m)
    if m < 2 * min_area:
        return np.zeros(m, dtype=np.int64)
    r0, c0 = rows.min(), cols.min()
    bh, bw = rows.max() - r0 + 1, cols.max() - c0 + 1
    if bh * bw > 64 * m:  # a long thin group (a trail): one object, it is not a star
        return np.zeros(m, dtype=np.int64)
    grid = np.full((bh, bw), -1, dtype=np.int64)
    order = np.argsort(-values)
    total = values.sum()
    peak_all = values[order[0]]
    log_span = math.log(peak_all / threshold) if peak_all > threshold else 0.0
    basin = np.arange(m)  # union-find over the branches met so far
    area = np.zeros(m, dtype=np.int64)
    flux = np.zeros(m)
    peak = np.zeros(m)
    top = np.arange(m)  # the object a branch's new pixels join
    roots = np.empty(8, dtype=np.int64)
    for p in order:
        y, x = rows[p] - r0, cols[p] - c0
        k = 0
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                yy, xx = y + dy, x + dx
                if 0 <= yy < bh and 0 <= xx < bw and grid[yy, xx] >= 0:
                    root = _find(basin, grid[yy, xx])
                    seen = False
                    for j in range(k):
                        seen |= roots[j] == root
                    if not seen:
                        roots[k] = root
                        k += 1
        if k == 0:
            area[p], flux[p], peak[p] = 1, values[p], values[p]
            grid[y, x] = p
            continue
        win = roots[0]
        for j in range(1, k):
            if peak[roots[j]] > peak[win]:
                win = roots[j]
        saddle = values[p]
        for j in range(k):
            q = roots[j]
            if q == win:
                continue
            # the first level above the saddle, below the branch's peak?
            split = False
            if log_span > 0.0 and area[q] >= min_area and flux[q] >= DEBLEND_CONTRAST * total:
                step = math.floor(DEBLEND_LEVELS * math.log(saddle / threshold) / log_span) + 1
                level = threshold * math.exp(step * log_span / DEBLEND_LEVELS)
                split = step < DEBLEND_LEVELS and level <= peak[q]
            if not split:
                obj[top[q]] = top[win]
            basin[q] = win
            area[win] += area[q]
            flux[win] += flux[q]
        basin[p] = win
        obj[p] = top[win]
        area[win] += 1
        flux[win] += values[p]
        grid[y, x] = p
    for p in range(m):  # the absorbed branches' pixels to the object that absorbed them
        o = obj[p]
        while obj[o] != o:
            o = obj[o]
        obj[p] = o
    return obj


@njit(cache=True)
def find_sources(data, threshold, tile_px, min_area, capacity, plateau_px):
    """sep-like sources of background-subtracted ``data``: pixels whose 3 x 3 filtered value
    exceeds the ``threshold`` map (per tile of ``tile_px`` px, interpolated as the background
    is), 8-connected groups of at least ``min_area`` of them, each split into objects at its
    saddles (``_deblended``). Returns (status, per object: pixel count, flux (the sum of its
    unfiltered pixels), moments (n, 5: barycentre x, y and second moments x2, y2, xy, px
    and px², weighted by the unfiltered pixels, or by 1 where their sum is not positive),
    peaks (n, 3: the brightest pixel's value, column and row)). ``status``: ``FOUND``;
    ``TOO_MANY_PIXELS`` beyond ``capacity`` pixels above the threshold; ``PLATEAU`` when a
    group has more than ``plateau_px`` pixels (residual glow: not a clean frame); with
    either, no objects."""
    rows, cols, values, parent, n = _pixels_above(data, threshold, tile_px, capacity)
    no_count, no_flux = np.zeros(0, dtype=np.int64), np.zeros(0)
    no_moments, no_peaks = np.zeros((0, 5)), np.zeros((0, 3))
    if n < 0:
        return TOO_MANY_PIXELS, no_count, no_flux, no_moments, no_peaks
    # pixels grouped by their root (counting sort; a root is its group's first pixel)
    group = np.full(n, -1, dtype=np.int64)
    n_groups = 0
    for i in range(n):
        if parent[i] == i:
            group[i] = n_groups
            n_groups += 1
    size = np.zeros(n_groups + 1, dtype=np.int64)
    for i in range(n):
        size[group[parent[i]] + 1] += 1
    for g in range(n_groups):
        if size[g + 1] > plateau_px:
            return PLATEAU, no_count, no_flux, no_moments, no_peaks
    start = np.cumsum(size)
    fill = start[:-1].copy()
    members = np.empty(n, dtype=np.int64)
    for i in range(n):
        g = group[parent[i]]
        members[fill[g]] = i
        fill[g] += 1
    # per object: the sums of v, v x, v y, v x², v y², v x y (v: the pixel), then of 1, x,
    # y, x², y², x y; the peak pixel and where it is
    acc = np.zeros((n, 12))
    peaks = np.empty((n, 3))
    n_obj = 0
    for g in range(n_groups):
        idx = members[start[g] : start[g + 1]]
        if len(idx) < min_area:
            continue
        local = threshold[rows[idx[0]] // tile_px, cols[idx[0]] // tile_px]
        obj = _deblended(rows[idx], cols[idx], values[idx], local, min_area)
        label = np.full(len(idx), -1, dtype=np.int64)
        for k in range(len(idx)):
            o = obj[k]
            if label[o] < 0:
                label[o] = n_obj
                peaks[n_obj, 0] = -np.inf
                n_obj += 1
            t = label[o]
            y, x = float(rows[idx[k]]), float(cols[idx[k]])
            v = float(data[rows[idx[k]], cols[idx[k]]])
            for j, term in enumerate((1.0, x, y, x * x, y * y, x * y)):
                acc[t, j + 6] += term
                acc[t, j] += v * term
            if v > peaks[t, 0]:
                peaks[t, 0], peaks[t, 1], peaks[t, 2] = v, x, y
    moments = np.empty((n_obj, 5))
    for t in range(n_obj):
        base = 0 if acc[t, 0] > 0.0 else 6  # unweighted where the pixels' sum is not positive
        norm = acc[t, base]
        x, y = acc[t, base + 1] / norm, acc[t, base + 2] / norm
        moments[t, 0], moments[t, 1] = x, y
        moments[t, 2] = acc[t, base + 3] / norm - x * x
        moments[t, 3] = acc[t, base + 4] / norm - y * y
        moments[t, 4] = acc[t, base + 5] / norm - x * y
    count = acc[:n_obj, 6].astype(np.int64)
    return FOUND, count, acc[:n_obj, 0].copy(), moments, peaks[:n_obj].copy()


@njit(cache=True)
def windowed_centroids(data, x, y, sigma):
    """SExtractor's windowed centroids (``XWIN_IMAGE``, ``YWIN_IMAGE``; ``sep.winpos`` with
    ``subpix=1`` gives the same numbers but for their last bits: the window's Gaussian is
    taken as the product of its factors along the row and the column, a tenth of the
    exponentials) of the sources starting at (``x``, ``y``) in
    background-subtracted ``data``, each with a Gaussian window of ``sigma`` px: the pixels
    whose centres lie within ``WINDOW_SIGMAS`` sigmas of the current position, weighted by
    the window, move it by ``_WINDOW_GAIN`` times their weighted mean offset (exact for a
    Gaussian star), up to ``_WINDOW_STEPS`` times, until that mean offset is under
    ``_WINDOW_OFFSET_MIN_PX`` or the weighted sum is not positive (the position reached is
    kept)."""
    height, width = data.shape
    x_out, y_out = x.copy(), y.copy()
    across = np.empty(2 * math.ceil(WINDOW_SIGMAS * sigma.max()) + 2 if len(x) else 0)
    min_offset2 = _WINDOW_OFFSET_MIN_PX * _WINDOW_OFFSET_MIN_PX
    for s in range(len(x)):
        xc, yc = x[s], y[s]
        radius = WINDOW_SIGMAS * sigma[s]
        radius2 = radius * radius
        inv_two_sigma2 = 1.0 / (2.0 * sigma[s] * sigma[s])
        for _ in range(_WINDOW_STEPS):
            total, sum_x, sum_y = 0.0, 0.0, 0.0
            top, bottom = max(0, math.ceil(yc - radius)), min(height, math.floor(yc + radius) + 1)
            left, right = max(0, math.ceil(xc - radius)), min(width, math.floor(xc + radius) + 1)
            for c in range(left, right):
                across[c - left] = math.exp(-((c - xc) ** 2) * inv_two_sigma2)
            for r in range(top, bottom):
                dy = r - yc
                down = math.exp(-dy * dy * inv_two_sigma2)
                for c in range(left, right):
                    dx = c - xc
                    if dx * dx + dy * dy < radius2:
                        w = float(data[r, c]) * (down * across[c - left])
                        total += w
                        sum_x += w * dx
                        sum_y += w * dy
            if not total > 0.0:
                break
            mean_x, mean_y = sum_x / total, sum_y / total
            xc += mean_x * _WINDOW_GAIN
            yc += mean_y * _WINDOW_GAIN
            if mean_x * mean_x + mean_y * mean_y < min_offset2:
                break
        x_out[s], y_out[s] = xc, yc
    return x_out, y_out


@njit(cache=True)
def half_light_radii(data, x, y, rmax, subpix):
    """Per source at (``x``, ``y``) of background-subtracted ``data``: the radius (px)
    within which half the light inside ``rmax`` lies, as ``sep.flux_radius(data, x, y, rmax,
    0.5, subpix=subpix)`` finds it (the same numbers): the pixels whose centres lie within
    ``rmax`` + 1.5 px (those of them whose samples can fall within ``rmax``), each split
    into ``subpix`` x ``subpix`` samples (all but those whose centre's distance lies farther
    than ``_BIN_MARGIN_PX`` from every edge of the ``_RADIUS_BINS`` annuli of equal width
    out to ``rmax``), summed per annulus; the sums
    accumulated outwards and the radius where they reach half of the last interpolated
    linearly within its annulus."""
    height, width = data.shape
    radii = np.empty(len(x))
    sums = np.empty(_RADIUS_BINS)
    scale = 1.0 / subpix
    scale2 = scale * scale
    # sep looks at the pixels within rmax + 1.5 px; those whose samples all lie beyond rmax
    # (their centre farther than rmax + the samples' reach, with a margin) add nothing
    reach = 0.5 * math.sqrt(2.0) * (1.0 - scale) + _REACH_MARGIN_PX
    squares = np.empty(2 * subpix * subpix)
    bins = np.empty(subpix * subpix, dtype=np.int64)
    for s in range(len(x)):
        xs, ys = x[s], y[s]
        r_out = rmax[s] + reach
        r_out2 = r_out * r_out
        step = rmax[s] / _RADIUS_BINS
        per_px = 1.0 / step
        every = step <= _BIN_MARGIN_PX  # then every pixel is split (sep's test always holds)
        sums[:] = 0.0
        top, bottom = max(0, math.ceil(ys - r_out)), min(height, math.floor(ys + r_out) + 1)
        left, right = max(0, math.ceil(xs - r_out)), min(width, math.floor(xs + r_out) + 1)
        for r in range(top, bottom):
            for c in range(left, right):
                dx, dy = c - xs, r - ys
                d2 = dx * dx + dy * dy
                if not d2 < r_out2:
                    continue
                pix = float(data[r, c])
                split = every
                if not split:
                    into = np.fmod(math.sqrt(d2), step)
                    split = into < _BIN_MARGIN_PX or into > step - _BIN_MARGIN_PX
                if split:
                    _split_pixel(sums, dx, dy, scale2 * pix, subpix, per_px, squares, bins)
                else:
                    j = int(math.sqrt(d2) * per_px)
                    if j < _RADIUS_BINS:
                        sums[j] += pix
        for j in range(1, _RADIUS_BINS):
            sums[j] += sums[j - 1]
        radii[s] = _radius_at(sums, rmax[s], 0.5 * sums[_RADIUS_BINS - 1])
    return radii


@njit(cache=True, inline="always")
def _split_pixel(sums, dx, dy, value, subpix, per_px, squares, bins):
    """A pixel at offset (``dx``, ``dy``) from the source split into ``subpix`` x ``subpix``
    samples of ``value`` each, added to the annuli ``sums`` (of 1 / ``per_px`` px) their
    centres fall in, in sep's order (row by row; the offsets stepped by additions as sep
    steps them): the samples' squared offsets laid out flat, their annuli in one loop
    without branches that the compiler vectorizes, then the additions (``squares``: 2
    ``subpix``² scratch values, ``bins``: ``subpix``²)."""
    scale = 1.0 / subpix
    offset = 0.5 * (scale - 1.0)
    n = subpix * subpix
    sx, sy = dx + offset, dy + offset
    for k in range(subpix):
        x2, y2 = sx * sx, sy * sy
        for i in range(subpix):
            squares[i * subpix + k] = x2  # sample (row i, column k)
            squares[n + k * subpix + i] = y2  # sample (row k, column i)
        sx += scale
        sy += scale
    for k in range(n):
        bins[k] = int(math.sqrt(squares[k] + squares[n + k]) * per_px)
    for k in range(n):
        if bins[k] < _RADIUS_BINS:
            sums[bins[k]] += value


@njit(cache=True)
def _radius_at(cumulative, rmax, target):
    """The radius at which the ``cumulative`` sums of ``half_light_radii``'s annuli out to
    ``rmax`` reach ``target``, linear within an annulus (0 when the first is not positive
    and the target is not either; ``rmax`` when none reaches it)."""
    n = len(cumulative)
    step = rmax / n
    i = 0
    while i < n and cumulative[i] < target:
        i += 1
    if i == 0:
        if target <= 0.0 or cumulative[0] == 0.0:
            return 0.0
        return step * target / cumulative[0]
    if i == n:
        return rmax
    return step * (i + (target - cumulative[i - 1]) / (cumulative[i] - cumulative[i - 1]))


@njit(cache=True)
def _plane(values, dx, dy, keep):
    """(c0, cx, cy): the plane c0 + cx dx + cy dy through the ``keep`` values, fitted as if
    their offsets were symmetric about the source (``starnav.detect.photometry._plane``)."""
    count, sx, sy, total = 0.0, 0.0, 0.0, 0.0
    for i in range(len(values)):
        if keep[i]:
            count += 1.0
            sx += dx[i]
            sy += dy[i]
            total += values[i]
    count = max(count, 1.0)
    mx, my, c0 = sx / count, sy / count, total / count
    vx, vy, tx, ty = 0.0, 0.0, 0.0, 0.0
    for i in range(len(values)):
        if keep[i]:
            ux, uy = dx[i] - mx, dy[i] - my
            vx += ux * ux
            vy += uy * uy
            tx += values[i] * ux
            ty += values[i] * uy
    cx, cy = tx / max(vx, 1e-9), ty / max(vy, 1e-9)
    return c0 - cx * mx - cy * my, cx, cy


@njit(cache=True)
def _plane_and_mad(ring, dx, dy, keep, rest, scratch, m):
    """The plane (c0, cx, cy) fitted to the ``keep`` values of ``ring[:m]`` (offsets ``dx``,
    ``dy``), the residuals of all m from it (to ``rest``), their median and their median
    absolute deviation about it (``scratch`` reordered)."""
    c0, cx, cy = _plane(ring[:m], dx[:m], dy[:m], keep[:m])
    for i in range(m):
        rest[i] = ring[i] - c0 - cx * dx[i] - cy * dy[i]
    scratch[:m] = rest[:m]
    centre = _median(scratch, m)
    for i in range(m):
        scratch[i] = abs(rest[i] - centre)
    return c0, cx, cy, centre, _median(scratch, m)


@njit(cache=True)
def annulus_photometry(data, x, y, r_ap, r_in, r_out):
    """Per source at (``x``, ``y``) of background-subtracted ``data``, as
    ``starnav.detect.photometry.local_photometry`` measures it: (flux in the aperture r <
    ``r_ap`` above the local background, the annulus's rms): the local background a plane
    fitted to the annulus ``r_in`` <= r < ``r_out`` (again without its pixels beyond 3
    sigmas of the first), plus the median of what is left; the rms the median absolute
    deviation of that, x 1.4826 (NaN with no annulus). Pixels by their centres; off the
    image: left out."""
    height, width = data.shape
    n = len(x)
    half = math.ceil(r_out)
    flux = np.zeros(n)
    noise = np.full(n, np.nan)
    size = (2 * half + 1) ** 2
    ring, dx, dy = np.empty(size), np.empty(size), np.empty(size)
    rest, scratch = np.empty(size), np.empty(size)
    keep = np.empty(size, dtype=np.bool_)
    for s in range(n):
        xc, yc = round(x[s]), round(y[s])
        m = 0
        for r in range(max(0, yc - half), min(height, yc + half + 1)):
            for c in range(max(0, xc - half), min(width, xc + half + 1)):
                d2 = (c - x[s]) ** 2 + (r - y[s]) ** 2
                if r_in * r_in <= d2 < r_out * r_out:
                    ring[m], dx[m], dy[m] = data[r, c], c - x[s], r - y[s]
                    m += 1
        c0, cx, cy, offset = 0.0, 0.0, 0.0, 0.0
        if m > 0:
            keep[:m] = True
            c0, cx, cy, centre, mad = _plane_and_mad(ring, dx, dy, keep, rest, scratch, m)
            spread = _MAD_TO_SIGMA * mad
            for i in range(m):
                keep[i] = abs(rest[i] - centre) <= 3.0 * spread
            c0, cx, cy, offset, mad = _plane_and_mad(ring, dx, dy, keep, rest, scratch, m)
            noise[s] = _MAD_TO_SIGMA * mad
        total = 0.0  # over the aperture's own box (the pixels of the annulus's, in order)
        top, bottom = max(0, math.ceil(y[s] - r_ap)), min(height, math.floor(y[s] + r_ap) + 1)
        left, right = max(0, math.ceil(x[s] - r_ap)), min(width, math.floor(x[s] + r_ap) + 1)
        for r in range(top, bottom):
            for c in range(left, right):
                ox, oy = c - x[s], r - y[s]
                if ox * ox + oy * oy < r_ap * r_ap:
                    total += data[r, c] - c0 - cx * ox - cy * oy - offset
        flux[s] = total
    return flux, noise


@njit(cache=True)
def plateau(data, high):
    """(how many pixels of ``data`` equal ``high``, whether two of them are neighbours in a
    row or a column): ``starnav.detect.stars``'s saturation test, in one pass without the
    image-sized arrays of numpy's comparison and search."""
    height, width = data.shape
    count = 0
    adjacent = False
    for r in range(height):
        row = data[r]
        here = 0
        for c in range(width):  # no branches: vectorized; most rows hold none
            here += row[c] == high
        if here == 0:
            continue
        count += here
        for c in range(width):
            if row[c] == high:
                adjacent |= c + 1 < width and row[c + 1] == high
                adjacent |= r + 1 < height and data[r + 1, c] == high
    return count, adjacent
