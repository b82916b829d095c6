"""starnav serve in process (Starlette's TestClient, real worker processes): nova's answers,
bad input ending as failed jobs while the server keeps serving, limits, sessions, restart."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")
from PIL import Image
from starlette.testclient import TestClient

from service_helpers import wait_for_job
from shared_data import LYRA, PEER_REFERENCE, as_png, peer_image
from starnav.cli import main as cli_main
from starnav.errors import StarnavError
from starnav.service import nova
from starnav.service.app import ServiceConfig, create_app
from starnav.service.store import INTERRUPTED, JobStore

pytestmark = pytest.mark.service


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("service")
    config = ServiceConfig(data_dir=data / "data", workers=1, max_upload_bytes=3_000_000)
    with TestClient(create_app(config)) as client:
        client.data_dir = data / "data"
        yield client


@pytest.fixture(scope="module")
def lyra_png(tmp_path_factory) -> Path:
    """The Lyra frame (tetra3, 16 bit) as a PNG, made from upstream's TIFF in ../shared/data."""
    return as_png(peer_image(LYRA), tmp_path_factory.mktemp("png"))


def _post(client, path: str, args: dict, **kw) -> dict:
    r = client.post(path, data={"request-json": json.dumps(args)}, **kw)
    assert r.status_code == 200, r.text
    return r.json()


def _session(client) -> str:
    return _post(client, "/api/login", {"apikey": "anything"})["session"]


def _upload(client, data: bytes, name: str = "img.png", **hints) -> int:
    args = {"session": _session(client), **hints}
    r = client.post("/api/upload", data={"request-json": json.dumps(args)},
                    files={"file": (name, data, "application/octet-stream")})  # fmt: skip
    assert r.json()["status"] == "success", r.text
    return r.json()["subid"]


def test_login_and_sessions(server):
    assert _post(server, "/api/login", {}) == {"status": "error", "errormessage": 'need "apikey"'}
    r = server.post("/api/login")
    assert r.json() == {"status": "error", "errormessage": "no json"}
    r = server.post("/api/login", data={"request-json": "{not json"})
    assert r.json()["errormessage"].startswith("failed to parse JSON")
    assert _post(server, "/api/upload", {})["errormessage"] == 'no "session" in JSON.'
    bad = _post(server, "/api/upload", {"session": "nope"})
    assert bad["errormessage"] == 'no session with key "nope"'
    assert _post(server, "/api/upload", {"session": _session(server)})["status"] == "error"


@pytest.mark.slow
def test_image_solved_with_nova_answers(server, lyra_png):
    """A real image: submission, job, calibration, info, annotations and the files, in nova's
    shapes, the centre within 60″ of the peers' reference."""
    job_id = _upload(server, lyra_png.read_bytes(), scale_units="degwidth", scale_lower=10,
                     scale_upper=13)  # fmt: skip
    job = wait_for_job(server, job_id)
    assert job["status"] == "success", job["reason"]
    sub = server.get(f"/api/submissions/{job_id}").json()
    assert sub["jobs"] == [job_id] and sub["job_calibrations"] == [[job_id, job_id]]
    assert sub["processing_finished"] != "None"
    cal = server.get(f"/api/jobs/{job_id}/calibration/").json()  # a trailing slash too
    assert set(cal) == {"ra", "dec", "width_arcsec", "height_arcsec", "radius", "pixscale",
                        "orientation", "parity"}  # fmt: skip
    ref = PEER_REFERENCE[LYRA]
    from astropy.coordinates import angular_separation

    sep = angular_separation(*np.radians([cal["ra"], cal["dec"], ref["ra_deg"], ref["dec_deg"]]))
    assert np.degrees(sep) * 3600 < 60
    # nova reports a PNG's orientation as displayed: (180 - raw) mod 360, raw = roll - 180
    turn = (cal["orientation"] - (360 - ref["roll_deg"]) + 180) % 360 - 180  # either side of 0
    assert turn == pytest.approx(0, abs=0.1)
    info = server.post(f"/api/jobs/{job_id}/info").json()  # POST like client.py
    assert info["status"] == "success" and info["original_filename"] == "img.png"
    assert info["calibration"]["ra"] == cal["ra"]
    anns = server.get(f"/api/jobs/{job_id}/annotations").json()["annotations"]
    assert len(anns) == job["result"]["n_matched"] >= 10
    assert all(a["names"][0].startswith("HIP ") for a in anns)
    for path, magic in (("wcs_file", b"SIMPLE"), ("new_fits_file", b"SIMPLE"),
                        ("annotated_display", b"\x89PNG"), ("json_file", b"{")):  # fmt: skip
        r = server.get(f"/{path}/{job_id}")
        assert r.status_code == 200 and r.content.startswith(magic), path


@pytest.mark.slow
def test_source_list_solved(server):
    from starnav.detect.read import read_image
    from starnav.pipeline.image import detect_image

    xy = detect_image(read_image(peer_image(LYRA))).xy[:30] + 0.5
    args = {"session": _session(server), "x": xy[:, 0].tolist(), "y": xy[:, 1].tolist(),
            "image_width": 1024, "image_height": 768}  # fmt: skip
    job_id = _post(server, "/api/url_upload", args)["subid"]
    job = wait_for_job(server, job_id)
    assert job["status"] == "success", job["reason"]
    assert server.get(f"/new_fits_file/{job_id}").status_code == 404  # no image to write
    assert server.get(f"/wcs_file/{job_id}").status_code == 200


