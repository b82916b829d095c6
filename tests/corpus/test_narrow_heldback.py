"""The held-back narrow-field set (tests/data/real/narrow_heldback.json): what makes it held
back and its hints as make_narrow_reference.py draws them. The image files are not needed:
these check the manifest only (the benchmark that solves the frames reads the files)."""

from __future__ import annotations

import importlib.util
import json
import re
import sys

import numpy as np
import pytest

from shared_data import DATA
from starnav.geometry import angle_between, radec_to_unit

REAL = DATA / "real"
MANIFEST = json.loads((REAL / "narrow_heldback.json").read_text())
FILES = MANIFEST["files"]
IN_SET = [entry for entry in FILES if entry["in_set"]]


def _load_script():
    """make_narrow_reference.py as a module (it imports make_reference from its folder)."""
    sys.path.insert(0, str(REAL))
    try:
        path = REAL / "make_narrow_reference.py"
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(REAL))


script = _load_script()


def test_sources_are_new():
    """No repository of the development or held-back corpus (sources.json) is in the set."""
    corpus = json.loads((REAL / "sources.json").read_text())["files"]
    seen = {entry["repository"].lower() for entry in corpus}
    assert not seen & {entry["repository"].lower() for entry in FILES}


def test_file_facts():
    names = [entry["name"] for entry in FILES]
    assert len(names) == len(set(names))
    for entry in FILES:
        assert re.fullmatch(r"[0-9a-f]{64}", entry["sha256"]), entry["name"]
        assert re.fullmatch(r"[0-9a-f]{40}", entry["git_blob"]), entry["name"]
        assert re.fullmatch(r"[0-9a-f]{40}", entry["commit"]), entry["name"]
        assert entry["bytes"] > 0 and entry["licence"] and entry["path"]
        assert isinstance(entry["redistributable"], bool)
        assert entry["in_set"] == ("hints" in entry), entry["name"]


def test_set_is_large_enough_and_narrow():
    """At least 20 frames, each with astrometry.net's horizontal field in 0.3-3.5°."""
    assert len(IN_SET) >= 20
    low, high = script.FOV_BAND_DEG
    for entry in IN_SET:
        assert low <= entry["reference"]["fov_deg"] <= high, entry["name"]
    for entry in FILES:
        if not entry["in_set"] and "reference" in entry:
            assert not low <= entry["reference"]["fov_deg"] <= high, entry["name"]


@pytest.mark.parametrize("entry", IN_SET, ids=[entry["name"] for entry in IN_SET])
def test_hints(entry):
    """The stored hints are the ones the fixed seed draws, their centre is within 5° of the
    reference centre (measured on the sphere, not from the draw) and their scale within 10 %."""
    ref, hint = entry["reference"], entry["hints"]
    assert hint == script.hints(entry["name"], ref)
    true = radec_to_unit(np.radians(ref["ra_deg"]), np.radians(ref["dec_deg"]))
    hinted = radec_to_unit(np.radians(hint["ra_deg"]), np.radians(hint["dec_deg"]))
    offset = np.degrees(angle_between(true, hinted))
    assert offset == pytest.approx(hint["offset_deg"], abs=1e-3)
    assert offset <= script.HINT_OFFSET_MAX_DEG + 1e-3
    ratio = hint["scale_arcsec_per_px"] / ref["scale_arcsec_per_px"]
    assert abs(ratio - 1.0) <= script.HINT_SCALE_ERROR + 1e-3
    assert hint["fov_deg"] / ref["fov_deg"] == pytest.approx(ratio, abs=1e-3)
