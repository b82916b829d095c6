"""Real nova clients against a real ``starnav serve`` process: astroquery's ``AstrometryNet``
and astrometry.net's own ``client.py`` (vendored in tests/vendor/astrometry_net), on the real
images of tests/data/images and a FITS made from one of them. Every answer's WCS must put the
image centre within 60″ of the peers' reference (tests/data/images/README.md)."""

from __future__ import annotations

import functools
import http.server
import json
import os
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits
from astropy.utils.exceptions import AstropyDeprecationWarning

from service_helpers import (
    IMAGES,
    REFERENCE,
    SOLVE_TIMEOUT_S,
    centre_offset_arcsec,
    source_list,
)
from starnav.detect import read_image
from starnav.service.store import JobStore

pytest.importorskip("astroquery")
from astroquery.astrometry_net import AstrometryNetClass

CLIENT_PY = Path(__file__).resolve().parent / "vendor" / "astrometry_net" / "client.py"
LYRA = "tetra3_2019-07-29T204726_Alt60_Azi135_Try1.png"
CYGNUS = "granasat_cisne_02sec.jpg"
TOLERANCE_ARCSEC = 60.0


@pytest.fixture(scope="module")
def astroquery_client(nova_server):
    """astroquery's client pointed at the local server (any API key logs in on loopback)."""
    client = AstrometryNetClass()
    client.URL = nova_server.url
    client.API_URL = nova_server.url + "/api"
    client.TIMEOUT = SOLVE_TIMEOUT_S
    client.api_key = "any key"
    return client


@pytest.fixture(scope="module")
def lyra_fits(tmp_path_factory) -> Path:
    """The Lyra PNG's pixels as a FITS file, unchanged (row 0 is FITS y = 1)."""
    path = tmp_path_factory.mktemp("fits") / "lyra.fits"
    fits.PrimaryHDU(read_image(IMAGES / LYRA)).writeto(path)
    return path


def reference_pixscale_arcsec(name: str) -> float:
    ref = REFERENCE[name]
    return ref["fov_deg"] * 3600.0 / ref["file"]["width"]


def solve_upload(client, path: Path, **settings) -> fits.Header:
    with warnings.catch_warnings():  # astroquery deprecates force_image_upload (kept working)
        warnings.simplefilter("ignore", AstropyDeprecationWarning)
        return client.solve_from_image(
            str(path), force_image_upload=True, verbose=False, solve_timeout=SOLVE_TIMEOUT_S,
            **settings,
        )  # fmt: skip


@pytest.mark.parametrize("name", [LYRA, CYGNUS])
def test_astroquery_uploads_an_image(astroquery_client, name):
    header = solve_upload(astroquery_client, IMAGES / name)
    assert header, f"{name}: astroquery got no WCS (the job failed)"
    assert centre_offset_arcsec(header, name) < TOLERANCE_ARCSEC


def test_astroquery_uploads_a_fits_file(astroquery_client, lyra_fits):
    header = solve_upload(astroquery_client, lyra_fits)
    assert header
    assert centre_offset_arcsec(header, LYRA) < TOLERANCE_ARCSEC


def hints(kind: str, name: str) -> dict:
    """astroquery settings of image ``name``: its scale (±10 %), a position 2.2° off with a 5°
    radius, or both."""
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


@pytest.mark.parametrize("kind", ["scale", "estimate", "position", "both"])
def test_astroquery_with_scale_and_position_hints(astroquery_client, kind):
    header = solve_upload(astroquery_client, IMAGES / CYGNUS, **hints(kind, CYGNUS))
    assert header
    assert centre_offset_arcsec(header, CYGNUS) < TOLERANCE_ARCSEC
    assert header["IMAGEW"] == REFERENCE[CYGNUS]["file"]["width"]


