"""Where batches run besides this process: the one way starnav starts worker processes, and
the Dask client.

``process_pool`` is every pool of worker processes (star-list batches, image batches, the
evaluation, the service's workers), its start method named by the caller for its reason:
"fork" shares a prepared solver's catalog, tables and machine code with the workers (spawn
where there is no fork), "spawn" gives fresh interpreters, "forkserver" workers that inherit no
threads or event loop. ``dask_client`` opens a client of a scheduler address, or of a
LocalCluster of ``workers`` processes for "local", with a one-line error when Dask is missing
or the scheduler cannot be reached.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Literal

from starnav.errors import StarnavError


def one_blas_thread() -> None:
    """Worker processes each run one frame at a time: a multi-threaded BLAS in every one of
    them only fights over the cores (small products became 10-20x slower). Set before the
    workers start, so their numpy reads it."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


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
