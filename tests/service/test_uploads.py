"""Source lists sent to nova's ``api/upload``: x/y lists in the request (what astrometry.net's
client.py --upload-xy sends: the x and y of an xylist, no brightness) and xylist files (a
FITS table uploaded as the file, sorted by its FLUX or magnitude column), of the GranaSAT
Pleiades frame's stars (``source_lists``). A solved answer must put the image centre within
3' of astrometry.net's; an unsolved one must say why."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")
from starlette.testclient import TestClient

from service_helpers import wait_for_job
from source_lists import (
    PLEIADES,
    REAL_REFERENCE,
    centre_offset_arcmin,
    plain_xylist,
    pleiades_sources,
    siril_xylist,
)
from starnav.service.app import ServiceConfig, create_app

pytestmark = [pytest.mark.service, pytest.mark.slow]

SCALE = REAL_REFERENCE[PLEIADES]["scale_arcsec_per_px"]
HINTS = {"scale_units": "arcsecperpix", "scale_type": "ul", "scale_lower": 0.9 * SCALE,
         "scale_upper": 1.1 * SCALE}  # fmt: skip


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("uploads")
    with TestClient(create_app(ServiceConfig(data_dir=data / "data", workers=1))) as client:
        yield client


def _session(client) -> str:
    r = client.post("/api/login", data={"request-json": json.dumps({"apikey": "k"})})
    return r.json()["session"]


def _submit(client, args: dict, file: tuple | None = None) -> int:
    args = {"session": _session(client), **args}
    files = None if file is None else {"file": file}
    r = client.post("/api/upload", data={"request-json": json.dumps(args)}, files=files)
    assert r.json()["status"] == "success", r.text
    return r.json()["subid"]


def _calibration(client, job_id: int) -> dict:
    return client.get(f"/api/jobs/{job_id}/calibration").json()


def _xy_args(order: np.ndarray) -> dict:
    x, y, _, width, height = pleiades_sources()
    return {"x": x[order].tolist(), "y": y[order].tolist(), "image_width": width,
            "image_height": height, **HINTS}  # fmt: skip


def test_xy_list_brightest_first_solves(server):
    _, _, flux, _, _ = pleiades_sources()
    job = _submit(server, _xy_args(np.argsort(-flux, kind="stable")))
    answer = wait_for_job(server, job)
    assert answer["status"] == "success", answer["reason"]
    cal = _calibration(server, job)
    assert centre_offset_arcmin(cal["ra"], cal["dec"]) < 3.0


def test_xylist_file_is_sorted_by_its_flux(server, tmp_path):
    """Siril's xylist in detection order, uploaded as the file: sorted by FLUX, solved."""
    data = siril_xylist(tmp_path / "stars.xyls").read_bytes()
    job = _submit(server, HINTS, ("stars.xyls", data, "application/octet-stream"))
    answer = wait_for_job(server, job)
    assert answer["status"] == "success", answer["reason"]
    cal = _calibration(server, job)
    assert centre_offset_arcmin(cal["ra"], cal["dec"]) < 3.0


def test_xy_list_in_detection_order_solves(server, tmp_path):
    """client.py --upload-xy of a list in detection order (by y) and no brightness, and the
    same as a plain xylist file: solved without brightness (issue 36.2), as the sorted one."""
    x, _, _, _, _ = pleiades_sources()
    for job in (_submit(server, _xy_args(np.arange(len(x)))),
                _submit(server, HINTS, ("plain.xyls", plain_xylist(tmp_path / "p.xyls")
                                        .read_bytes(), "application/octet-stream"))):  # fmt: skip
        answer = wait_for_job(server, job)
        assert answer["status"] == "success", answer["reason"]
        cal = _calibration(server, job)
        assert centre_offset_arcmin(cal["ra"], cal["dec"]) < 3.0
