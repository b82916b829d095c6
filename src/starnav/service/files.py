"""Every file of ``starnav serve`` under its data dir, and what a stopped run left cleaned.

``DATA`` is ``--data-dir``::

    starnav.sqlite, jobs/N/   the jobs (starnav.service.store)
    tmp/      TMPDIR: a job's input while a worker solves it, multiprocessing's sockets
              (emptied at every start; a job's temporary folder at every stop too)
    cache/    STARNAV_CACHE_DIR: the tables; numba/ the kernels' machine code
              (NUMBA_CACHE_DIR), matplotlib/ (MPLCONFIGDIR), astropy/; XDG_CACHE_HOME
    config/   XDG_CONFIG_HOME, astropy's configuration
    home/     HOME: whatever another library keeps under ``~``
    lock      held while a server runs on this data dir (a second one is refused)

``use_data_dir`` sets these in this process's environment once, before the worker processes
(or a local Dask cluster) start: they inherit it. The tables and the machine code already
built in the cache starnav uses outside the service (``$STARNAV_CACHE_DIR`` or
``~/.cache/starnav``, ``$NUMBA_CACHE_DIR``) are linked into ``cache/`` and only read: a
table built anew (or one of the format before, written again aligned: ``load_cached``) is
written in ``cache/`` (replacing the link, never its target), and only while the tables there
take less than the cache limit (``STARNAV_CACHE_LIMIT_MB``,
``starnav.runtime.caching.save_cached``); past it a worker keeps a new table in its memory.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from starnav.errors import StarnavError
from starnav.runtime.caching import CACHE_LIMIT_ENV, cache_dir, kernel_cache_dir
from starnav.service.store import JobStore

JOB_TMP_PREFIX = "starnav-job-"  # a worker's temporary folder for one job (service.worker)
DEFAULT_CACHE_LIMIT_MB = 2000.0


@dataclass(frozen=True)
class Leftovers:
    """What ``clean_leftovers`` removed: ``temporary`` entries of ``DATA/tmp``, and the
    ``jobs`` whose upload was never stored (failed, their folders removed)."""

    temporary: int = 0
    jobs: tuple[int, ...] = ()

    def __str__(self) -> str:
        parts = []
        if self.temporary:
            parts.append(f"{self.temporary} temporary file(s) or folder(s)")
        if self.jobs:
            parts.append(f"job(s) {', '.join(map(str, self.jobs))} without their upload")
        return f"cleaned what the last run left: {' and '.join(parts)}" if parts else ""


def tmp_dir(data_dir: Path) -> Path:
    """``DATA/tmp``, the temporary folder of the server and its workers."""
    return Path(data_dir) / "tmp"


def lock_data_dir(data_dir: Path) -> int:
    """Hold ``DATA/lock`` for this process's life (a file descriptor the system releases when
    the process ends, however it ends; -1 where there is no ``flock``); ``StarnavError`` when
    another server holds it, since the start-up cleaning would remove that server's files."""
    try:
        import fcntl
    except ImportError:  # no flock on this system: not locked
        return -1
    fd = os.open(Path(data_dir) / "lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise StarnavError(
            f"--data-dir {str(data_dir)!r} is in use by another starnav serve (process "
            f"{holder}): give each server its own data dir"
        ) from None
    os.ftruncate(fd, 0)
    os.write(fd, str(os.getpid()).encode())
    return fd


def clean_leftovers(data_dir: Path) -> Leftovers:
    """Before a start (the data dir locked): empty ``DATA/tmp`` and fail the jobs whose
    upload was never stored (``JobStore.fail_unstored``), removing their folders."""
    tmp = tmp_dir(data_dir)
    temporary = remove_entries(tmp) if tmp.is_dir() else 0
    store = JobStore(data_dir)
    try:
        jobs = tuple(store.fail_unstored())
        for job_id in jobs:
            shutil.rmtree(store.job_dir(job_id), ignore_errors=True)
    finally:
        store.close()
    return Leftovers(temporary, jobs)


