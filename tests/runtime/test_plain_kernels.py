"""The kernels run as plain Python (``$STARNAV_KERNELS=python``): numba is not loaded, the
answers are the machine code's, and ``starnav identify`` on one list of a known field starts
that way, redoing the command with the machine code when the plain solve runs out of its
short budget. Times are measured by benchmarks/speed/startup.py, never here."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from starnav.runtime.caching import KERNELS_ENV

# frames of both parities, noisy ones with false stars and missing stars, a few-star one
FRAMES = [
    {"seed": seed, "parity": parity, **noise}
    for seed, parity, noise in [
        (1, 1, {}),
        (2, -1, {}),
        (3, 1, {"noise_px": 0.5, "false_stars": 2, "missing_frac": 0.1}),
        (4, -1, {"noise_px": 0.5, "false_stars": 2, "missing_frac": 0.1}),
        (5, 1, {"noise_px": 0.3, "false_stars": 1}),
        (6, 1, {}),
    ]
]
SOLVE = """
import json, sys
import numpy as np
import starnav
cat = starnav.load_catalog(None, mag_limit=6.0)
camera = starnav.Camera.from_fov(12.0, 512)
out = []
for spec in {frames!r}:
    spec = dict(spec)
    f = starnav.simulate_frame(cat, camera, seed=spec.pop("seed"), **spec)
    r = starnav.solve_stars(f.xy, width=512, fov_deg=12.0, brightness=f.brightness, catalog=cat)
    s = r.solution
    out.append(None if s is None else
               {{"ids": [m.catalog_id for m in s.stars], "R": s.R_cam_from_icrs.tolist(),
                 "p": s.false_match_probability}})
print(json.dumps({{"answers": out, "numba": "numba" in sys.modules}}))
"""


def _run(code_or_args: list[str], kernels: str | None, **kwargs) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != KERNELS_ENV}
    if kernels is not None:
        env[KERNELS_ENV] = kernels
    return subprocess.run(
        [sys.executable, *code_or_args], env=env, capture_output=True, text=True, **kwargs
    )


def test_plain_python_kernels_answer_as_the_machine_code_without_loading_numba():
    runs = {}
    for kernels in ("python", "numba"):
        done = _run(["-c", SOLVE.format(frames=FRAMES)], kernels, check=True)
        runs[kernels] = json.loads(done.stdout.splitlines()[-1])
    assert runs["python"]["numba"] is False
    assert runs["numba"]["numba"] is True
    plain, machine = runs["python"]["answers"], runs["numba"]["answers"]
    assert sum(a is not None for a in machine) >= 5
    for a, b in zip(plain, machine, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            assert a["ids"] == b["ids"]
            np.testing.assert_allclose(a["R"], b["R"], atol=1e-12)
            assert a["p"] == pytest.approx(b["p"], rel=1e-9)


def _identify(star_list, kernels: str | None, *extra: str) -> tuple[dict, str, int]:
    """``python -X importtime -m starnav identify LIST ...``: its JSON answer, the modules
    it imported (stderr) and its exit status."""
    args = ["-X", "importtime", "-m", "starnav", "identify", str(star_list), "--fov-deg", "12"]
    done = _run([*args, "--width", "512", "--json", *extra], kernels)
    lines = done.stdout.splitlines()
    assert len(lines) == 1, done.stdout  # one answer, also when the command ran again
    return json.loads(lines[0]), done.stderr, done.returncode


def _imported(importtime: str, module: str) -> bool:
    return any(line.rsplit("|", 1)[-1].strip() == module for line in importtime.splitlines())


def test_identify_on_one_list_of_a_known_field_runs_without_numba(star_list):
    plain, imports, code = _identify(star_list, None)
    machine, imports_machine, code_machine = _identify(star_list, "numba")
    assert code == code_machine == 0
    assert not _imported(imports, "numba")
    assert _imported(imports_machine, "numba")
    assert [s["catalog_id"] for s in plain["stars"]] == [s["catalog_id"] for s in machine["stars"]]
    for key in ("ra_deg", "dec_deg", "roll_deg"):
        assert plain[key] == pytest.approx(machine[key], abs=1e-9)


def test_identify_redoes_a_plain_solve_that_runs_out_of_time_with_the_machine_code(star_list):
    """A budget the plain solve cannot keep (1 ms): the command runs again with numba, which
    gets the same budget, and prints one answer."""
    answer, imports, code = _identify(star_list, None, "--time-budget", "0.001")
    assert _imported(imports, "numba")
    assert code in (0, 1)
    assert answer["solved"] or answer["reason"].startswith("time budget spent")


def test_an_unknown_kernels_setting_is_one_line_and_exit_2(star_list):
    args = ["-m", "starnav", "identify", str(star_list), "--fov-deg", "12", "--width", "512"]
    done = _run(args, "fast")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "starnav identify: error: $STARNAV_KERNELS must be numba or python, got 'fast'"
    ]