def _png(width: int, height: int) -> bytes:
    buf = io.BytesIO()
    Image.new("1", (width, height)).save(buf, format="PNG")
    return buf.getvalue()


@pytest.mark.parametrize(
    ("data", "hints", "reason"),
    [
        (lambda png: b"this is not an image\n" * 10, {}, "not an image format we read"),
        (lambda png: png[:20000], {}, "cannot read image file"),  # truncated
        (lambda png: _png(20000, 20000), {}, "over the limit of 200 MP"),  # 4e8 px in kBs
        (
            lambda png: png,
            {"scale_units": "furlongs", "scale_lower": 1, "scale_upper": 2},
            "unknown scale units",
        ),
        (lambda png: png, {"parity": 7}, "parity must be"),
        (lambda png: _png(64, 48), {}, "stars detected, at least 4 are needed"),
    ],
    ids=["text", "truncated", "bomb", "units", "parity", "blank"],
)
def test_bad_input_fails_the_job_not_the_server(server, lyra_png, data, hints, reason):
    """``data``: the upload made from the Lyra PNG's bytes."""
    job_id = _upload(server, data(lyra_png.read_bytes()), **hints)
    job = wait_for_job(server, job_id)
    assert job["status"] == "failure"
    assert reason in job["reason"]
    assert server.get("/api/status").json()["status"] == "success"  # still serving


def test_upload_limit_and_names(server):
    r = server.post("/api/upload", data={"request-json": "{}"},
                    files={"file": ("big.fits", b"\0" * 3_100_000)})  # fmt: skip
    assert r.status_code == 413 and "limit of 3 MB" in r.json()["errormessage"]
    job_id = _upload(server, b"junk", name="../../../../tmp/starnav-escape.png")
    wait_for_job(server, job_id)
    assert not Path("/tmp/starnav-escape.png").exists()
    files = {p.name for p in (server.data_dir / "jobs" / str(job_id)).iterdir()}
    assert files == {"input.bin"}  # the service's own name, never the client's
    info = server.get(f"/api/jobs/{job_id}/info").json()
    assert info["original_filename"] == "starnav-escape.png"
    assert server.get("/api/jobs/999999").status_code == 404


def test_store_restart(tmp_path):
    """A restart keeps finished jobs, fails the one that was solving, gives back the queued."""
    store = JobStore(tmp_path)
    done, solving, queued = (store.add_job("xy", "json-xy", {}) for _ in range(3))
    store.start(done)
    store.finish(done, True, "solved", {"ra": 1.0}, {"stars": []})
    store.start(solving)
    store.close()
    again = JobStore(tmp_path)
    assert again.recover() == [queued]
    assert again.get(done).calibration == {"ra": 1.0} and again.get(done).status == "success"
    assert again.get(solving).status == "failure" and again.get(solving).reason == INTERRUPTED
    assert nova.job_status(again.get(queued)) == {"status": "processing"}
    assert nova.submission_status(again.get(queued))["jobs"] == []


def test_nova_hints():
    hints = nova.plate_hints({"scale_units": "arcsecperpix", "scale_type": "ev",
                              "scale_est": 40, "scale_err": 10, "center_ra": 286,
                              "center_dec": 29, "radius": 5, "parity": 1,
                              "downsample_factor": 2, "positional_error": 1.5,
                              "crpix_center": True}, 1024)  # fmt: skip
    assert hints.fov_range_deg == pytest.approx((36 * 1024 / 3600, 44 * 1024 / 3600))
    assert (hints.ra_deg, hints.dec_deg, hints.radius_deg, hints.parity) == (286, 29, 5, 1)
    assert hints.downsample == 2 and hints.positional_error_px == 1.5 and hints.crpix_center
    assert nova.plate_hints({}, 1024).fov_range_deg is None
    bad_hints = [
        ({"scale_lower": 1}, "go together"),
        ({"center_ra": 1}, "go together"),
        ({"downsample_factor": 0}, ">= 1"),
        ({"scale_type": "xx"}, "'ul' or"),
        ({"center_dec": "north", "center_ra": 1}, "must be a number"),
    ]
    for bad, message in bad_hints:
        with pytest.raises(StarnavError, match=message):
            nova.plate_hints(bad, 1024)


def test_serve_refuses_the_network_without_a_key(capsys):
    assert cli_main(["serve", "--host", "0.0.0.0", "--data-dir", "/nonexistent/x"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--api-key" in err


@pytest.mark.slow
def test_jobs_on_a_dask_cluster(tmp_path):
    """--dask: the same jobs on a (local) Dask cluster, bytes in and out."""
    pytest.importorskip("distributed", reason="Dask's distributed is not installed")
    from starnav.detect.read import read_image
    from starnav.pipeline.image import detect_image

    xy = detect_image(read_image(peer_image(LYRA))).xy[:30] + 0.5
    config = ServiceConfig(data_dir=tmp_path, workers=1, dask_address="local")
    with TestClient(create_app(config)) as client:
        args = {"session": _session(client), "x": xy[:, 0].tolist(), "y": xy[:, 1].tolist(),
                "image_width": 1024, "image_height": 768}  # fmt: skip
        job = wait_for_job(client, _post(client, "/api/url_upload", args)["subid"])
        assert job["status"] == "success", job["reason"]
        assert client.get(f"/wcs_file/{job['id']}").status_code == 200
