"""What a process loads on each path: ``import starnav`` (and the CLI's parser) loads no heavy
dependency, the drop-ins' help not even numpy, a star-list solve with the field known loads
numba (its kernels) but not the image stack (astropy, sep, PIL, scipy.ndimage), matplotlib,
scipy.optimize or scipy.spatial, and a clean frame's detection (the path of a plate solve)
does not load scipy.ndimage. Times are measured by benchmarks/speed/startup.py and
benchmarks/speed/dropin_vs_solve_field.py, never here."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import starnav

# what a star-list solve must not load: the image stack, plotting, and the scipy parts only
# images, calibration, pointing and the KD-tree algorithms use (numba itself loads scipy.linalg)
NOT_FOR_STAR_LISTS = (
    "astropy",
    "matplotlib",
    "PIL",
    "sep",
    "tifffile",
    "png",
    "tqdm",
    "scipy.ndimage",
    "scipy.optimize",
    "scipy.spatial",
    "scipy.special",
)
NOT_AT_IMPORT = (*NOT_FOR_STAR_LISTS, "numba", "scipy")

REPORT = """
import json, sys
print(json.dumps(sorted(m for m in sys.modules if m.startswith({prefixes!r}))))
"""


def _loaded(code: str, prefixes: tuple[str, ...]) -> set[str]:
    """The modules among ``prefixes`` (and their submodules) a fresh Python process running
    ``code`` has loaded at its end."""
    script = code + REPORT.format(prefixes=prefixes)
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    ).stdout
    names = set(json.loads(out.splitlines()[-1]))
    return {p for p in prefixes if p in names or any(n.startswith(p + ".") for n in names)}


def test_import_starnav_and_the_cli_parser_load_no_heavy_dependency():
    code = "import starnav, starnav.cli\nstarnav.cli.build_parser()\n"
    assert _loaded(code, NOT_AT_IMPORT) == set()


@pytest.mark.parametrize(
    ("module", "help_flag"),
    [("starnav.dropin.solve_field", "--help"), ("starnav.dropin.astap", "-h")],
)
def test_a_drop_in_help_loads_no_numerical_library(module, help_flag):
    """``starnav-solve-field --help`` and ``starnav-astap -h`` import none of numpy, astropy,
    numba or scipy: the solver is imported when a file is solved."""
    code = (
        "import contextlib, io\n"
        f"import {module} as dropin\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out, "
        "contextlib.suppress(SystemExit):\n"
        f"    dropin.main([{help_flag!r}])\n"
        "assert 'usage' in out.getvalue(), out.getvalue()\n"
    )
    assert _loaded(code, (*NOT_AT_IMPORT, "numpy")) == set()


def test_a_clean_frame_is_detected_without_scipy_ndimage():
    """A star-tracker frame takes detection's fast path (``starnav.detect.tracker``), whose
    3 x 3 median of the tiles is numpy's: importing scipy.ndimage would cost a plate solve
    0.2-0.3 s. The plate solver's own imports do not load it either."""
    code = (
        "import numpy as np\n"
        "import starnav.pipeline.plate\n"
        "from starnav.detect.stars import detect_stars\n"
        "rng = np.random.default_rng(1)\n"
        "y, x = np.mgrid[0:384, 0:512]\n"
        "image = 100.0 + rng.normal(0.0, 5.0, size=x.shape)\n"
        "for cx, cy, peak in zip(rng.uniform(10, 502, 80), rng.uniform(10, 374, 80),\n"
        "                        rng.uniform(100, 2000, 80)):\n"
        "    image += peak * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 1.3**2))\n"
        "found = detect_stars(image.astype(np.float32))\n"
        "assert len(found) >= 60, len(found)\n"
    )
    assert _loaded(code, ("scipy.ndimage",)) == set()


def test_a_star_list_solve_loads_no_image_stack(star_list):
    code = (
        "import numpy as np, starnav\n"
        f"t = np.loadtxt({str(star_list)!r}, delimiter=',', skiprows=1)\n"
        "s = starnav.solve(t[:, :2], fov_deg=12.0, width=512, brightness=-t[:, 2])\n"
        "assert s is not None and s.n_matched == 20, s\n"
    )
    assert _loaded(code, (*NOT_FOR_STAR_LISTS, "numba")) == {"numba"}


def test_starnav_identify_on_a_star_list_loads_no_image_stack(star_list):
    code = (
        "from starnav.cli import main\n"
        f"args = ['identify', {str(star_list)!r}, '--fov-deg', '12', '--width', '512', '--json']\n"
        "assert main(args) == 0\n"
    )
    assert _loaded(code, NOT_FOR_STAR_LISTS) == set()


def test_the_public_names_are_there_when_first_used():
    """``starnav``'s names are imported on first use (module ``__getattr__``), each the one of
    the module it comes from; ``dir()`` lists them before."""
    from starnav import api

    assert set(starnav.__all__) <= set(dir(starnav))
    for name in starnav.__all__:
        assert getattr(starnav, name) is not None
    assert starnav.solve is api.solve and starnav.solve_image is api.solve_image
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        starnav.no_such_name  # noqa: B018


@pytest.mark.parametrize("module", ["starnav.dropin.solve_field", "starnav.dropin.astap"])
def test_a_drop_in_runs_without_the_garbage_collector_and_gives_it_back(module, monkeypatch):
    """A drop-in call runs with the cyclic garbage collector paused (its collections walked
    every object numpy, astropy, scipy and numba made, again and again: ~0.2 s of a call), and
    the caller gets it back as it was, also when the call raises."""
    import gc
    import importlib

    dropin = importlib.import_module(module)
    seen = []

    def run(argv):
        seen.append(gc.isenabled())
        if argv == ["raise"]:
            raise RuntimeError("stop")
        return 0

    monkeypatch.setattr(dropin, "_main", run)
    assert gc.isenabled()
    assert dropin.main(["x"]) == 0
    with pytest.raises(RuntimeError, match="stop"):
        dropin.main(["raise"])
    assert seen == [False, False] and gc.isenabled()


@pytest.mark.parametrize(
    ("module", "argv", "code", "said"),
    [
        ("starnav.dropin.solve_field", ["--version"], 0, "starnav "),
        ("starnav.dropin.solve_field", ["/no/such/image.jpg"], 2, "no/such/image.jpg"),
        ("starnav.dropin.astap", ["-f", "/no/such/image.jpg"], 2, "no/such/image.jpg"),
    ],
)
def test_a_drop_in_console_call_ends_at_once_with_its_output(module, argv, code, said):
    """Run as its console script runs it (``main()``, sys.argv), a drop-in ends its process
    itself (``exit_now``: no interpreter teardown) with its exit status, what it printed
    flushed; nothing after ``main()`` runs."""
    script = (
        "import sys\n"
        f"sys.argv = ['prog', *{argv!r}]\n"
        f"from {module} import main\n"
        "main()\n"
        "print('after main')\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == code, done.stderr
    assert said in done.stdout + done.stderr
    assert "after main" not in done.stdout and "Traceback" not in done.stderr
