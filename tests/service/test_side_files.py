"""nova's file routes for solve-field's side files (``corr_file/N``, ``rdls_file/N``,
``axy_file/N``, ``kml_file/N``, as ``net/urls.py`` names them), from a real ``starnav serve``
process (tests/service_helpers.py): the files a solved image's job has, read with astropy;
a source list's job has no KMZ (no picture) and an unknown job is 404."""

from __future__ import annotations

import io
import urllib.error
import zipfile

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")
pytest.importorskip("httpx2", reason="httpx2 (the multipart uploads of the tests) is missing")
from astropy.io import fits

from service_helpers import Server, fetch, login, upload_image, upload_list, wait_done
from shared_data import REAL, shared_file

pytestmark = [pytest.mark.service, pytest.mark.slow]

IMAGE = "granasat_pleyades_05sec.jpg"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("nova") / "data", workers=1).start()
    try:
        yield srv
    finally:
        srv.stop()


def _table(blob: bytes) -> np.ndarray:
    with fits.open(io.BytesIO(blob)) as hdul:
        return np.array(hdul[1].data)


def test_image_job_serves_corr_rdls_axy_and_kml(server):
    session = login(server.url)
    data = shared_file(REAL / IMAGE).read_bytes()
    job = upload_image(server.url, session, IMAGE, data)
    assert wait_done(server.url, job) == "success"
    corr = _table(fetch(f"{server.url}/corr_file/{job}"))
    rdls = _table(fetch(f"{server.url}/rdls_file/{job}/"))  # a trailing slash too
    axy = _table(fetch(f"{server.url}/axy_file/{job}"))
    assert len(corr) >= 20 and len(rdls) >= len(set(corr["index_id"]))
    np.testing.assert_allclose(rdls["RA"][corr["index_id"]], corr["index_ra"])
    np.testing.assert_allclose(axy["X"][corr["field_id"]], corr["field_x"], atol=1e-3)
    kmz = fetch(f"{server.url}/kml_file/{job}")
    with zipfile.ZipFile(io.BytesIO(kmz)) as z:
        assert sorted(z.namelist()) == ["doc.kml", "image.png"]
        assert "<GroundOverlay>" in z.read("doc.kml").decode()


def test_source_list_job_has_no_kmz(server):
    session = login(server.url)
    path = shared_file(REAL / IMAGE)
    from starnav.detect.read import read_image
    from starnav.pipeline.image import detect_image

    xy = detect_image(read_image(path)).xy[:40] + 0.5
    job = upload_list(server.url, session, xy[:, 0].tolist(), xy[:, 1].tolist(), 1280, 960)
    assert wait_done(server.url, job) == "success"
    assert len(_table(fetch(f"{server.url}/corr_file/{job}"))) >= 10
    for route in (f"kml_file/{job}", "corr_file/99999"):
        with pytest.raises(urllib.error.HTTPError) as err:
            fetch(f"{server.url}/{route}")
        assert err.value.code == 404