def remove_entries(folder: Path, prefix: str = "") -> int:
    """Remove every file and folder in ``folder`` whose name starts with ``prefix``; how many."""
    count = 0
    for entry in list(folder.iterdir()):
        if not entry.name.startswith(prefix):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        count += 1
    return count


def clean_job_tmp(data_dir: Path) -> int:
    """After a stop (workers stopped): remove the jobs' temporary folders from ``DATA/tmp``
    (multiprocessing removes its own as the server exits)."""
    tmp = tmp_dir(data_dir)
    return remove_entries(tmp, JOB_TMP_PREFIX) if tmp.is_dir() else 0


def service_environment(data_dir: Path, cache_limit_mb: float) -> dict[str, str]:
    """The environment variables that keep the server's and its workers' files in
    ``data_dir`` (absolute paths; the folders made)."""
    data = Path(data_dir).resolve()
    cache, config = data / "cache", data / "config"
    env = {
        "TMPDIR": data / "tmp",
        "STARNAV_CACHE_DIR": cache,
        "NUMBA_CACHE_DIR": cache / "numba",
        "MPLCONFIGDIR": cache / "matplotlib",
        "ASTROPY_CACHE_DIR": cache / "astropy",
        "XDG_CACHE_HOME": cache,
        "ASTROPY_CONFIG_DIR": config / "astropy",
        "XDG_CONFIG_HOME": config,
        "HOME": data / "home",
    }
    for folder in env.values():  # astropy ignores a folder that does not exist
        folder.mkdir(parents=True, exist_ok=True)
    out = {name: str(folder) for name, folder in env.items()}
    out[CACHE_LIMIT_ENV] = f"{cache_limit_mb:g}"
    return out


def use_data_dir(data_dir: Path, cache_limit_mb: float = DEFAULT_CACHE_LIMIT_MB) -> None:
    """Keep every file of this process and of the processes it starts in ``data_dir``: link
    the shared cache's tables and machine code into ``DATA/cache`` (read, never written),
    then set ``service_environment`` (call it before numba is imported: numba reads
    ``NUMBA_CACHE_DIR`` once)."""
    shared_tables = cache_dir()
    shared_code = kernel_cache_dir(os.environ.get("NUMBA_CACHE_DIR", ""))
    home_dask = Path.home() / ".config" / "dask"
    env = service_environment(data_dir, cache_limit_mb)
    try:
        link_tables(shared_tables, Path(env["STARNAV_CACHE_DIR"]))
        link_tree(shared_code, kernel_cache_dir(env["NUMBA_CACHE_DIR"]))
    except OSError:  # no links here (or an unreadable cache): the workers build what they need
        pass
    if "DASK_CONFIG" not in os.environ and home_dask.is_dir():
        env["DASK_CONFIG"] = str(home_dask)  # the operator's Dask settings, from the old home
    os.environ.update(env)
    tempfile.tempdir = None  # tempfile reads TMPDIR again


def link_tables(shared: Path, cache: Path) -> int:
    """Link each table (``*.npz``) of the cache ``shared`` into ``cache`` (links of an earlier
    start renewed; files built in ``cache`` kept); how many."""
    if shared.resolve() == cache.resolve():
        return 0
    for entry in cache.iterdir():
        if entry.is_symlink():
            entry.unlink()
    count = 0
    if shared.is_dir():
        for table in shared.glob("*.npz"):
            if not table.name.startswith("tmp") and not (cache / table.name).exists():
                (cache / table.name).symlink_to(table.resolve())
                count += 1
    return count


def link_tree(shared: Path, target: Path) -> int:
    """Link every file under ``shared`` into the same place under ``target`` (folders made,
    files already there kept); how many."""
    if not shared.is_dir() or shared.resolve() == target.resolve():
        return 0
    count = 0
    for folder, _, names in os.walk(shared):
        into = target / Path(folder).relative_to(shared)
        into.mkdir(parents=True, exist_ok=True)
        for name in names:
            link = into / name
            if link.is_symlink() and not link.exists():
                link.unlink()  # its target is gone
            if not link.exists():
                link.symlink_to(Path(folder, name).resolve())
                count += 1
    return count
