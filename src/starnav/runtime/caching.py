"""Where starnav keeps what it computes once: the pair and pattern tables, the columns of the
embedded Hipparcos catalog it reads, and the machine code of its numba kernels.

They live under ``$STARNAV_CACHE_DIR`` (default ``~/.cache/starnav``). With
``$STARNAV_CACHE_LIMIT_MB`` set (``starnav serve`` sets it), a table is written only while the
tables there (its files, links left out) stay within that many MB. A table is one ``.npz``
file, uncompressed, each array's data at a 64-byte boundary, so that it is read
memory-mapped (copy-on-write): a process reads only the pages of the table it touches. The
machine code goes to ``numba/kernels-<hash>`` there (or under ``$NUMBA_CACHE_DIR`` when that
is set), the hash taken over the sources of every kernel module together: numba invalidates a
cached function when its own file changes, not when a function it calls in another file does
(``pipeline.kernels`` calls ``identify.kernels.pairing``), so a release that changed only a
callee would otherwise run the old callee's code. numba checks its own version and Python's itself.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import mmap
import os
import struct
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from starnav.errors import StarnavError

PACKAGE = Path(__file__).resolve().parents[1]
CACHE_LIMIT_ENV = "STARNAV_CACHE_LIMIT_MB"
KERNELS_ENV = "STARNAV_KERNELS"
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
    "identify/kernels/patterns.py",
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
    """The arrays of a cached table, or None when it is missing or damaged (then rebuilt).

    The arrays are memory-mapped copy-on-write (writable, a write stays in the process):
    only the pages used are read. An array whose data is not aligned for its type (in a
    file ``np.savez`` wrote, the format before) is copied into memory instead, and the file
    written again aligned, once. The data bytes are not checksummed on reading (that would
    read every page); the zip and ``.npy`` headers and the sizes they give are checked, so a
    cut or overwritten file is rebuilt.
    """
    if not path.exists():
        return None
    try:
        with path.open("rb") as fh:
            pages = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_COPY)
            with zipfile.ZipFile(fh) as archive:
                arrays = {
                    info.filename.removesuffix(".npy"): _mapped_array(fh, pages, info)
                    for info in archive.infolist()
                }
    except (OSError, KeyError, ValueError, EOFError, struct.error, zipfile.BadZipFile):
        return None
    if any(array.flags.owndata for array in arrays.values()):
        save_cached(path, **arrays)  # the old format: mapped from the next process on
    return arrays


def _mapped_array(fh, pages: mmap.mmap, info: zipfile.ZipInfo) -> np.ndarray:
    """The array of the stored (uncompressed) ``.npy`` member ``info``, a view of ``pages``."""
    if info.compress_type != zipfile.ZIP_STORED or not info.filename.endswith(".npy"):
        raise ValueError(f"{info.filename}: not a stored .npy member")
    signature, name_len, extra_len = struct.unpack_from("<4s22xHH", pages, info.header_offset)
    if signature != b"PK\x03\x04":
        raise ValueError(f"{info.filename}: no local header")
    start = info.header_offset + 30 + name_len + extra_len
    fh.seek(start)
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(fh)
    elif version == (2, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(fh)
    else:
        raise ValueError(f"{info.filename}: .npy version {version}")
    offset = fh.tell()
    nbytes = dtype.itemsize * int(np.prod(shape, dtype=np.int64))
    if dtype.hasobject or offset + nbytes != start + info.file_size:
        raise ValueError(f"{info.filename}: sizes disagree")
    order = "F" if fortran_order else "C"
    array = np.ndarray(shape, dtype, buffer=pages, offset=offset, order=order)
    return array if array.flags.aligned else array.copy(order=order)


def save_cached(path: Path, **arrays) -> Path | None:
    """Write a table's arrays to ``path`` (written then renamed, so a concurrent reader never
    sees half a file); None when it cannot be written (a read-only home still works) or
    when the folder's tables would pass ``$STARNAV_CACHE_LIMIT_MB`` with it."""
    limit_mb = _limit_mb()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as fh:
            _write_aligned(fh, arrays)
        if limit_mb is not None and stored_bytes(path.parent) > limit_mb * 1e6:
            os.unlink(fh.name)  # counted with the others: over the limit with it
            return None
        os.replace(fh.name, path)
        return path
    except OSError:
        return None


_ALIGN = 64  # bytes; numpy pads a .npy header to a multiple of 64 as well
_PADDING_ID = 0xD935  # the zip extra-field id of padding (Android's zipalign uses it too)


def _write_aligned(fh, arrays: dict) -> None:
    """``np.savez``'s file (uncompressed; ``np.load`` reads it), with each member's local
    header padded so that its ``.npy`` starts, and so its data does, at a multiple of
    ``_ALIGN`` bytes in the file."""
    with zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED) as archive:
        for name, value in arrays.items():
            array = np.asanyarray(value)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            zip64 = array.nbytes > 1 << 30  # zipfile adds a 20-byte extra field for it
            header = 30 + len(info.filename.encode()) + 4 + (20 if zip64 else 0)
            pad = -(fh.tell() + header) % _ALIGN
            info.extra = struct.pack("<HH", _PADDING_ID, pad) + bytes(pad)
            with archive.open(info, "w", force_zip64=zip64) as member:
                np.lib.format.write_array(member, array, allow_pickle=False)


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


@functools.cache
def python_kernels() -> bool:
    """Whether this process runs the kernels as plain Python (``$STARNAV_KERNELS`` =
    ``python``; default ``numba``): numba is then never imported. Loading numba and the
    kernels' cached machine code costs a process ~0.6 s and ~150 MB, more than a star list
    of a known field takes to solve in plain Python (~50 ms; the kernels run 10-100x
    slower), so ``starnav identify`` on one list starts that way (``starnav.cli.identify``).
    The answers are the same either way. Read once, when the first kernel module is
    imported: a process does not mix the two."""
    mode = os.environ.get(KERNELS_ENV, "numba")
    if mode not in ("numba", "python"):
        raise StarnavError(f"${KERNELS_ENV} must be numba or python, got {mode!r}")
    return mode == "python"


class _PlainObjmode:
    """``numba.objmode`` of a kernel run as plain Python: its block is Python anyway."""

    def __call__(self, **_types: str) -> contextlib.nullcontext:
        return contextlib.nullcontext()


def kernel_objmode():
    """What a kernel module binds ``objmode`` to: numba's (a block of a compiled kernel run
    by the interpreter; numba recognises its own object among the kernel's globals), or a
    stand-in when the kernels are plain Python (``python_kernels``)."""
    if python_kernels():
        return _PlainObjmode()
    from numba import objmode

    return objmode


def njit(**options) -> Callable:
    """``numba.njit(**options)`` whose cache (``cache=True``) is ``kernel_cache_dir()``: numba
    picks a function's cache folder when it is decorated, so ``numba.config.CACHE_DIR`` is set
    for the decoration only (numba code of other packages keeps its own). With
    ``python_kernels()`` the function itself, undecorated."""
    if python_kernels():
        return lambda func: func
    import numba

    def decorate(func: Callable) -> Callable:
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(kernel_cache_dir(saved))
        try:
            return numba.njit(**options)(func)
        finally:
            numba.config.CACHE_DIR = saved

    return decorate
