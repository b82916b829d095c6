"""A real ``starnav serve`` process killed (SIGKILL, server and workers at once) while a job
is solving, then started again on the same --data-dir: finished jobs keep their answers and
files, the interrupted job fails as "interrupted", the queued ones run."""

from __future__ import annotations

import time

import pytest
from astropy.io import fits

from service_helpers import (
    Server,
    api,
    centre_offset_arcsec,
    fetch,
    login,
    source_list,
    upload_image,
    upload_list,
    wait_done,
)
from shared_data import CYGNUS, LYRA, USER_CACHE_DIR, peer_image

pytestmark = [pytest.mark.service, pytest.mark.slow]


def wait_solving(url: str, job_id: int, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while api(url, f"jobs/{job_id}")["status"] != "solving":
        assert time.monotonic() < deadline, f"job {job_id} never started"
        time.sleep(0.02)


def test_a_killed_server_restarts_with_its_jobs(tmp_path):
    # one worker: the job killed is the only one solving, the others wait in the queue
    server = Server(tmp_path / "data", workers=1, cache_dir=USER_CACHE_DIR).start()
    try:
        session = login(server.url)
        done = upload_image(server.url, session, LYRA, peer_image(LYRA).read_bytes())
        assert wait_done(server.url, done) == "success"
        calibration = api(server.url, f"jobs/{done}/calibration")
        # the slowest of the images to solve: the one killed
        killed = upload_image(server.url, session, CYGNUS, peer_image(CYGNUS).read_bytes())
        x, y = source_list(LYRA)
        queued = [upload_list(server.url, session, x, y, 1024, 768) for _ in range(2)]
        wait_solving(server.url, killed)
        server.kill()

        server.start()
        assert api(server.url, f"jobs/{done}")["status"] == "success"
        assert api(server.url, f"jobs/{done}/calibration") == calibration
        header = fits.Header.fromstring(fetch(f"{server.url}/wcs_file/{done}").decode("latin-1"))
        assert centre_offset_arcsec(header, LYRA) < 60.0
        with fits.open(server.data_dir / "jobs" / str(done) / "new.fits") as hdul:
            assert hdul[0].data.shape == (768, 1024)
        assert fetch(f"{server.url}/annotated_display/{done}").startswith(b"\x89PNG")

        interrupted = api(server.url, f"jobs/{killed}/starnav")
        assert interrupted["status"] == "failure"
        assert interrupted["reason"].startswith("interrupted")
        assert api(server.url, f"jobs/{killed}")["status"] == "failure"

        for job_id in queued:
            assert wait_done(server.url, job_id) == "success"
        assert login(server.url)  # the sessions table survived too
    finally:
        server.kill()
