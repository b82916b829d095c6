"""starnav on real star-camera images: the four of tests/data/images/reference.json, read from
../shared/data (``shared_data.PEER_FILES``; provenance and licences: the README beside
reference.json and those of ../shared/data/images and ../shared/data/real).

The reference answers (reference.json) come from two peer solvers, cedar-solve and tetra3rs,
each solving from the image with its own star extraction (tests/data/images/make_reference.py);
they agree with each other within 10″ in boresight, 0.005° in rotation about the boresight and
0.25 % in FOV. starnav must land within BORESIGHT_TOL_DEG / TWIST_TOL_DEG / FOV_TOL of that
reference, with the field of view unknown and with the nominal one given.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from PIL import Image

import starnav
from shared_data import DATA, LYRA, PEER_FILES, POLARIS, SHARED, peer_image
from shared_data import PEER_REFERENCE as REFERENCE
from starnav.geometry import (
    angle_between,
    attitude_difference_deg,
    attitude_from_radec_roll,
    radec_to_unit,
)

pytestmark = pytest.mark.corpus

NAMES = sorted(REFERENCE)

BORESIGHT_TOL_DEG = 0.05  # the peers agree within 10″ (0.003°)
TWIST_TOL_DEG = 0.1  # rotation about the boresight; the peers agree within 0.005°
FOV_TOL = 0.005  # relative; the peers agree within 0.25 % (JPEGs of a distorted lens)
MAX_RMS_PX = 3.0  # the peers' rms: 0.15-0.25 px (tetra3 TIFF/PNG), 0.85-1.4 px (GranaSAT JPEGs)


def boresight_error_deg(ra_deg: float, dec_deg: float, ref: dict) -> float:
    a = radec_to_unit(np.radians(ra_deg), np.radians(dec_deg))
    b = radec_to_unit(np.radians(ref["ra_deg"]), np.radians(ref["dec_deg"]))
    return float(np.degrees(angle_between(a, b)))


def check_against_reference(result, name: str) -> None:
    ref = REFERENCE[name]
    assert result.solution is not None, f"{name}: not solved: {result.reason}"
    sol = result.solution
    assert result.reason == ""
    assert sol.parity == ref["parity"] == 1  # ordinary cameras: the sky as seen
    error = boresight_error_deg(sol.ra_deg, sol.dec_deg, ref)
    assert error < BORESIGHT_TOL_DEG, f"{name}: boresight {error * 3600:.0f}″ off"
    R_ref = attitude_from_radec_roll(ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"])
    boresight_deg, twist_deg = attitude_difference_deg(sol.R_cam_from_icrs, R_ref)
    assert boresight_deg < BORESIGHT_TOL_DEG  # the matrix agrees with the reported RA/Dec
    assert twist_deg < TWIST_TOL_DEG, f"{name}: {twist_deg:.3f}° of roll off"
    assert abs(sol.fov_deg / ref["fov_deg"] - 1.0) < FOV_TOL, f"{name}: FOV {sol.fov_deg}"
    assert sol.n_matched >= 4
    assert sol.rms_px < MAX_RMS_PX


# ------------------------------------------------------------------ the data themselves


@pytest.mark.parametrize("name", NAMES)
def test_shared_file_is_the_one_referenced(name):
    """The file in ../shared/data holds the pixels the references were made from: the JPEGs
    byte for byte; the tetra3 frames (referenced as lossless re-encodings, a deflate TIFF and
    a 16-bit PNG) as upstream's TIFFs, whose decoded pixels are the same."""
    ref = REFERENCE[name]["file"]
    path = peer_image(name)
    if ref["identical_to_upstream"] == "bytes":
        assert path.stat().st_size == ref["bytes"]
        assert hashlib.sha256(path.read_bytes()).hexdigest() == ref["sha256"]
    with Image.open(path) as img:
        pixels = np.asarray(img)
    assert pixels.shape == (ref["height"], ref["width"])
    assert str(pixels.dtype) == ref["dtype"]
    if ref["identical_to_upstream"] == "pixels":  # PNG/TIFF decoding is exact everywhere
        le = pixels.astype(pixels.dtype.newbyteorder("<"))
        assert hashlib.sha256(le.tobytes()).hexdigest() == ref["pixel_sha256"]


def test_readme_gives_every_image_its_licence_and_shared_file():
    readme = (DATA / "images" / "README.md").read_text()
    for name in NAMES:
        assert name in readme
        assert str(PEER_FILES[name].relative_to(SHARED)) in readme, f"{name}: no shared file"
        licence = REFERENCE[name]["provenance"]["licence"].split(",")[0]
        assert licence in readme, f"{name}: licence {licence!r} not in README.md"


def test_references_agree_between_peers():
    """Each reference is backed by two independent solvers that agree closely."""
    for name, ref in REFERENCE.items():
        peers = ref["peers"]
        assert {p["status"].upper() for p in peers.values()} == {"MATCH_FOUND"}, name
        for peer in peers.values():
            assert boresight_error_deg(peer["ra_deg"], peer["dec_deg"], ref) < 10 / 3600
            assert abs(peer["fov_deg"] / ref["fov_deg"] - 1.0) < 0.0015
            assert peer["parity"] == ref["parity"]
            R_peer = attitude_from_radec_roll(
                peer["ra_deg"], peer["dec_deg"], peer["roll_deg"], peer["parity"]
            )
            R_ref = attitude_from_radec_roll(
                ref["ra_deg"], ref["dec_deg"], ref["roll_deg"], ref["parity"]
            )
            assert attitude_difference_deg(R_peer, R_ref)[1] < 0.005


# ------------------------------------------------------------------ starnav on them


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_solve_image_fov_unknown(name):
    result = starnav.solve_image(peer_image(name))
    check_against_reference(result, name)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_solve_image_fov_given(name):
    result = starnav.solve_image(peer_image(name), fov_deg=REFERENCE[name]["nominal_fov_deg"])
    check_against_reference(result, name)


@pytest.mark.slow
def test_solve_image_from_array_matches_file():
    """A decoded array gives the same answer as its file."""
    name = LYRA
    with Image.open(peer_image(name)) as img:
        pixels = np.asarray(img)
    result = starnav.solve_image(pixels)
    check_against_reference(result, name)
    from_file = starnav.solve_image(peer_image(name)).solution
    assert result.solution.ra_deg == pytest.approx(from_file.ra_deg, abs=1e-9)
    assert result.solution.dec_deg == pytest.approx(from_file.dec_deg, abs=1e-9)


@pytest.mark.slow
def test_cli_solve_json(capsys):
    from starnav.cli import main

    name = POLARIS
    assert main(["solve", str(peer_image(name)), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["solved"] is True
    assert boresight_error_deg(out["ra_deg"], out["dec_deg"], REFERENCE[name]) < BORESIGHT_TOL_DEG
