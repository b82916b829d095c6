"""Time budgets: every solve stops when its budget is spent and says so.

A ``Deadline`` is made when a solve starts (after the catalog, tables and solver are
prepared: a one-time cost per process) and travels in the identification's ``MatchSettings``;
the searches look at it between units of work: the triangle search's kernel reads the clock
every ``CLOCK_EVERY`` hypotheses screened or verified, the FOV search between look-up batches
(``next_chunk`` sizes them to ``UNIT_SHARE`` of the budget) and hypotheses, a fisheye scan
between trial focal lengths. So a call overruns its budget by at most one such unit. When it
is spent the answer is "not solved" with the reason
"time budget spent (...)" and what was tried.

Time spent compiling the machine code (once per installation, about 1-4 min) is not counted: the
first solve after installing would otherwise always run out. numba announces compilations as
"numba:compile" events, listened to from the first deadline on; loading already compiled code
(~0.2 s, once per process) is counted.

Defaults (seconds), chosen as what a user waits for and measured not to cost a solve on the
benchmarks (docs/performance.md, "Time budgets"):
``KNOWN_BUDGET_S`` star lists or images with the camera (focal length) known, a field up to
``WIDE_FIELD_DEG`` across the diagonal; ``WIDE_BUDGET_S`` a wider one (its hypotheses cost more
to verify); ``SEARCH_BUDGET_S`` the field of view searched (pinhole); ``SCAN_BUDGET_S`` a
fisheye's focal length scanned.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

from starnav.errors import StarnavError, shown

KNOWN_BUDGET_S = 2.0
WIDE_BUDGET_S = 10.0
WIDE_FIELD_DEG = 60.0
SEARCH_BUDGET_S = 10.0
SCAN_BUDGET_S = 120.0
DEFAULTS = (
    f"{KNOWN_BUDGET_S:g} s with the FOV or camera given ({WIDE_BUDGET_S:g} s for fields over "
    f"{WIDE_FIELD_DEG:g}° across), {SEARCH_BUDGET_S:g} s with the FOV searched, "
    f"{SCAN_BUDGET_S:g} s for a fisheye's focal scan"
)

SPENT = "time budget spent"  # how the reason of a solve stopped by its deadline begins
UNIT_SHARE = 0.05  # a search's unit of work lasts about this part of its budget
CHUNK_GROWTH = 2  # a chunk of work is at most this many times the last one

_COMPILING = threading.local()  # per thread: nesting depth and start of the outermost compile
_COMPILE_S = [0.0]  # seconds spent compiling in this process
_RUNNING = [0.0]  # start of the outermost compilation running now (any thread), 0: none
_CLOCK: list[bool] = []  # whether the compile clock is installed


def _install_compile_clock() -> None:
    """Count the seconds of numba compilations (outermost events only: a kernel compiles the
    kernels it calls inside its own event)."""
    if _CLOCK:
        return
    _CLOCK.append(True)
    from starnav.runtime.caching import python_kernels

    if python_kernels():  # nothing compiles, and numba is not to be imported
        return
    try:
        from numba.core import event
    except ImportError:  # no numba event API: compilations are counted in budgets
        return

    class _Clock(event.Listener):
        def on_start(self, _event) -> None:
            depth = getattr(_COMPILING, "depth", 0)
            if depth == 0:
                _COMPILING.t0 = _RUNNING[0] = time.perf_counter()
            _COMPILING.depth = depth + 1

        def on_end(self, _event) -> None:
            _COMPILING.depth -= 1
            if _COMPILING.depth == 0:
                _COMPILE_S[0] += time.perf_counter() - _COMPILING.t0
                _RUNNING[0] = 0.0

    event.register("numba:compile", _Clock())


def compiled_s() -> float:
    """Seconds of numba compilation in this process, the one running now included, counted
    from the first call (which starts the count; loading cached machine code is none)."""
    _install_compile_clock()
    running = _RUNNING[0]
    return _COMPILE_S[0] + (time.perf_counter() - running if running else 0.0)


def default_budget_s(*, known: bool, scan: bool, field_deg: float = 0.0) -> float:
    """The default budget (s) of a solve: a fisheye's focal ``scan``, or the camera or FOV
    ``known`` (a field of ``field_deg`` across the diagonal), or the FOV searched."""
    if scan:
        return SCAN_BUDGET_S
    if known:
        return WIDE_BUDGET_S if field_deg > WIDE_FIELD_DEG else KNOWN_BUDGET_S
    return SEARCH_BUDGET_S


def check_budget(time_budget_s: float | None, default_s: float) -> float:
    """A budget in seconds: ``default_s`` for None, ``math.inf`` for no limit, or a one-line
    error for anything but a positive number."""
    if time_budget_s is None:
        return default_s
    ok = isinstance(time_budget_s, int | float) and not isinstance(time_budget_s, bool)
    if not ok or math.isnan(time_budget_s) or time_budget_s <= 0:
        raise StarnavError(
            f"time_budget_s must be a positive number of seconds, got {shown(time_budget_s)}"
        )
    return float(time_budget_s)


@dataclass(frozen=True)
class Deadline:
    """When a solve's budget ends. ``budget_s``: the budget (s); ``start``: its start
    (``time.perf_counter()``, s); ``compile_s``: seconds compiled in this process before it
    (compilation after the start extends the deadline)."""

    budget_s: float
    start: float
    compile_s: float

    @classmethod
    def after(cls, budget_s: float) -> Deadline | None:
        """A deadline ``budget_s`` seconds from now (None for an infinite budget)."""
        if math.isinf(budget_s):
            return None
        _install_compile_clock()  # numba is imported by the solve anyway
        return cls(budget_s, time.perf_counter(), _COMPILE_S[0])

    @property
    def end_time(self) -> float:
        """When the budget ends (``time.perf_counter()`` s), the compilations so far left out
        (a kernel reads its clock against it)."""
        return self.start + self.budget_s + (_COMPILE_S[0] - self.compile_s)

    @classmethod
    def now(cls, budget_s: float) -> Deadline:
        """A deadline ``budget_s`` seconds (``math.inf``: none) from now, kept as a start too:
        ``spent_s`` counts from it (a job's read and detection against its budget)."""
        return cls(budget_s, time.perf_counter(), compiled_s())

    def spent_s(self) -> float:
        """Seconds since the start, the compilations since left out."""
        return time.perf_counter() - self.start - (compiled_s() - self.compile_s)

    def expired(self) -> bool:
        """Whether the budget is spent."""
        return time.perf_counter() >= self.end_time

    def reason(self, tried: str) -> str:
        """The reason of a solve stopped by this deadline, with what was ``tried``."""
        return f"{SPENT} ({self.budget_s:g} s): {tried}"


def next_chunk(deadline: Deadline, elapsed_s: float, size: int, most: int) -> int:
    """The items of a search's next chunk of work, for it to last about ``UNIT_SHARE`` of the
    ``deadline``'s budget, from the last chunk's: ``size`` items in ``elapsed_s`` seconds
    (1 to ``most``, and at most ``CHUNK_GROWTH`` times ``size``)."""
    per_item = max(elapsed_s, 1e-6) / size
    wanted = UNIT_SHARE * deadline.budget_s / per_item
    # at most twice the last: items differ in cost (a pattern of short edges draws many
    # times the catalog candidates of a long one), so a cheap chunk says little of the next
    return int(min(max(wanted, 1.0), CHUNK_GROWTH * size, most))


def sooner(budget_s: float, deadline: Deadline | None) -> Deadline | None:
    """A deadline ``budget_s`` seconds from now, or ``deadline`` (None: no limit) when it
    ends first: a part of a solve's work capped by its own budget and the solve's."""
    own = Deadline.after(budget_s)
    if deadline is not None and (own is None or deadline.end_time < own.end_time):
        return deadline
    return own


def expired(deadline: Deadline | None) -> bool:
    """Whether ``deadline`` (None: no limit) has passed."""
    return deadline is not None and deadline.expired()
