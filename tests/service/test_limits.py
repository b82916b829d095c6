"""The limits of a job in a real ``starnav serve`` process: the issue's attack files fail their
jobs at once with the size and the limit (checked from the header); a read longer than the
job's time budget gets its worker stopped and replaced while the other worker's job goes on;
a shorter one still counts against the budget; ``--max-pixels-mp`` and ``--max-job-mb`` set
the limits, and a job past its memory fails with the reason."""

from __future__ import annotations

import json
import time

import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")

from bomb_files import gzip_fits, png_claiming, tiff_claiming, zero_png16
from service_helpers import Server, api, login, source_list, upload_image, upload_list, wait_done
from shared_data import LYRA, USER_CACHE_DIR
from starnav.service.processes import GRACE_S

pytestmark = [pytest.mark.service, pytest.mark.slow]

BUDGET_S = 2.0
HINTS = {"scale_units": "degwidth", "scale_type": "ul", "scale_lower": 10, "scale_upper": 13}
REFUSED_WITHIN_S = 30.0  # from the upload, the worker new (imports): a header read


def reason(url: str, job_id: int) -> str:
    return api(url, f"jobs/{job_id}/starnav")["reason"]


def list_job(url: str, session: str) -> int:
    x, y = source_list(LYRA)
    return upload_list(url, session, x, y, 1024, 768, HINTS)


@pytest.fixture(scope="module")
def budget_server(tmp_path_factory):
    data = tmp_path_factory.mktemp("limits")
    server = Server(data / "data", workers=2, cache_dir=USER_CACHE_DIR,
                    options=("--time-budget", str(BUDGET_S))).start()  # fmt: skip
    yield server
    server.stop()


def test_the_attack_files_fail_at_once_with_the_limit(budget_server, tmp_path):
    pytest.importorskip("tifffile", reason="colour TIFFs of over 8 bits are read by tifffile")
    url, session = budget_server.url, login(budget_server.url)
    attacks = {
        "bomb.fits.gz": (gzip_fits(tmp_path / "a.fits.gz", (14000, 14000), -64),
                         "decodes to 1568 MB (14000 x 14000 px, 8 bytes a pixel), over the "
                         "limit of 1200 MB"),
        "deep.png": (png_claiming(tmp_path / "a.png", 30000, 20000),
                     "is 30000 x 20000 px (600 MP), over the limit of 200 MP"),
        "float.tif": (tiff_claiming(tmp_path / "a.tif", 60000, 50000),
                      "is 60000 x 50000 px (3000 MP), over the limit of 200 MP"),
    }  # fmt: skip
    for name, (path, why) in attacks.items():
        t0 = time.monotonic()
        job_id = upload_image(url, session, name, path.read_bytes())
        assert wait_done(url, job_id, timeout_s=REFUSED_WITHIN_S) == "failure"
        assert time.monotonic() - t0 < REFUSED_WITHIN_S
        assert why in reason(url, job_id), name


def test_a_read_past_the_budget_stops_its_worker_not_the_other_job(budget_server, tmp_path):
    # a real 16-bit RGB PNG of 40 MP (240 MB decoded, within the limits), Paeth-filtered, in
    # ~0.3 MB: pypng reads it for far longer than the budget and its grace (~1.3 s a MP)
    slow = zero_png16(tmp_path / "slow.png", 8000, 5000, paeth=True).read_bytes()
    url, session = budget_server.url, login(budget_server.url)
    t0 = time.monotonic()
    stopped = upload_image(url, session, "slow.png", slow)
    beside = list_job(url, session)  # on the other worker, at the same time
    assert wait_done(url, beside) == "success"
    assert wait_done(url, stopped) == "failure"
    took = time.monotonic() - t0
    text = reason(url, stopped)
    assert f"ran past its time budget of {BUDGET_S:g} s (+{GRACE_S:g} s) while reading" in text
    assert "worker process was stopped" in text
    assert took < GRACE_S + 45.0  # the read alone takes minutes on this machine's share
    after = [list_job(url, session) for _ in range(2)]  # the replaced worker solves too
    assert [wait_done(url, j) for j in after] == ["success", "success"]


def test_a_read_within_the_grace_still_counts_against_the_budget(budget_server, tmp_path):
    # 4 MP of Paeth-filtered 16-bit RGB: ~5 s of pypng, past the 2 s budget, within its grace
    png = zero_png16(tmp_path / "long.png", 2000, 2000, paeth=True).read_bytes()
    url = budget_server.url
    job_id = upload_image(url, login(url), "long.png", png)
    assert wait_done(url, job_id) == "failure"
    why = f"time budget spent: the budget of {BUDGET_S:g} s went to reading and detecting"
    assert why in reason(url, job_id)


def test_pixel_and_memory_limits_are_set_by_the_options(tmp_path):
    server = Server(tmp_path / "data", workers=1, cache_dir=USER_CACHE_DIR,
                    options=("--max-pixels-mp", "100", "--max-job-mb", "700")).start()  # fmt: skip
    try:
        url, session = server.url, login(server.url)
        big = gzip_fits(tmp_path / "big.fits.gz", (14000, 14000), 16).read_bytes()
        refused = upload_image(url, session, "big.fits.gz", big)
        assert wait_done(url, refused) == "failure"
        assert "is 14000 x 14000 px (196 MP), over the limit of 100 MP" in reason(url, refused)
        # 90 MP of 16-bit (180 MB): within the pixel limit, not in 700 MB once decoded
        heavy = gzip_fits(tmp_path / "heavy.fits.gz", (9000, 10000), 16).read_bytes()
        failed = upload_image(url, session, "heavy.fits.gz", heavy)
        assert wait_done(url, failed) == "failure"
        text = reason(url, failed)
        assert "needed more than its limit of 700 MB (--max-job-mb)" in text, text
        fine = list_job(url, session)
        assert wait_done(url, fine) == "success"
    finally:
        server.stop()


def test_a_dask_job_past_its_deadline_is_failed_and_cancelled(tmp_path, monkeypatch):
    """On Dask the worker cannot be stopped: past the longest a job may take (its budget, the
    grace and the files' time, here none) the job fails and its future is cancelled."""
    pytest.importorskip("distributed", reason="Dask's distributed is not installed")
    from starlette.testclient import TestClient

    from service_helpers import wait_for_job
    from starnav.service import processes
    from starnav.service.app import ServiceConfig, create_app

    monkeypatch.setattr(processes, "WRITE_S", 0.0)
    slow = zero_png16(tmp_path / "slow.png", 8000, 5000, paeth=True).read_bytes()
    config = ServiceConfig(data_dir=tmp_path / "data", workers=1, dask_address="local",
                           time_budget_s=BUDGET_S)  # fmt: skip
    with TestClient(create_app(config)) as client:
        session = client.post("/api/login", data={"request-json": '{"apikey": "k"}'})
        args = json.dumps({"session": session.json()["session"]})
        t0 = time.monotonic()
        r = client.post("/api/upload", data={"request-json": args},
                        files={"file": ("slow.png", slow)})  # fmt: skip
        job = wait_for_job(client, r.json()["subid"])
        assert job["status"] == "failure"
        why = f"ran past its time budget of {BUDGET_S:g} s (+{GRACE_S:g} s) while running on Dask"
        assert why in job["reason"]
        assert time.monotonic() - t0 < 60.0
