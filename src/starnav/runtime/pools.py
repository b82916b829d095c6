"""Where batches run besides this process: the one way starnav starts worker processes, and
the Dask client.

``process_pool`` is every pool of worker processes (star-list batches, image batches, the
evaluation), its start method named by the caller for its reason: "fork" shares a prepared
solver's catalog, tables and machine code with the workers (spawn where there is no fork),
"spawn" gives fresh interpreters, "forkserver" workers that inherit no threads or event loop.
``worker_process`` is a process of its own with a pipe (each of the service's workers: one can
be killed without breaking a pool), ``limit_memory`` and ``die_with_parent`` what such a
process does first. ``dask_client`` opens a client of a scheduler address, or of a
LocalCluster of ``workers`` processes for "local", with a one-line error when Dask is missing
or the scheduler cannot be reached.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Literal

from starnav.errors import StarnavError

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def one_blas_thread() -> None:
    """Worker processes each run one frame at a time: a multi-threaded BLAS in every one of
    them only fights over the cores (small products became 10-20x slower). Set before the
    workers start, so their numpy reads it."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


def worker_process(target: Callable[..., None], args: tuple = (), *, name: str = "worker"):
    """A process of its own (no pool) running ``target(conn, *args)``, started with "spawn"
    (a fresh interpreter: nothing of the caller's threads or event loop), as a daemon (killed
    when the caller exits normally), one BLAS thread; ``conn`` is its end of a pipe. Returns
    the process and the caller's end."""
    one_blas_thread()
    context = multiprocessing.get_context("spawn")
    here, there = context.Pipe()
    process = context.Process(target=target, args=(there, *args), name=name, daemon=True)
    process.start()
    there.close()
    return process, here


def limit_memory(memory_bytes: int) -> None:
    """Limit this process's memory to ``memory_bytes`` (``resource.RLIMIT_DATA``: its heap and
    private mappings, what numpy's arrays take; ``RLIMIT_AS`` would also count the address
    space numba's LLVM and the allocators reserve without using it): past it an allocation
    raises ``MemoryError``. Not below the system's hard limit; nothing where there is no
    ``resource`` module."""
    try:
        import resource
    except ImportError:
        return
    hard = resource.getrlimit(resource.RLIMIT_DATA)[1]
    if hard != resource.RLIM_INFINITY:
        memory_bytes = min(memory_bytes, hard)
    resource.setrlimit(resource.RLIMIT_DATA, (memory_bytes, hard))


def die_with_parent(parent_pid: int) -> None:
    """Ask the kernel for SIGKILL when the parent process dies (Linux's ``PR_SET_PDEATHSIG``,
    which follows the parent's thread that started this process), and exit now if the parent
    ``parent_pid`` is already gone. Elsewhere the caller watches ``os.getppid()``."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(0)


def worker_count(workers: int | None) -> int:
    """``workers``, or every core when None."""
    return workers or os.cpu_count() or 1


def process_pool(
    workers: int,
    *,
    start: Literal["fork", "spawn", "forkserver"] = "fork",
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes started by ``start`` ("fork" is spawn where the system
    has no fork), each running ``initializer(*initargs)`` first, with one BLAS thread each
    (``one_blas_thread``)."""
    one_blas_thread()
    if start == "fork" and os.name != "posix":
        start = "spawn"
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context(start),
        initializer=initializer,
        initargs=initargs,
    )


@contextmanager
def dask_client(address: str, workers: int) -> Iterator[tuple[object, object]]:
    """``(client, as_completed)`` of the Dask scheduler at ``address`` ("local": a
    LocalCluster of ``workers`` single-threaded processes, closed on exit)."""
    try:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed
    except ImportError:
        raise StarnavError(
            "--dask needs the distributed package: pip install 'starnav[dask]'"
        ) from None
    cluster = None
    try:
        if address == "local":
            one_blas_thread()
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
            client = Client(cluster)
        else:
            client = Client(address, timeout="10s")
    except OSError as exc:
        if cluster is not None:
            cluster.close()
        raise StarnavError(f"cannot reach the Dask scheduler at {address!r}: {exc}") from None
    try:
        yield client, dask_completed
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
