"""One star list of a known field in a process of its own (``starnav identify LIST``): the
kernels run as plain Python (``starnav.runtime.caching.python_kernels``). Loading numba and
the kernels' machine code costs such a process ~0.6 s and ~150 MB; the plain solve of a
short list takes ~50-200 ms. A solve that needs longer than ``PLAIN_BUDGET_S`` is redone, the
whole command again, with the machine code (benchmarks/speed/startup.py measures both)."""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

import numpy as np

from starnav.api import SolveOptions, solve_stars
from starnav.results import SolveResult
from starnav.runtime.budget import SPENT
from starnav.runtime.caching import KERNELS_ENV, python_kernels
from starnav.starlist import StarList

PLAIN_BUDGET_S = 0.3  # s: a plain solve that needs longer is redone with the machine code
# longer lists are solved with the machine code at once: a plain solve's screen costs points
# x hypotheses (a 6° tracker's 105 points and its deep stage: ~0.5 s)
PLAIN_MAX_POINTS = 50


def plain_python(args: argparse.Namespace, n_points: int) -> bool:
    """Whether this command's one list of ``n_points`` of a known field is solved with the
    kernels as plain Python: the console script (the process is the command's alone), at
    most ``PLAIN_MAX_POINTS``, ``$STARNAV_KERNELS`` not set, and no kernel loaded with numba
    yet (then it sets the variable)."""
    known = args.fov_deg is not None or args.camera is not None
    own = getattr(args, "own_process", False)
    if not (own and known and n_points <= PLAIN_MAX_POINTS and KERNELS_ENV not in os.environ):
        return False
    os.environ[KERNELS_ENV] = "python"
    if python_kernels():
        return True
    del os.environ[KERNELS_ENV]  # decided before: the machine code, for this process's children too
    return False


def solve_plain(
    stars: StarList,
    options: SolveOptions,
    *,
    width: int | None,
    height: int | None,
    prior: np.ndarray | None,
) -> SolveResult:
    """``solve_stars`` in plain Python within ``PLAIN_BUDGET_S`` (or the budget given, when
    less); when that is spent, the same command again with the machine code (``exec``:
    nothing has been printed yet), which has the whole budget."""
    budget_s = PLAIN_BUDGET_S if options.time_budget_s is None else options.time_budget_s
    quick = replace(options, time_budget_s=min(budget_s, PLAIN_BUDGET_S))
    result = solve_stars(stars, quick, width=width, height=height, prior=prior)
    if result.solution is None and result.reason.startswith(SPENT):
        sys.stdout.flush()
        sys.stderr.flush()
        env = {**os.environ, KERNELS_ENV: "numba"}
        os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)
    return result
