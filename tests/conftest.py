"""Shared fixtures: the data of ../shared, the Hipparcos catalog as the reference frames used it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from starnav.catalog import HIPPARCOS_EPOCH_YEAR, load_catalog

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
CONTEST = SHARED / "contest2019"
REFERENCE = SHARED / "reference_frames"


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
    return load_catalog(CONTEST / "catalog.csv")


def reference_frames(name: str) -> list[dict]:
    with (REFERENCE / name).open() as fh:
        return [json.loads(line) for line in fh]
