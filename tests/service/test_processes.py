"""Nothing of a ``starnav serve`` run stays alive after it is stopped: SIGTERM, SIGINT (clean
stops) and SIGKILL (the workers see their parent die) of the server process alone, while a
worker is busy with a slow job, leave no process of that run (found by a marker in their
environment: the server's children inherit it) within a few seconds."""

from __future__ import annotations

import os
import signal
import time
import uuid
from pathlib import Path

import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")

from bomb_files import zero_png16
from service_helpers import Server, api, login, upload_image
from shared_data import USER_CACHE_DIR

pytestmark = [pytest.mark.service, pytest.mark.slow]

GONE_WITHIN_S = 10.0  # a clean stop, or the kernel's signal to the workers and the tracker


def processes_marked(marker: str) -> list[str]:
    """The pid and command line of every process whose environment holds ``marker``."""
    found = []
    needle = f"STARNAV_TEST_RUN={marker}".encode()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if needle in (entry / "environ").read_bytes().split(b"\0"):
                cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
                found.append(f"{entry.name}: {cmd[:120]}")
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return found


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs Linux's /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL],
                         ids=["SIGTERM", "SIGINT", "SIGKILL"])  # fmt: skip
def test_no_process_of_a_stopped_server_remains(tmp_path, sig):
    marker = uuid.uuid4().hex
    server = Server(tmp_path / "data", workers=2, cache_dir=USER_CACHE_DIR,
                    options=("--time-budget", "none"),
                    env={"STARNAV_TEST_RUN": marker})  # fmt: skip
    server.start()
    try:
        slow = zero_png16(tmp_path / "slow.png", 8000, 5000, paeth=True).read_bytes()  # ~1 min
        job_id = upload_image(server.url, login(server.url), "slow.png", slow)
        deadline = time.monotonic() + 60.0
        while api(server.url, f"jobs/{job_id}")["status"] != "solving":
            assert time.monotonic() < deadline, "the job never started"
            time.sleep(0.1)
        time.sleep(1.0)  # into the read
        running = processes_marked(marker)
        # the server, its resource tracker and two workers
        assert len(running) >= 4, running
        server.proc.send_signal(sig)  # the server alone, not its process group
        server.proc.wait(30)
        server.proc = None
        deadline = time.monotonic() + GONE_WITHIN_S
        while (left := processes_marked(marker)) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert left == [], f"left after {sig.name}: {left}"
    finally:
        for line in processes_marked(marker):  # never leave them to the next test
            os.kill(int(line.split(":")[0]), signal.SIGKILL)
        if server.proc is not None:
            server.kill()
