"""The real all-sky corpus (tests/data/real/allsky_manifest.json): its metadata and independent
references, and starnav on its development frames through the command line.

The frames are other projects' files (the manifest gives repository, commit, path, SHA-256);
they are read from ``$STARNAV_ALLSKY_CORPUS`` and every test that needs them is skipped, saying
so, when that folder is not there. The references (astrometry.net on crops of each frame, or
hand identifications) are made by benchmarks/images/make_allsky_reference.py; the solve test
runs benchmarks/images/real_allsky.py's mode (b), ``--lens MODEL`` only, and asserts that no
answer is wrong and that at least ``SOLVED_FLOOR`` development frames solve (measured on the
code of 0ed6782, see docs/allsky.md): a frame that stops solving fails it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from shared_data import DATA, ROOT

pytestmark = pytest.mark.corpus

MANIFEST = json.loads((DATA / "real" / "allsky_manifest.json").read_text())
FILES = MANIFEST["files"]
ENV = "STARNAV_ALLSKY_CORPUS"
SOLVED_FLOOR = 2  # development frames solved with --lens only at 0ed6782 (docs/allsky.md)
LENSES = {"equidistant", "equisolid", "stereographic", "orthographic", "unknown"}
# a reference star's pixel through its crop's WCS vs its catalog RA/Dec: the script keeps the
# matches within 2 px of their WCS position; in pixels of the centre crop's scale, with room
# for the other crops' scales
REFERENCE_AGREES_PX = 2.5


def _benchmark():
    path = ROOT / "benchmarks" / "images" / "real_allsky.py"
    spec = importlib.util.spec_from_file_location("real_allsky", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def corpus_folder() -> Path:
    folder = os.environ.get(ENV)
    if not folder or not Path(folder).is_dir():
        pytest.skip(f"the all-sky frames are not here: set {ENV} to their folder")
    return Path(folder)


def test_manifest_entries_say_where_each_frame_comes_from():
    sets = _benchmark().SETS
    names = [f["name"] for f in FILES]
    assert len(names) == len(set(names)) >= 25
    for f in FILES:
        assert len(f["commit"]) == 40 and len(f["sha256"]) == 64 and f["bytes"] > 0
        assert f["repository"].count("/") == 1 and f["path"]
        assert f["licence"] and isinstance(f["redistributable"], bool)
        assert f["set"] in sets, f["name"]
        assert f["lens"] in LENSES
        assert f["kind"] in ("all-sky", "meteor")
        ref = f["reference"]
        assert ref["method"]
        assert ref.get("uncertainty_deg", 0.0) >= 0.0 and ref.get("scale_deg_per_px", 1.0) > 0.0


def test_whole_projects_are_held_back():
    """Each held-back set is whole projects (at least two) that no other set has; the second
    and third ("heldback_2", "heldback_3", each gathered after the one before had been run)
    take their frames from repositories named nowhere else in tests/data/real, the other
    sets' or the other manifests'."""
    projects: dict[str, set] = {}
    for f in FILES:
        projects.setdefault(f["project"], set()).add(f["set"])
    assert all(len(sets) == 1 for sets in projects.values())  # no project split across sets
    assert len({p for p, sets in projects.items() if sets == {"development"}}) >= 5
    for held in _benchmark().SETS[1:]:
        assert len([p for p, sets in projects.items() if sets == {held}]) >= 2, held
    for held in ("heldback_2", "heldback_3"):
        fresh = {f["repository"] for f in FILES if f["set"] == held}
        elsewhere = {f["repository"] for f in FILES if f["set"] != held}
        for other in ("sources.json", "narrow_heldback.json"):
            text = (DATA / "real" / other).read_text()
            elsewhere |= set(re.findall(r'"repo(?:sitory)?": "([^"]+)"', text))
        assert fresh and not fresh & elsewhere, (held, fresh & elsewhere)


def test_reference_stars_lie_where_their_crop_wcs_puts_them():
    """Each astrometry.net reference star's pixel, through the WCS of the crop that matched it,
    is its catalog position within the match's 2 px: the pixel conversion (crop offset, FITS
    1-based) is right."""
    bench = _benchmark()
    checked = 0
    for f in FILES:
        ref = f["reference"]
        if not ref.get("stars") or not ref["method"].startswith(("astrometry.net", "sky rotation")):
            continue
        reference = bench.Reference(ref)
        assert len(ref["stars"]) <= 40
        for x, y, ra, dec, _source in ref["stars"]:
            sky = reference.sky_at(x, y)
            if sky is None:  # at a crop's edge: the scoring does not use its WCS there
                continue
            off = float(bench._angle_deg(sky, bench._unit(ra, dec)))
            assert off < REFERENCE_AGREES_PX * reference.scale_deg_px, (f["name"], x, y, off)
            checked += 1
    assert checked >= 100


def test_score_flags_an_answer_that_puts_a_star_elsewhere():
    """The benchmark's scoring: identified stars at their reference pixels are right; one of
    them given another reference star's catalog number is WRONG; so is a boresight 2° off."""
    from starnav.catalog import load_catalog

    bench = _benchmark()
    catalog = load_catalog()
    ref = next(
        (f["reference"] for f in FILES
         if f["reference"].get("confirmed_by") and len(f["reference"].get("stars") or []) >= 10),
        None,
    )  # fmt: skip
    assert ref is not None, "no frame with a confirmed astrometry.net reference"
    reference = bench.Reference(ref)
    units = bench._unit(catalog.ra_deg, catalog.dec_deg)
    stars = []
    for x, y, ra, dec, _ in ref["stars"]:
        off = bench._angle_deg(units, bench._unit(ra, dec))
        k = int(np.argmin(off))
        if off[k] < 0.01:  # a Hipparcos star (Tycho-2 holds fainter ones too)
            stars.append({"x": x, "y": y, "catalog_id": int(catalog.ids[k])})
    assert len(stars) >= 3
    none = {"cx": None, "ra_deg": None}
    assert bench.score({"stars": stars, **none}, reference, catalog)["verdict"] == "ok"
    far = next(
        s for s in stars[1:] if np.hypot(s["x"] - stars[0]["x"], s["y"] - stars[0]["y"]) > 30
    )
    swapped = [dict(stars[0], catalog_id=far["catalog_id"]), *stars[1:]]
    assert bench.score({"stars": swapped, **none}, reference, catalog)["verdict"] == "WRONG"
    (x, y), (ra, dec) = ref["centre_px"], ref["centre_radec_deg"]
    on = {"stars": [], "cx": x, "cy": y, "ra_deg": ra, "dec_deg": dec}
    assert bench.score(on, reference, catalog)["verdict"] == "ok"
    off = dict(on, dec_deg=dec + 2.0 if dec < 80 else dec - 2.0)
    assert bench.score(off, reference, catalog)["verdict"] == "WRONG"


def test_frames_present_are_upstream_bytes():
    folder = corpus_folder()
    present = [f for f in FILES if (folder / f["name"]).exists()]
    if not present:
        pytest.skip(f"none of the manifest's frames is in {folder}")
    for f in present:
        data = (folder / f["name"]).read_bytes()
        assert len(data) == f["bytes"] and hashlib.sha256(data).hexdigest() == f["sha256"], f[
            "name"
        ]


@pytest.mark.slow
def test_development_frames_solve_with_the_lens_type_only_and_never_wrongly():
    from starnav.catalog import load_catalog

    folder = corpus_folder()
    bench = _benchmark()
    catalog = load_catalog()
    help_text = bench.cli_options()
    solved, wrong = [], []
    for f in FILES:
        if f["set"] != "development" or bench.file_state(f, folder):
            continue
        result = bench.run_frame(f, folder, ["b"], help_text, catalog)
        word = bench.mode_summary(result["modes"]["b"])[0]
        solved += [f["name"]] if word == "solved" else []
        wrong += [(f["name"], bench.outcome(result["modes"]["b"][-1]))] if word == "WRONG" else []
    assert wrong == []
    assert len(solved) >= SOLVED_FLOOR, solved
