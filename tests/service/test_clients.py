"""Real nova clients installed from PyPI, against a real ``starnav serve`` process on the
loopback: astroquery's ``AstrometryNet`` and astrometry-net-client (``astrometry_net_client``),
on the real images of tests/data/images/reference.json (read from ../shared/data) and a FITS
made from one of them. Every answer's WCS must put the image centre within 60″ of the peers'
reference (tests/data/images/README.md).

Neither client has a setting for its server. astroquery builds every URL from the instance's
``URL`` and ``API_URL`` (``url_helpers.join``); astrometry-net-client from string constants
and class attributes that begin ``http://nova.astrometry.net`` (``config.BASE_URL`` and the
login and upload URLs bound from it at import, ``Submission.url``, ``Job.url`` and Job's file
URLs), which ``anc_local`` rewrites to the local server, checking that none is left."""

from __future__ import annotations

import functools
import http.server
import importlib
import pkgutil
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits
from astropy.utils.exceptions import AstropyDeprecationWarning

from service_helpers import SOLVE_TIMEOUT_S, centre_offset_arcsec, source_list
from shared_data import CYGNUS, LYRA, PEER_FILES, peer_image
from shared_data import PEER_REFERENCE as REFERENCE
from starnav.detect import read_image
from starnav.service.store import JobStore

pytest.importorskip("astroquery", reason="astroquery is not installed: pip install '.[dev]'")
anc = pytest.importorskip(
    "astrometry_net_client", reason="astrometry-net-client is not installed: pip install '.[dev]'"
)

pytestmark = [pytest.mark.service, pytest.mark.slow]  # a server process, 15 s in all

TOLERANCE_ARCSEC = 60.0
NOVA = "http://nova.astrometry.net"


@pytest.fixture(scope="module")
def lyra_fits(tmp_path_factory) -> Path:
    """The Lyra frame's pixels as a FITS file, unchanged (row 0 is FITS y = 1)."""
    path = tmp_path_factory.mktemp("fits") / "lyra.fits"
    fits.PrimaryHDU(read_image(peer_image(LYRA))).writeto(path)
    return path


def reference_pixscale_arcsec(name: str) -> float:
    ref = REFERENCE[name]
    return ref["fov_deg"] * 3600.0 / ref["file"]["width"]


def hints(kind: str, name: str) -> dict:
    """nova settings of image ``name``: its scale (±10 %), a scale estimate, a position 2.2°
    off with a 5° radius, or scale and position."""
    ref = REFERENCE[name]
    scale = reference_pixscale_arcsec(name)
    out = {}
    if kind in ("scale", "both"):
        out.update(scale_units="arcsecperpix", scale_type="ul", scale_lower=0.9 * scale,
                   scale_upper=1.1 * scale)  # fmt: skip
    if kind == "estimate":
        out.update(scale_units="degwidth", scale_type="ev", scale_est=ref["fov_deg"],
                   scale_err=10.0)  # fmt: skip
    if kind in ("position", "both"):
        out.update(center_ra=ref["ra_deg"] + 2.0, center_dec=ref["dec_deg"] - 1.0, radius=5.0)
    return out


# --- astroquery's AstrometryNet ----------------------------------------------------------


@pytest.fixture(scope="module")
def astroquery_client(nova_server):
    """astroquery's client pointed at the local server (any API key logs in on loopback),
    its response cache off: job numbers restart at 1 with every fresh server, so a cached
    ``wcs_file/1`` of an earlier session on the same port would be another image's WCS."""
    from astroquery import cache_conf
    from astroquery.astrometry_net import AstrometryNetClass

    client = AstrometryNetClass()
    client.URL = nova_server.url
    client.API_URL = nova_server.url + "/api"
    client.TIMEOUT = SOLVE_TIMEOUT_S
    client.api_key = "any key"
    with cache_conf.set_temp("cache_active", False):
        yield client


def solve_upload(client, path: Path, **settings) -> fits.Header:
    with warnings.catch_warnings():  # astroquery deprecates force_image_upload (kept working)
        warnings.simplefilter("ignore", AstropyDeprecationWarning)
        return client.solve_from_image(
            str(path), force_image_upload=True, verbose=False, solve_timeout=SOLVE_TIMEOUT_S,
            **settings,
        )  # fmt: skip


@pytest.mark.parametrize("name", [LYRA, CYGNUS])
def test_astroquery_uploads_an_image(astroquery_client, name):
    header = solve_upload(astroquery_client, peer_image(name))
    assert header, f"{name}: astroquery got no WCS (the job failed)"
    assert centre_offset_arcsec(header, name) < TOLERANCE_ARCSEC


def test_astroquery_uploads_a_fits_file(astroquery_client, lyra_fits):
    header = solve_upload(astroquery_client, lyra_fits)
    assert header
    assert centre_offset_arcsec(header, LYRA) < TOLERANCE_ARCSEC


@pytest.mark.parametrize("kind", ["scale", "estimate", "position", "both"])
def test_astroquery_with_scale_and_position_hints(astroquery_client, kind):
    header = solve_upload(astroquery_client, peer_image(CYGNUS), **hints(kind, CYGNUS))
    assert header
    assert centre_offset_arcsec(header, CYGNUS) < TOLERANCE_ARCSEC
    assert header["IMAGEW"] == REFERENCE[CYGNUS]["file"]["width"]


