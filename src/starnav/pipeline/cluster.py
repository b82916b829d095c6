"""Where batches run besides this process: worker settings and the Dask client.

Shared by the evaluation (``starnav evaluate --dask``) and the image batches (``starnav solve
--dask``): ``dask_client`` opens a client of a scheduler address, or of a LocalCluster of
``workers`` processes for "local", with a one-line error when Dask is missing or the scheduler
cannot be reached.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

from starnav.errors import StarnavError


def one_blas_thread() -> None:
    """Worker processes each run one frame at a time: a multi-threaded BLAS in every one of
    them only fights over the cores (small products became 10-20x slower). Set before the
    workers start, so their numpy reads it."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


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
