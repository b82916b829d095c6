"""What every benchmark shares: the machine line, the scoring of an answer against the truth,
markdown tables and the generated blocks of the docs.

* ``machine()``: one line naming the CPU, cores, load average, Python, numpy, the system and
  the starnav checkout measured (version and git commit), for the text a script writes.
* Scoring: ``score_solution`` / ``score_attitude`` are ``starnav.evaluate.score``'s, the rule
  ``starnav evaluate`` scores with (``CORRECT_RULE`` says it in words); ``score_answer`` applies
  it to an answer in the JSON form workers and the peers' adapters print; ``verdict`` adds the
  benchmarks' one further bound, ``WRONG_DEG``, between an inexact answer and a wrong one
  (comparisons with other solvers, real photographs whose reference is another solver's).
* ``table_head`` / ``table_row``: markdown table lines; ``replace_block``: writes generated
  text between ``<!-- begin NAME -->`` and ``<!-- end NAME -->`` of a hand-written markdown
  file, the prose around it left as written.
* ``warm_up``: the first solves of a process (machine code loaded), before anything is timed.

Scripts run from the repository root, as files or as modules::

    python benchmarks/speed/batch.py --frames 2000
    python -m benchmarks.speed.batch --frames 2000

Each script's first import lines put the repository on ``sys.path`` (``parents[2]`` of the
script), so ``benchmarks.harness`` imports either way, also in workers started with
``python -I``. benchmarks/README.md lists the scripts and the docs they write.
"""

from __future__ import annotations

import os
import platform
import re
import subprocess
import time
from pathlib import Path

import numpy as np

import starnav
from starnav.evaluate.score import (
    CORRECT_BORESIGHT_DEG,
    CORRECT_ROLL_DEG,
    CORRECT_SIGMAS,
    AttitudeScore,
    parity_of,
    score_attitude,
    score_solution,
)
from starnav.geometry import attitude_from_radec_roll

__all__ = [
    "CORRECT_RULE",
    "DOCS",
    "LOAD_AT_START",
    "ROOT",
    "WRONG_DEG",
    "WRONG_RULE",
    "AttitudeScore",
    "machine",
    "replace_block",
    "score_answer",
    "score_attitude",
    "score_solution",
    "table_head",
    "table_row",
    "verdict",
    "warm_up",
]

ROOT = Path(__file__).resolve().parents[1]  # the repository
DOCS = ROOT / "docs"
SHARED = ROOT.parent / "shared" / "data"  # the test data beside the repository
LOAD_AT_START = os.getloadavg()[0]  # when the benchmark's process imported this module

# ----------------------------------------------------------------------------------------------
# the machine


def cpu_model() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if "model name" in line)
    except (OSError, StopIteration):
        pass
    return cpu