def test_astroquery_scale_hint_is_followed(astroquery_client, nova_server):
    """A scale twice the true one: the field is searched at that scale only, and not solved;
    the job stored nova's fields as astroquery sent them."""
    wrong = {k: 2.0 * v if k.startswith("scale_") and k != "scale_units" else v
             for k, v in hints("scale", CYGNUS).items() if k != "scale_type"}  # fmt: skip
    header, job_id = solve_upload(astroquery_client, IMAGES / CYGNUS, scale_type="ul",
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


# --- astrometry.net's client.py, as a user runs it -------------------------------------------


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def image_host():
    """tests/data/images over HTTP on another loopback port (for --urlupload)."""
    handler = functools.partial(_QuietHandler, directory=str(IMAGES))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


FITS_TABLE_SHIM = '''"""astrometry.util.fits.fits_table, the part client.py's --upload-xy uses."""
from astropy.table import Table


class fits_table:
    def __init__(self, path):
        table = Table.read(path)
        self.x, self.y = list(table["x"]), list(table["y"])
'''


def _xy_table(folder: Path, name: str) -> tuple[Path, Path]:
    """A FITS table of image ``name``'s source list (columns x, y) and a folder holding the
    module ``astrometry.util.fits`` that client.py's --upload-xy imports to read it."""
    from astropy.table import Table

    x, y = source_list(name)
    table = folder / "sources.xyls"
    Table({"x": x, "y": y}).write(table, format="fits")
    pkg = folder / "shim" / "astrometry" / "util"
    pkg.mkdir(parents=True)
    for init in (pkg.parent / "__init__.py", pkg / "__init__.py"):
        init.write_text("")
    (pkg / "fits.py").write_text(FITS_TABLE_SHIM)
    return table, folder / "shim"


@pytest.fixture(scope="module")
def client_runs(nova_server, image_host, tmp_path_factory):
    """client.py runs started together (each polls every 5 s): by label, the process, its
    output folder and the image its answer is checked against."""
    runs = {}
    api = nova_server.url + "/api/"

    def start(label: str, name: str, args: list[str], pythonpath: Path | None = None):
        out = tmp_path_factory.mktemp(label)
        env = dict(os.environ)
        if pythonpath is not None:
            env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
        cmd = [sys.executable, str(CLIENT_PY), "--server", api, "--apikey", "k", *args, "--wait",
               "--wcs", str(out / "out.wcs"), "--annotate", str(out / "ann.json")]  # fmt: skip
        if "--upload" in args or "--urlupload" in args:
            cmd += ["--newfits", str(out / "out.new")]
        proc = subprocess.Popen(cmd, cwd=out, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)  # fmt: skip
        runs[label] = (proc, out, name)

    start("upload", LYRA, ["--upload", str(IMAGES / LYRA)])
    start("urlupload", CYGNUS, ["--urlupload", f"{image_host}/{CYGNUS}"])
    table, shim = _xy_table(tmp_path_factory.mktemp("xy"), LYRA)
    start("upload_xy", LYRA, ["--upload-xy", str(table)], pythonpath=shim)
    yield runs
    for proc, _, _ in runs.values():
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def finished_run(client_runs, label: str, returncode: int = 0) -> tuple[Path, str, str]:
    """The output folder, image name and printed text of a client.py run that has ended with
    ``returncode``."""
    proc, out, name = client_runs[label]
    try:
        printed, _ = proc.communicate(timeout=SOLVE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        printed, _ = proc.communicate()
    assert proc.returncode == returncode, f"client.py {label}:\n{printed[-3000:]}"
    return out, name, printed


def check_wcs_and_annotations(out: Path, name: str) -> list[dict]:
    header = fits.getheader(out / "out.wcs")
    assert centre_offset_arcsec(header, name) < TOLERANCE_ARCSEC
    annotations = json.loads((out / "ann.json").read_text())["annotations"]
    assert len(annotations) >= 10
    ref = REFERENCE[name]["file"]
    for a in annotations:
        assert a["names"][0].startswith("HIP ")
        assert 0.5 <= a["pixelx"] <= ref["width"] + 0.5
        assert 0.5 <= a["pixely"] <= ref["height"] + 0.5
    return annotations


def check_new_fits(out: Path, name: str) -> None:
    with fits.open(out / "out.new") as hdul:
        data, header = hdul[0].data, hdul[0].header
    pixels = read_image(IMAGES / name)
    assert data.shape == pixels.shape
    assert np.array_equal(data, pixels)
    assert centre_offset_arcsec(header, name) < TOLERANCE_ARCSEC


def test_client_py_upload(client_runs):
    out, name, _ = finished_run(client_runs, "upload")
    check_wcs_and_annotations(out, name)
    check_new_fits(out, name)


def test_client_py_urlupload(client_runs):
    out, name, _ = finished_run(client_runs, "urlupload")
    annotations = check_wcs_and_annotations(out, name)
    check_new_fits(out, name)
    names = {n for a in annotations for n in a["names"]}
    assert "Fawaris" in names  # delta Cygni, 4.7° from the centre, by its IAU name


def test_client_py_upload_xy(client_runs):
    """--upload-xy sends the list without the image size (client.py drops --image-width); the
    server then takes the list's extent, as nova does."""
    out, name, _ = finished_run(client_runs, "upload_xy")
    check_wcs_and_annotations(out, name)
