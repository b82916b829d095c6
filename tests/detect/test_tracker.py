"""starnav.detect.tracker: the fast path of a clean star-tracker frame, chosen by
``detect_stars`` itself, against the real-sky detection and the rendered stars' true
positions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sep
from scipy.spatial import cKDTree

from starnav.catalog import load_catalog
from starnav.detect import stars
from starnav.detect.stars import detect_stars
from starnav.detect.tracker import tracker_sources
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate.render import PRESETS, render_frame


@pytest.fixture(scope="module")
def frame():
    """A seed-1024 render (1024 px, 20°, Hp <= 7): a clean star-tracker frame."""
    catalog = load_catalog(None, mag_limit=7.0)
    camera, settings = PRESETS["seed-1024"]
    R = attitude_from_radec_roll(83.0, -5.0, 30.0)  # Orion: bright stars and crowding
    return render_frame(catalog, camera, R, dataclasses.replace(settings, seed=5))


def _fast(image: np.ndarray) -> bool:
    """Whether ``detect_stars`` takes the fast path on ``image``."""
    data = np.asarray(image, dtype=np.float32)
    return tracker_sources(data.copy(), float(data.min()), 5.0, 3, None, True) is not None


def _real_sky_detection(monkeypatch, image: np.ndarray, **options):
    """``detect_stars`` with the fast path declined."""
    with monkeypatch.context() as m:
        m.setattr(stars, "tracker_sources", lambda *args, **kwargs: None)
        return detect_stars(image, **options)


def _with_tree_line(image: np.ndarray, seed: int) -> np.ndarray:
    """The frame with a lit, textured tree line along its bottom (a bright ragged band whose
    pixels vary far more than the sky's noise) and a bright glow rising to it."""
    rng = np.random.default_rng(seed)
    height, width = image.shape
    rows = np.arange(height)[:, None].astype(float)
    edge = 0.8 * height + 20.0 * np.sin(np.arange(width) / 37.0) + rng.normal(0, 4, width)
    tree = (rows > edge[None, :]) * rng.uniform(300.0, 3000.0, image.shape)
    glow = 400.0 * np.exp(-(height - rows) / 150.0)
    return np.clip(image + tree + glow, 0, 65535).astype(np.uint16)


def test_the_fast_path_is_taken_on_a_clean_render_and_not_beside_a_tree_line(frame):
    assert _fast(frame.image)
    assert not _fast(_with_tree_line(frame.image, 1))


def test_the_fast_path_is_not_taken_on_a_bright_gradient_patch(frame):
    """A wide patch of glow (a cloud lit by the town) across a third of the frame."""
    height, width = frame.image.shape
    y, x = np.mgrid[:height, :width]
    patch = 3000.0 * np.exp(-((x - 300.0) ** 2 + (y - 600.0) ** 2) / (2 * 90.0**2))
    assert not _fast(np.clip(frame.image + patch, 0, 65535).astype(np.uint16))


def test_both_paths_give_the_same_stars_on_a_clean_render(frame, monkeypatch):
    """The same stars within 0.05 px (the windowed centroid from either path's start) but
    for blends (another drawn star within 6 px: both paths' centroids are off the truth by
    ~0.3 px there), and the same PSF within 5 %."""
    fast = detect_stars(frame.image)
    slow = _real_sky_detection(monkeypatch, frame.image)
    assert abs(fast.psf_sigma_px / slow.psf_sigma_px - 1.0) < 0.05
    dist, nearest = cKDTree(slow.xy).query(fast.xy)
    same = dist < 0.5
    assert same.sum() >= 0.95 * min(len(fast), len(slow))
    neighbour = cKDTree(frame.xy).query(fast.xy, k=2)[0][:, 1]
    assert np.max(dist[same & (neighbour > 6.0)]) < 0.05
    # the brightest stars in the same order
    assert np.array_equal(nearest[:10], np.arange(10))


def test_fast_centroids_are_as_accurate_as_the_real_sky_path(frame, monkeypatch):
    """Against the true positions: no bias (< 0.01 px per axis) and the same scatter as the
    real-sky path (which reaches the Cramér-Rao bound: tests/detect/test_detect.py)."""
    fast = detect_stars(frame.image)
    slow = _real_sky_detection(monkeypatch, frame.image)
    errors = []
    for found in (fast, slow):
        dist, nearest = cKDTree(frame.xy).query(found.xy)
        ok = dist < 1.0
        offsets = found.xy[ok] - frame.xy[nearest[ok]]
        assert np.all(np.abs(offsets.mean(axis=0)) < 0.01)
        errors.append(np.median(dist[ok]))
    assert errors[0] <= 1.02 * errors[1] + 0.002


def test_the_fast_path_keeps_the_options(frame):
    """max_stars, keep_saturated and a hot pixel as the real-sky path treats them."""
    image = frame.image.copy()
    image[100, 200] = 60000  # a hot pixel
    found = detect_stars(image, max_stars=20)
    assert len(found) == 20
    assert found.n_hot >= 1
    assert not np.any(np.hypot(*(found.xy - [200.5, 100.5]).T) < 1.0)
    assert np.all(np.diff(found.snr[~found.saturated]) <= 0)


def test_the_kernels_give_seps_and_numpys_numbers(frame):
    """The windowed centroids are ``sep.winpos``'s (subpix=1) but for their last bits (1e-9
    px), from the isophotal barycentres and from 0.7 px off them, for the window of either
    path and a wide one; the hot-pixel candidates listed while the background is subtracted
    are the pixels ``np.flatnonzero`` finds over the level; the tiles' 3 x 3 medians are
    ``detect.background``'s; the half-light radii are ``sep.flux_radius``'s."""
    from starnav.detect import kernels
    from starnav.detect.background import median_3x3

    data = np.asarray(frame.image, dtype=np.float32)
    found = tracker_sources(data, float(data.min()), 5.0, 3, None, True)
    x0, y0 = found.objects["x"], found.objects["y"]
    for sigma in (np.hypot(found.psf_sigma_px, 1.0), 1.0, 3.0):
        window = np.full(len(x0), sigma)
        for dx in (0.0, 0.7):
            x, y = kernels.windowed_centroids(found.data, x0 + dx, y0 - dx, window)
            xs, ys, _ = sep.winpos(found.data, x0 + dx, y0 - dx, window, subpix=1)
            assert np.max(np.abs(np.concatenate([x - xs, y - ys]))) < 1e-9
    level = np.float32(5.0 * found.rms)
    for sky in (100.0, 0.0):  # few pixels over the level; most (the list grown many times)
        residual = np.empty_like(data)
        above = kernels.background_subtracted(data, np.full((16, 16), sky), 64, level, residual)
        assert np.array_equal(residual, data - np.float32(sky))
        assert np.array_equal(above, np.flatnonzero(residual > level))
    assert len(above) > data.size // 2
    mesh = np.random.default_rng(1).normal(size=(11, 7))
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(mesh, 1, mode="edge"), (3, 3))
    assert np.array_equal(kernels.median_3x3(mesh), np.median(windows.reshape(11, 7, 9), axis=2))
    assert median_3x3(mesh.astype(np.float32)).dtype == np.float32
    # half-light radii: sep.flux_radius's (subpix 5) to the last bit, out to the PSF's
    # sizes, beyond 45 px (where pixels away from the annuli's edges are not split) and at
    # random sizes (the pixels left out beyond rmax add nothing to sep's sums either)
    x, y = np.ascontiguousarray(x0), np.ascontiguousarray(y0)
    size = np.sqrt(found.objects["x2"] + found.objects["y2"])
    random_rmax = np.random.default_rng(2).uniform(0.5, 50.0, len(x))
    for rmax in (np.clip(3.0 * size, 3.0, 50.0), np.full(len(x), 47.3), random_rmax):
        radii, _ = sep.flux_radius(found.data, x, y, rmax, 0.5, subpix=5)
        assert np.array_equal(kernels.half_light_radii(found.data, x, y, rmax, 5), radii)


