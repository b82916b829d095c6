"""Exit codes, the parser that reports a mistake in one line, the exit without the last
garbage collections, a run without them and an exit without the teardown: what every
command line of starnav shares (``starnav``, ``starnav-solve-field``, ``starnav-astap``).
Only the standard library is imported here, so that a drop-in's ``--help`` loads nothing
heavier."""

from __future__ import annotations

import argparse
import atexit
import contextlib
import gc
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import NoReturn

EXIT_OK, EXIT_NOT_SOLVED, EXIT_BAD_INPUT = 0, 1, 2


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage mistake in one line (exit 2), without the usage dump."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


def freeze_at_exit() -> None:
    """Skip the interpreter's last garbage collections when the process exits: ``gc.freeze``
    registered with ``atexit``, once however often this is called. After a solve they walk every
    object numba made (0.1-0.3 s of a command's wall time); the system takes the memory back."""
    atexit.unregister(gc.freeze)
    atexit.register(gc.freeze)


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Run a command without the cyclic garbage collector (its state restored after): a drop-in
    call imports numpy, astropy, scipy and numba, ~180 000 objects, and the collections their
    allocations set off walk them all again and again, ~0.2 s of a 1.3 s call
    (docs/performance.md). What one solve leaves in reference cycles is a few thousand objects,
    taken back when the process ends (a batch of files holds each file's)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def exit_now(code: int) -> NoReturn:
    """End a drop-in's process with ``code`` at once, stdout and stderr flushed: ``os._exit``
    skips the interpreter's teardown, which frees the objects of numpy, astropy, scipy and
    numba one by one (60-90 ms of a drop-in call, docs/performance.md), and the ``atexit``
    handlers, none of which has work left after a drop-in call (logging has no handlers, PIL's
    and numba's and llvmlite's clear caches or mark the shutdown, no temporary file or thread
    is left: the SExtractor folder is removed by its ``with``). Only for a process whose files
    are closed: the drop-ins' console scripts (``main()`` without ``argv``)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said
            pass
    os._exit(code)


def run_console(run: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None) -> int:
    """A drop-in's ``main``: ``run(argv)`` without the cyclic garbage collector
    (``collector_paused``); its exit code, or for the console script (``argv`` None) the end
    of its process at once (``exit_now``)."""
    freeze_at_exit()
    with collector_paused():
        code = run(argv)
    if argv is None:
        exit_now(code)
    return code