def test_astroquery_scale_hint_is_followed(astroquery_client, nova_server):
    """A scale twice the true one: the field is searched at that scale only, and not solved;
    the job stored nova's fields as astroquery sent them."""
    wrong = {k: 2.0 * v if k.startswith("scale_") and k != "scale_units" else v
             for k, v in hints("scale", CYGNUS).items() if k != "scale_type"}  # fmt: skip
    header, job_id = solve_upload(astroquery_client, peer_image(CYGNUS), scale_type="ul",
                                  return_submission_id=True, **wrong)  # fmt: skip
    assert header == {}
    store = JobStore(nova_server.data_dir)
    stored = store.get(int(job_id))
    store.close()
    assert stored.status == "failure"
    assert not stored.reason.startswith("error"), stored.reason  # not solved, no mistake
    assert {k: stored.request[k] for k in wrong} == wrong


@pytest.mark.parametrize("name", [LYRA, CYGNUS])
def test_astroquery_solves_a_source_list(astroquery_client, name):
    x, y = source_list(name)
    ref = REFERENCE[name]["file"]
    header = astroquery_client.solve_from_source_list(
        x, y, ref["width"], ref["height"], verbose=False, solve_timeout=SOLVE_TIMEOUT_S,
        **hints("scale", name),
    )  # fmt: skip
    assert header
    assert centre_offset_arcsec(header, name) < TOLERANCE_ARCSEC


# --- astrometry-net-client ----------------------------------------------------------------

# astrometry-net-client reads an answer as JSON only when its Content-Type is text/plain, as
# nova serves it (astrometry.net's net/api.py: json_type = 'text/plain'), and so does
# starnav serve (service.app.NovaJSON).


def _anc_objects():
    """(owner, attribute, value) of every string of astrometry-net-client's modules and
    classes that names nova."""
    for info in pkgutil.walk_packages(anc.__path__, anc.__name__ + "."):
        if info.name.endswith(".scripts") or ".scripts." in info.name:
            continue  # the command-line script: not imported by the library
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, str) and NOVA in value:
                yield module, name, value
            elif isinstance(value, type) and value.__module__ == module.__name__:
                for attr, v in vars(value).items():
                    if isinstance(v, str) and NOVA in v:
                        yield value, attr, v


@pytest.fixture(scope="module")
def anc_local(nova_server):
    """astrometry-net-client's URLs moved from nova to the local server for this module."""
    mp = pytest.MonkeyPatch()
    found = list(_anc_objects())
    assert found, "astrometry-net-client names no nova URL: its URLs moved, read its source"
    for owner, name, value in found:
        mp.setattr(owner, name, value.replace(NOVA, nova_server.url))
    assert not list(_anc_objects())  # nothing left that would reach the real nova
    yield nova_server
    mp.undo()


def _until_done(statusable) -> None:
    """Wait as the client's own ``until_done`` does, polling every 0.25-1 s (its default
    starts at 4 s)."""
    statusable.until_done(start=0.25, end=1, timeout=SOLVE_TIMEOUT_S)


def anc_solve(upload):
    """Submit an upload, wait for its submission and then its job; the job."""
    submission = upload.submit()
    _until_done(submission)
    job = submission.jobs[0]
    _until_done(job)
    return job


def test_anc_file_upload_with_hints(anc_local):
    """``FileUpload`` with scale and position settings: the job's WCS, its info (nova's
    calibration, the star names in the field) and the new FITS (the image's pixels with the
    WCS)."""
    from astrometry_net_client import FileUpload, Session, Settings

    settings = Settings(hints("both", CYGNUS))
    job = anc_solve(FileUpload(str(peer_image(CYGNUS)), session=Session("k"), settings=settings))
    assert job.success(), job.info()
    assert centre_offset_arcsec(job.wcs_file(), CYGNUS) < TOLERANCE_ARCSEC
    info = job.info()
    assert info["original_filename"] == CYGNUS
    ref = REFERENCE[CYGNUS]
    half = np.radians(ref["fov_deg"]) / 2.0  # nova's pixscale: the scale at the centre
    centre_scale = np.degrees(2.0 * np.tan(half) / ref["file"]["width"]) * 3600.0
    assert job.calibration["pixscale"] == pytest.approx(centre_scale, rel=0.01)
    assert abs(job.calibration["dec"] - ref["dec_deg"]) < TOLERANCE_ARCSEC / 3600
    assert "Fawaris" in info["objects_in_field"]  # delta Cygni, 4.7° from the centre
    with job.new_fits_file() as hdul:
        assert np.array_equal(hdul[0].data, read_image(peer_image(CYGNUS)))
        assert centre_offset_arcsec(hdul[0].header, CYGNUS) < TOLERANCE_ARCSEC


@pytest.fixture(scope="module")
def image_host():
    """The folder of the Cygnus JPEG (../shared/data/images) over HTTP on another loopback
    port, for a URL upload."""
    folder = peer_image(CYGNUS).parent
    handler = functools.partial(_QuietHandler, directory=str(folder))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def test_anc_url_upload(anc_local, image_host):
    """``URLUpload``: the server fetches the image from the URL given, then solves it."""
    from astrometry_net_client import Session
    from astrometry_net_client.uploads import URLUpload

    url = f"{image_host}/{PEER_FILES[CYGNUS].name}"
    job = anc_solve(URLUpload(url, session=Session("k")))
    assert job.success(), job.info()
    assert centre_offset_arcsec(job.wcs_file(), CYGNUS) < TOLERANCE_ARCSEC


def test_anc_client_calibrates_an_image(anc_local):
    """The high-level ``Client``: log in, upload, wait (its own polling: from 4 s, doubling),
    the WCS header."""
    from astrometry_net_client import Client

    client = Client(api_key="any key")
    header = client.calibrate_file_wcs(str(peer_image(LYRA)))
    assert header is not None, "astrometry-net-client: the job failed"
    assert centre_offset_arcsec(header, LYRA) < TOLERANCE_ARCSEC