def test_the_callers_image_is_left_unchanged(frame):
    """A float32 array is detected in place, not copied, on either path: its pixels are left
    as they were, and a read-only one gives the same stars."""
    for image in (frame.image, _with_tree_line(frame.image, 1)):
        pixels = np.asarray(image, dtype=np.float32)
        pixels[100, 200] = 60000.0  # a hot pixel, which detection replaces in its own copy
        before = pixels.copy()
        found = detect_stars(pixels)
        assert found.n_hot >= 1
        assert np.array_equal(pixels, before)
        pixels.setflags(write=False)  # and a read-only one (a memory-mapped file's) is taken
        assert np.array_equal(detect_stars(pixels).xy, found.xy)


def test_the_arrays_kept_from_frame_to_frame_leave_no_trace(frame):
    """Detection in the arrays a thread keeps (the pixels as float32, the residual) gives
    the stars of a fresh detection, whatever was detected before in them: another frame, one
    of another size, the real-sky path's."""
    images = [frame.image, _with_tree_line(frame.image, 2), frame.image[:700, :900]]
    first = [detect_stars(image) for image in images]
    for image, found in zip(images[::-1], first[::-1], strict=True):
        again = detect_stars(image)
        assert np.array_equal(again.xy, found.xy) and np.array_equal(again.flux, found.flux)


def test_the_selection_and_the_saturation_test_give_numpys_answers():
    """The kernels' k-th smallest and median are numpy's on noise, on whole numbers with many
    ties (a quantised sky), on sorted, reversed and constant values; the saturation test
    finds the pixels at the maximum and whether two of them touch in a row or a column as
    the numpy rule it replaced, at the edges too."""
    from starnav.detect import kernels
    from starnav.detect.stars import _infer_saturation

    rng = np.random.default_rng(7)
    for trial in range(3000):
        n = int(rng.integers(1, 200))
        kind = trial % 5
        values = [
            rng.normal(size=n),
            rng.integers(0, 4, size=n).astype(float),
            np.sort(rng.normal(size=n)),
            np.sort(rng.normal(size=n))[::-1].copy(),
            np.full(n, 2.5),
        ][kind]
        for k in {0, n // 2, n - 1, int(rng.integers(0, n))}:
            assert kernels._select(values.copy(), n, k) == np.sort(values)[k]
        assert kernels._median(values.copy(), n) == np.median(values)
    for values in (np.full(9, np.nan), np.array([3.0, np.nan, 1.0, np.nan, 2.0])):
        kernels._select(values.copy(), len(values), len(values) // 2)  # NaN: it ends

    def numpy_rule(data, high):
        at_max = np.flatnonzero(data == np.float32(high))
        if len(at_max) < 2 or len(at_max) > data.size // 2:
            return None
        width = data.shape[1]
        same_row = np.isin(at_max + 1, at_max) & ((at_max % width) != width - 1)
        below = np.isin(at_max + width, at_max)
        return high if bool(same_row.any() or below.any()) else None

    for _ in range(400):
        data = rng.integers(0, 3, size=(int(rng.integers(3, 9)), int(rng.integers(3, 9))))
        data = data.astype(np.float32) + (rng.random(data.shape) < 0.7) * np.float32(0.5)
        high = float(data.max())
        assert _infer_saturation(data, np.dtype(np.float32), high) == numpy_rule(data, high)
