"""Exit codes, the parser that reports a mistake in one line, the exit without the last
garbage collections and a run without them: what every command line of starnav shares
(``starnav``, ``starnav-solve-field``, ``starnav-astap``). Only the standard library is
imported here, so that a drop-in's ``--help`` loads nothing heavier."""

from __future__ import annotations

import argparse
import atexit
import contextlib
import gc
from collections.abc import Iterator

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
