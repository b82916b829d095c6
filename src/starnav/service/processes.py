"""The service's worker processes: one process a slot, each solving one job at a time
(``starnav.service.worker.run_job``), stopped and replaced when a job overruns.

A worker is started with "spawn" (a fresh interpreter: no event loop or threads of the server's)
from the server's main thread, as the server's own child, so that it can die with it: on Linux
it asks the kernel for SIGKILL when its parent dies (``runtime.pools.die_with_parent``), and
a thread of it looks every ``WATCH_S`` seconds whether its parent is still the server. Its
memory is limited (``runtime.pools.limit_memory``): a job past the limit gets ``MemoryError``,
which fails it with the reason.

The server gives each job a deadline: its time budget (with starnav's defaults, until the
image is read and detected, the searched field's ``SEARCH_BUDGET_S``) and a grace of
``GRACE_S`` (a fresh worker loading the catalog and tables, the solve's last unit of work).
Reading and detection count: when they are done the worker tells the budget left to the solve
(the default of the image's kind, a fisheye's scan included, less what they took), and the
deadline becomes that and the grace from then; the seconds the worker reports compiling
machine code (once per installation) are added, as the budget leaves them out; once the worker
says the solve is over, ``WRITE_S`` are given to write the files. A worker past its deadline
is killed and a new one started: the other slots' jobs go on.
"""

from __future__ import annotations

import asyncio
import os
import threading
import time
from dataclasses import dataclass

from starnav.detect.read import MAX_PIXELS
from starnav.runtime.budget import SCAN_BUDGET_S, SEARCH_BUDGET_S, compiled_s
from starnav.runtime.limits import DEFAULT_WORKER_MEMORY_MB
from starnav.runtime.pools import die_with_parent, limit_memory, worker_process
from starnav.service.worker import failed_answer, run_job

GRACE_S = 15.0  # past the budget before a worker is stopped (a fresh worker loads its tables)
WRITE_S = 120.0  # for writing a job's files once its solve is over (a 200 MP image's)
WATCH_S = 0.5  # a worker looks for its parent this often


@dataclass(frozen=True)
class Limits:
    """What a job may use: ``budget_s`` its time budget (s; None: starnav's defaults, at most
    ``SCAN_BUDGET_S``; ``math.inf``: none), ``max_pixels`` the largest image read,
    ``memory_bytes`` a worker process's memory (None: no limit)."""

    budget_s: float | None = None
    max_pixels: int = MAX_PIXELS
    memory_bytes: int | None = int(DEFAULT_WORKER_MEMORY_MB * 1e6)

    @property
    def deadline_s(self) -> float:
        """Seconds a job may run before its worker is stopped, until the worker tells the
        budget of the solve (``math.inf``: never)."""
        return (SEARCH_BUDGET_S if self.budget_s is None else self.budget_s) + GRACE_S

    @property
    def whole_s(self) -> float:
        """The longest a job may run, its files written (a Dask job, which tells nothing)."""
        return (SCAN_BUDGET_S if self.budget_s is None else self.budget_s) + GRACE_S + WRITE_S

    @staticmethod
    def overrun(budget_s: float, doing: str) -> str:
        """The reason of a job whose worker was stopped past its deadline: its budget (s)
        and what it was ``doing``."""
        return (
            f"error: the job ran past its time budget of {budget_s:.3g} s (+{GRACE_S:g} s) "
            f"while {doing}: its worker process was stopped"
        )


class WorkerProcess:
    """One worker process and the pipe to it; ``run`` a job, ``stop`` it. Made (and remade)
    in the server's main thread: the kernel's parent-death signal follows the thread that
    started the process."""

    def __init__(self, limits: Limits):
        self.limits = limits
        self._start()

    def _start(self) -> None:
        self.process, self.conn = worker_process(
            serve, (os.getpid(), self.limits.memory_bytes), name="starnav-worker"
        )

    async def run(self, args: tuple) -> dict:
        """The answer of ``run_job(*args, max_pixels=...)``, or a failed answer when the
        worker overran its deadline (it is then replaced) or died."""
        loop = asyncio.get_running_loop()
        answer, fault = await loop.run_in_executor(None, self._exchange, args)
        if fault is not None:
            self.stop()
            self._start()
            return failed_answer(fault)
        return answer

    def _exchange(self, args: tuple) -> tuple[dict | None, str | None]:
        """Send a job and wait for its answer (in a thread): (answer, None), or (None, the
        reason to stop the worker)."""
        try:
            self.conn.send((args, self.limits.max_pixels))
        except OSError:
            return None, "error: the worker process solving this job died"
        start = time.monotonic()
        deadline = start + self.limits.deadline_s
        doing = "reading and detecting the image" if args[0] is not None else "solving"
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None, self.limits.overrun(deadline - start - GRACE_S, doing)
            try:
                if not self.conn.poll(min(left, 1.0)):
                    continue
                kind, value = self.conn.recv()
            except (EOFError, OSError):
                return None, "error: the worker process solving this job died"
            if kind == "answer":
                return value, None
            if kind == "compiled":  # machine code compiled: not counted, as in the budget
                deadline += value
            elif kind == "budget":  # the image read and detected: the solve's budget left
                deadline, doing = time.monotonic() + value + GRACE_S, "solving"
            elif kind == "solved":
                deadline = max(deadline, time.monotonic() + WRITE_S)
                doing = "writing its files"

    def stop(self) -> None:
        """Kill the process (a job of it is lost) and close the pipe."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5.0)
        self.conn.close()


def serve(conn, parent_pid: int, memory_bytes: int | None) -> None:
    """A worker process's life: die with the parent, limit the memory, answer jobs from
    ``conn`` until it closes."""
    die_with_parent(parent_pid)
    if memory_bytes is not None:
        limit_memory(memory_bytes)
    lock = threading.Lock()

    def send(message: tuple) -> None:
        with lock:
            conn.send(message)

    threading.Thread(target=_watch, args=(parent_pid, send), daemon=True).start()
    while True:
        try:
            args, max_pixels = conn.recv()
        except (EOFError, OSError):
            return
        answer = run_job(*args, max_pixels=max_pixels, told=lambda *event: send(event))
        send(("answer", answer))


def _watch(parent_pid: int, send) -> None:
    """Exit when the parent is gone; report the seconds spent compiling machine code."""
    counted = compiled_s()
    while True:
        time.sleep(WATCH_S)
        if os.getppid() != parent_pid:
            os._exit(0)
        now = compiled_s()
        if now > counted + 0.1:
            try:
                send(("compiled", now - counted))
            except OSError:
                os._exit(0)
            counted = now
