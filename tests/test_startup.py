"""What a process loads on each path: ``import starnav`` (and the CLI's parser) loads no heavy
dependency, and a star-list solve with the field known loads numba (its kernels) but not the
image stack (astropy, sep, PIL, scipy.ndimage), matplotlib, scipy.optimize or scipy.spatial.
Times are measured by benchmarks/speed/startup.py, never here."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
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


@pytest.fixture(scope="module")
def star_list(tmp_path_factory):
    """A 12° / 512 px star list (x, y, mag) of 20 stars, solved once here: the subprocesses
    find the pair table in the cache (building it uses scipy.spatial), as every solve but an
    installation's first does."""
    cat = starnav.load_catalog(None, mag_limit=6.0)
    camera = starnav.Camera.from_fov(12.0, 512)
    frame = next(
        f
        for seed in range(100)
        if len((f := starnav.simulate_frame(cat, camera, seed=seed)).xy) >= 20
    )
    keep = np.sort(np.argsort(frame.mag)[:20])
    path = tmp_path_factory.mktemp("startup") / "stars.csv"
    np.savetxt(path, np.column_stack([frame.xy[keep], frame.mag[keep]]), delimiter=",",
               header="x,y,mag", comments="", fmt="%.4f")  # fmt: skip
    assert starnav.solve(frame.xy[keep], fov_deg=12.0, width=512) is not None
    return path


def test_import_starnav_and_the_cli_parser_load_no_heavy_dependency():
    code = "import starnav, starnav.cli\nstarnav.cli.build_parser()\n"
    assert _loaded(code, NOT_AT_IMPORT) == set()


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
