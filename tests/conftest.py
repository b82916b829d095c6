"""Shared fixtures: the Hipparcos catalog as the reference frames used it, the contest's
catalog, a private table cache, a ``starnav serve`` process. Where the data are:
``shared_data`` (``../shared/data`` beside the repository)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from shared_data import CONTEST, SHARED, USER_CACHE_DIR, reference_frames, shared_file
from starnav.api import solve
from starnav.camera import Camera
from starnav.catalog import HIPPARCOS_EPOCH_YEAR, load_catalog
from starnav.runtime.caching import cache_dir
from starnav.simulate import simulate_frame

# The kernels' machine code stays where every solve keeps it (the user's cache, which
# `starnav demo` fills): _private_cache below moves STARNAV_CACHE_DIR before the first kernel
# module is imported, and the kernels would otherwise be compiled again in every test session
# (over a minute of the suite on 2 cores). Subprocesses (the CLI, the drop-ins, the server's
# workers) inherit it. Set before numba is imported: numba reads it once.
os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_dir() / "numba"))

# the names tests imported from conftest before shared_data.py (import them from there)
__all__ = ["CONTEST", "SHARED", "USER_CACHE_DIR", "reference_frames"]


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Databases go to a fresh cache directory, so the tests build them at least once."""
    mp = pytest.MonkeyPatch()
    mp.setenv("STARNAV_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
    yield
    mp.undo()


@pytest.fixture(scope="session")
def hip_1991():
    """Hipparcos Hp <= 6 at its own epoch: the catalog the reference frames were made from."""
    return load_catalog(None, mag_limit=6.0, epoch_year=HIPPARCOS_EPOCH_YEAR)


@pytest.fixture(scope="session")
def contest_catalog():
    return load_catalog(shared_file(CONTEST / "catalog.csv"))


@pytest.fixture(scope="session")
def star_list(tmp_path_factory):
    """A 12° / 512 px star list (x, y, mag) of 20 stars, solved once here: the subprocesses
    that solve it find the pair table in the cache (building it uses scipy.spatial), as every
    solve but an installation's first does."""
    cat = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(12.0, 512)
    frame = next(
        f for seed in range(100) if len((f := simulate_frame(cat, camera, seed=seed)).xy) >= 20
    )
    keep = np.sort(np.argsort(frame.mag)[:20])
    path = tmp_path_factory.mktemp("stars") / "stars.csv"
    np.savetxt(path, np.column_stack([frame.xy[keep], frame.mag[keep]]), delimiter=",",
               header="x,y,mag", comments="", fmt="%.4f")  # fmt: skip
    assert solve(frame.xy[keep], fov_deg=12.0, width=512) is not None
    return path


@pytest.fixture(scope="module")
def nova_server(tmp_path_factory):
    """``starnav serve`` with 2 workers on a free loopback port, its data in a fresh folder,
    for one test module (``service_helpers.Server``: ``url``, ``data_dir``, ``log()``). It
    uses the user's table cache, not the tests' fresh one: the service's tests are not about
    building tables, and a build would cost each test session half a minute. URL uploads
    may fetch from the loopback (the tests' image hosts)."""
    from service_helpers import Server

    server = Server(tmp_path_factory.mktemp("serve"), cache_dir=USER_CACHE_DIR,
                    options=("--allow-url-hosts", "127.0.0.1")).start()  # fmt: skip
    yield server
    server.stop()


def pytest_collection_modifyitems(config, items):
    """Without ../shared/data/contest2019 the tests of the modules that read it are skipped,
    saying so: most reach it through ``shared_file``, which skips, but some name its files
    directly (the CLI's star-list tests) and would fail instead."""
    if CONTEST.is_dir():
        return
    skip = pytest.mark.skip(
        reason=f"the contest data are not in {CONTEST}: the shared test data go beside the "
        "repository, in ../shared/data"
    )
    for item in items:
        if getattr(getattr(item, "module", None), "CONTEST", None) is CONTEST:
            item.add_marker(skip)