def starnav_checkout() -> str:
    """starnav's version and, when it is imported from a git checkout, that checkout's commit
    (with "+ changes" when its src/ or benchmarks/ differ from the commit)."""
    text = f"starnav {starnav.__version__}"
    repo = Path(starnav.__file__).resolve().parents[2]  # src/starnav/__init__.py
    git = ["git", "-C", str(repo)]
    try:
        head = subprocess.run(
            [*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        changes = subprocess.run(
            [*git, "status", "--porcelain", "--untracked-files=no", "--", "src", "benchmarks"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return text
    return f"{text} at {head}{' + changes' if changes else ''}"


def machine(load: float | None = None, *, load_at_end: bool = False) -> str:
    """CPU, cores, the load average when the run started (``load``, default: when this module
    was imported; with ``load_at_end`` also the one now), Python, numpy, the system and the
    starnav checkout: the machine line of a benchmark's text."""
    start = LOAD_AT_START if load is None else load
    loads = f"load average {start:.1f} when it started"
    if load_at_end:
        loads += f", {os.getloadavg()[0]:.1f} at the end"
    return (
        f"{cpu_model()}, {os.cpu_count()} cores, {loads}; Python {platform.python_version()}, "
        f"numpy {np.__version__}, {platform.system()}; {starnav_checkout()}"
    )


# ----------------------------------------------------------------------------------------------
# scoring: starnav.evaluate.score's rule, and the bound beyond which an answer is wrong

CORRECT_RULE = (
    f"correct: the truth's parity and within {CORRECT_BORESIGHT_DEG:g}° in boresight and "
    f"{CORRECT_ROLL_DEG:g}° in roll of the truth, or within {CORRECT_SIGMAS:g} of the answer's "
    "own reported 1-sigma errors (`starnav.evaluate.score`, the rule of `starnav evaluate`)"
)
WRONG_DEG = 0.5  # an answer this far off in boresight or in roll, or of the other parity, is wrong
WRONG_RULE = f"wrong: {WRONG_DEG:g}° or more off in boresight or in roll, or the other parity"
MIRROR = np.diag([-1.0, 1.0, 1.0])


def answer_attitude(answer: dict) -> np.ndarray | None:
    """The attitude ``R_cam_from_icrs`` of an answer in the JSON form the workers and the
    peers' adapters print (and a converted reference's): ``R_cam_from_icrs`` (or ``R``),
    else from ``ra_deg``/``dec_deg``/``roll_deg`` and ``parity`` (null or absent: +1); None
    when it holds none."""
    R = answer.get("R_cam_from_icrs", answer.get("R"))
    if R is not None:
        return np.asarray(R, dtype=float)
    if answer.get("ra_deg") is None:
        return None
    return attitude_from_radec_roll(
        answer["ra_deg"], answer["dec_deg"], answer["roll_deg"], answer.get("parity") or 1
    )


def score_answer(answer: dict, R_true: np.ndarray) -> AttitudeScore | None:
    """``score_attitude`` of an answer in the JSON form the workers and the peers' adapters
    print: ``R_cam_from_icrs`` (or ``R``), else ``ra_deg``/``dec_deg``/``roll_deg``; ``parity``
    (null or absent: not reported); ``sigma_boresight_arcsec`` / ``sigma_roll_arcsec`` when
    it has them. None when it holds no answer (``error`` set, or no attitude). An answer of the
    other parity is compared with its mirror image (the attitude of the parity it says), so
    that its errors mean something; it is wrong whatever they are."""
    if answer.get("error") is not None:
        return None
    R = answer_attitude(answer)
    if R is None:
        return None
    parity = answer.get("parity")
    if parity is not None and parity != parity_of(R_true):
        R = MIRROR @ R

    def sigma(key: str) -> float:
        value = answer.get(key)
        return float("nan") if value is None else float(value)

    return score_attitude(
        R,
        R_true,
        parity=parity,
        sigma_boresight_arcsec=sigma("sigma_boresight_arcsec"),
        sigma_roll_arcsec=sigma("sigma_roll_arcsec"),
    )


def verdict(score: AttitudeScore | None) -> str:
    """ "none" (no answer), "correct" (``starnav.evaluate.score``'s rule), "wrong" (``WRONG_DEG``
    or more off in boresight or roll, or the other parity), else "inexact"."""
    if score is None:
        return "none"
    if score.correct:
        return "correct"
    if not score.same_parity or score.boresight_deg >= WRONG_DEG or score.roll_deg >= WRONG_DEG:
        return "wrong"
    return "inexact"


# ----------------------------------------------------------------------------------------------
# markdown


def table_head(*columns: str) -> list[str]:
    """A markdown table's header line and its rule."""
    return [table_row(*columns), "|" + "---|" * len(columns)]


def table_row(*cells: object) -> str:
    """A markdown table row of ``cells`` (each as ``str`` gives it)."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def replace_block(path: str | Path, name: str, text: str, *, missing: str | None = None) -> None:
    """Replace block ``name`` of ``path`` (between ``<!-- begin NAME -->`` and ``<!-- end
    NAME -->``) with ``text``. A missing block (or file) stops the script, unless ``missing``
    is given: then that markdown and an empty block are appended first (the file made)."""
    path = Path(path)
    begin, end = f"<!-- begin {name} -->", f"<!-- end {name} -->"
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    doc = path.read_text() if path.exists() else ""
    if not pattern.search(doc):
        if missing is None:
            raise SystemExit(f"{path}: no block {begin} ... {end}")
        doc = (doc.rstrip("\n") + "\n\n" if doc.strip() else "") + f"{missing}\n\n{begin}\n{end}\n"
    path.write_text(pattern.sub(lambda _: f"{begin}\n{text.strip()}\n{end}", doc))


# ----------------------------------------------------------------------------------------------
# solving


def warm_up(catalog, camera) -> float:
    """Seconds the first solves of a process take (lost in space and tracking, on one
    simulated frame): they load the machine code, or compile it the first time after
    installing. Benchmarks call this before timing anything."""
    from starnav.api import solve_stars
    from starnav.simulate import simulate_frame

    t0 = time.perf_counter()
    frame = simulate_frame(catalog, camera, ra_deg=10.0, dec_deg=20.0, roll_deg=30.0)
    for prior in (None, frame.R_cam_from_icrs):
        solve_stars(
            frame.xy,
            width=camera.width,
            height=camera.height,
            fov_deg=camera.fov_deg,
            catalog=catalog,
            prior=prior,
        )
    return time.perf_counter() - t0
