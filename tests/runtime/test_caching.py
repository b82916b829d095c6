"""The kernels' machine-code cache: keyed by all kernel sources together; the tables' cache
written only within its limit."""

from __future__ import annotations

import mmap
import re

import numpy as np

from starnav.runtime import caching


def test_the_kernel_source_list_is_every_module_with_numba_kernels():
    """A module that compiles kernels but is not in KERNEL_SOURCES would leave its callers'
    cached code stale when it changes."""
    found = {
        str(path.relative_to(caching.PACKAGE))
        for path in caching.PACKAGE.rglob("*.py")
        if re.search(r"^@njit\(", path.read_text(), flags=re.MULTILINE)
    }
    assert found == set(caching.KERNEL_SOURCES)


def test_kernel_cache_folders_follow_the_sources(monkeypatch, tmp_path):
    """The cache folder's name changes with any kernel module's source (a callee's too), sits
    under NUMBA_CACHE_DIR when that is given, else under STARNAV_CACHE_DIR."""
    monkeypatch.setenv("STARNAV_CACHE_DIR", str(tmp_path))
    here = caching.kernel_cache_dir()
    assert here.parent == tmp_path / "numba" and here.name.startswith("kernels-")
    assert caching.kernel_cache_dir("/somewhere").parent.as_posix() == "/somewhere"
    copy = tmp_path / "pkg"
    for name in caching.KERNEL_SOURCES:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        (copy / name).write_bytes((caching.PACKAGE / name).read_bytes())
    monkeypatch.setattr(caching, "PACKAGE", copy)
    caching.kernel_sources_hash.cache_clear()
    try:
        assert caching.kernel_cache_dir() == here  # the same sources: the same folder
        with (copy / "identify/kernels/sky.py").open("a") as fh:
            fh.write("\n# a callee changed\n")
        caching.kernel_sources_hash.cache_clear()
        assert caching.kernel_cache_dir() != here
    finally:
        caching.kernel_sources_hash.cache_clear()


def test_kernels_are_cached_in_their_folder_and_numba_config_is_restored():
    """A kernel decorated through ``caching.njit`` has its cache in a ``kernels-<hash>``
    folder (under the cache folder set when it was imported: the tests' private one may come
    later); numba's CACHE_DIR is what it was before (other packages' numba code keeps its own
    cache)."""
    import numba

    from starnav.identify.kernels import sky

    before = numba.config.CACHE_DIR
    cache = getattr(sky.chord, "_cache", None)
    if cache is None:  # NUMBA_DISABLE_JIT: plain Python, nothing cached
        return
    assert f"kernels-{caching.kernel_sources_hash()}" in cache.cache_path.split("/")
    if before:
        assert cache.cache_path.startswith(str(caching.kernel_cache_dir(before)))
    assert numba.config.CACHE_DIR == before


def test_a_table_is_written_only_within_the_cache_limit(monkeypatch, tmp_path):
    save_cached, stored_bytes = caching.save_cached, caching.stored_bytes
    outside = tmp_path / "big.npy"
    np.save(outside, np.zeros(1_000_000))  # 8 MB, linked in: links are not counted
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "shared.npz").symlink_to(outside)
    monkeypatch.setenv(caching.CACHE_LIMIT_ENV, "1")
    first = save_cached(tmp_path / "cache" / "a.npz", x=np.zeros(60_000))  # 0.48 MB
    second = save_cached(tmp_path / "cache" / "b.npz", x=np.zeros(80_000))  # 0.64 MB
    assert first == tmp_path / "cache" / "a.npz"
    assert np.array_equal(caching.load_cached(first)["x"], np.zeros(60_000))
    assert second is None  # 1.12 MB with it: not written, no temporary file left
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == ["a.npz", "shared.npz"]
    assert stored_bytes(tmp_path / "cache") == first.stat().st_size
    monkeypatch.setenv(caching.CACHE_LIMIT_ENV, "0")
    assert save_cached(tmp_path / "cache" / "c.npz", x=np.zeros(1)) is None
    monkeypatch.delenv(caching.CACHE_LIMIT_ENV)
    assert save_cached(tmp_path / "cache" / "b.npz", x=np.zeros(80_000)) is not None


def _memory_mapped(array: np.ndarray) -> bool:
    base = array
    while isinstance(base, np.ndarray):
        base = base.base
    return isinstance(base, mmap.mmap)


def test_a_table_is_read_back_memory_mapped_as_written(tmp_path):
    """Each array comes back equal, aligned, writable (copy-on-write: the file keeps what was
    written) and memory-mapped; np.load reads the file as well."""
    rng = np.random.default_rng(1)
    arrays = {
        "keys": np.sort(rng.integers(0, 2**40, 5001)),
        "codes": rng.integers(0, 2**32, 5001).astype(np.uint32),
        "fields": rng.integers(0, 60000, (333, 7)).astype(np.uint16),
        "fortran": np.asfortranarray(rng.normal(size=(9, 5))),
        "none": np.empty(0, dtype=np.int32),
        "edge_step_rad": 1.5e-6,
        "bins": 50,
    }
    path = caching.save_cached(tmp_path / "t.npz", **arrays)
    read = caching.load_cached(path)
    assert read.keys() == arrays.keys()
    for name, value in arrays.items():
        array = read[name]
        assert np.array_equal(array, value) and array.dtype == np.asarray(value).dtype
        assert _memory_mapped(array) and array.flags.aligned and array.flags.writeable
    assert read["fortran"].flags.f_contiguous
    read["codes"][:] = 0
    assert np.array_equal(caching.load_cached(path)["codes"], arrays["codes"])
    with np.load(path) as data:
        assert all(np.array_equal(data[name], value) for name, value in arrays.items())


def test_old_savez_tables_are_read_and_damaged_ones_refused(tmp_path):
    """A file np.savez wrote (the format before) is read, and written again aligned; a cut,
    overwritten, emptied or compressed one is None (its table is then rebuilt)."""
    x = np.arange(100_000, dtype=np.int64)
    np.savez(tmp_path / "old.npz", x=x, bins=50)
    old = caching.load_cached(tmp_path / "old.npz")
    assert np.array_equal(old["x"], x) and old["bins"] == 50 and old["x"].flags.aligned
    again = caching.load_cached(tmp_path / "old.npz")  # written again aligned: mapped now
    assert np.array_equal(again["x"], x) and _memory_mapped(again["x"])
    whole = caching.save_cached(tmp_path / "t.npz", x=x).read_bytes()
    bad = tmp_path / "bad.npz"
    for damaged in (whole[: len(whole) // 2], whole[:-30], b"not a numpy file", b""):
        bad.write_bytes(damaged)
        assert caching.load_cached(bad) is None
    np.savez_compressed(bad, x=x)
    assert caching.load_cached(bad) is None
    assert caching.load_cached(tmp_path / "missing.npz") is None
