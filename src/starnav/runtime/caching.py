"""Where starnav keeps what it computes once: the pair and pattern tables, the columns of the
embedded Hipparcos catalog it reads, and the machine code of its numba kernels.

They live under ``$STARNAV_CACHE_DIR`` (default ``~/.cache/starnav``). With
``$STARNAV_CACHE_LIMIT_MB`` set (``starnav serve`` sets it), a table is written only while the
tables there (its files, links left out) stay within that many MB. The machine code goes to
``numba/kernels-<hash>`` there (or under ``$NUMBA_CACHE_DIR`` when that is set), the hash taken
over the sources of every kernel module together: numba invalidates a cached function when its
own file changes, not when a function it calls in another file does (``pipeline.kernels``
calls ``identify.kernels.pairing``), so a release that changed only a callee would otherwise run the
old callee's code. numba checks its own version and Python's itself.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

PACKAGE = Path(__file__).resolve().parents[1]
CACHE_LIMIT_ENV = "STARNAV_CACHE_LIMIT_MB"
# every module with numba kernels (tests/runtime/test_caching.py checks the list against the
# sources)
KERNEL_SOURCES = (
    "attitude/kernels.py",
    "attitude/rotation.py",
    "camera/kernels.py",
    "detect/kernels.py",
    "identify/kernels/evidence.py",
    "identify/kernels/hypothesis.py",
    "identify/kernels/pairing.py",
    "identify/kernels/search.py",
    "identify/kernels/sky.py",
    "identify/kernels/triangles.py",
    "pipeline/kernels.py",
)


def cache_dir() -> Path:
    """Directory of starnav's caches (``$STARNAV_CACHE_DIR`` or ``~/.cache/starnav``)."""
    env = os.environ.get("STARNAV_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "starnav"


def load_cached(path: Path) -> dict[str, np.ndarray] | None:
    """The arrays of a cached table, or None when it is missing or damaged (then rebuilt)."""
    if not path.exists():
        return None
    try:
        with np.load(path) as data:
            return {name: data[name] for name in data.files}
    except (OSError, KeyError, ValueError):
        return None


def save_cached(path: Path, **arrays) -> Path | None:
    """Write a table's arrays to ``path`` (written then renamed, so a concurrent reader never
    sees half a file); None when it cannot be written (a read-only home still works) or
    when the folder's tables would pass ``$STARNAV_CACHE_LIMIT_MB`` with it."""
    limit_mb = _limit_mb()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as fh:
            np.savez(fh, **arrays)
        if limit_mb is not None and stored_bytes(path.parent) > limit_mb * 1e6:
            os.unlink(fh.name)  # counted with the others: over the limit with it
            return None
        os.replace(fh.name, path)
        return path
    except OSError:
        return None


def _limit_mb() -> float | None:
    text = os.environ.get(CACHE_LIMIT_ENV)
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        return 0.0  # unreadable: nothing written rather than no limit


def stored_bytes(folder: Path) -> int:
    """Bytes of the files directly in ``folder`` (links and subfolders left out)."""
    total = 0
    with os.scandir(folder) as entries:
        for entry in entries:
            if entry.is_file(follow_symlinks=False):
                total += entry.stat(follow_symlinks=False).st_size
    return total


@functools.cache
def kernel_sources_hash() -> str:
    """SHA-256 (hex, 16 digits) of the kernel modules' sources, in ``KERNEL_SOURCES`` order."""
    digest = hashlib.sha256()
    for name in KERNEL_SOURCES:
        digest.update(name.encode())
        digest.update((PACKAGE / name).read_bytes())
    return digest.hexdigest()[:16]


def kernel_cache_dir(numba_cache_dir: str = "") -> Path:
    """Where the kernels' machine code is cached: ``kernels-<hash>`` under
    ``numba_cache_dir`` (numba's ``NUMBA_CACHE_DIR``) when given, else under
    ``cache_dir() / "numba"``."""
    base = Path(numba_cache_dir) if numba_cache_dir else cache_dir() / "numba"
    return base / f"kernels-{kernel_sources_hash()}"


def njit(**options) -> Callable:
    """``numba.njit(**options)`` whose cache (``cache=True``) is ``kernel_cache_dir()``: numba
    picks a function's cache folder when it is decorated, so ``numba.config.CACHE_DIR`` is set
    for the decoration only (numba code of other packages keeps its own)."""
    import numba

    def decorate(func: Callable) -> Callable:
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(kernel_cache_dir(saved))
        try:
            return numba.njit(**options)(func)
        finally:
            numba.config.CACHE_DIR = saved

    return decorate
