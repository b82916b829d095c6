"""``starnav serve`` as a real process for tests and benchmarks: start it on a free loopback
port, wait for it, talk to it with the standard library (nova's form-encoded ``request-json``),
stop or kill it."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from pathlib import Path

from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.wcs import WCS

from starnav.service.app import wait_ready

IMAGES = Path(__file__).resolve().parent / "data" / "images"
REFERENCE = json.loads((IMAGES / "reference.json").read_text())["images"]
START_TIMEOUT_S = 60.0  # imports of a cold process on a shared machine
SOLVE_TIMEOUT_S = 120.0  # the first solve of a fresh server loads (or builds) the tables


def free_port() -> int:
    """A TCP port free on the loopback just now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """One ``starnav serve`` process (``workers`` worker processes, jobs under ``data_dir``);
    its output goes to ``data_dir/server.log``. ``start`` again after ``stop`` or ``kill`` to
    restart it on the same data dir and port. ``cache_dir``: its STARNAV_CACHE_DIR (None: the
    default cache)."""

    def __init__(
        self, data_dir: Path, *, workers: int = 2, port: int | None = None, cache_dir=None
    ):
        self.data_dir, self.workers, self.cache_dir = Path(data_dir), workers, cache_dir
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen | None = None

    def start(self) -> Server:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "starnav.cli", "serve", "--port", str(self.port),
               "--data-dir", str(self.data_dir), "--workers", str(self.workers)]  # fmt: skip
        env = {k: v for k, v in os.environ.items() if k != "STARNAV_CACHE_DIR"}
        if self.cache_dir is not None:
            env["STARNAV_CACHE_DIR"] = str(self.cache_dir)
        log = (self.data_dir / "server.log").open("ab")
        # its own process group: a kill reaches the worker processes too
        self.proc = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )
        log.close()
        try:
            wait_ready(self.url, timeout_s=START_TIMEOUT_S)
        except OSError:
            self.kill()
            raise RuntimeError(f"starnav serve did not start: {self.log()[-2000:]}") from None
        return self

    def log(self) -> str:
        return (self.data_dir / "server.log").read_text(errors="replace")

    def stop(self) -> None:
        """SIGINT (uvicorn's clean shutdown), then SIGKILL if it takes over 20 s."""
        if self.proc is None:
            return
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.kill()
        self.proc = None

    def kill(self) -> None:
        """SIGKILL the server and its workers at once (a crash, a power cut)."""
        if self.proc is None:
            return
        os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()
        self.proc = None


def api(url: str, service: str, args: dict | None = None, timeout_s: float = 30.0) -> dict:
    """POST nova's ``request-json`` form to ``url/api/service`` (no args: a GET)."""
    data = None
    if args is not None:
        data = urllib.parse.urlencode({"request-json": json.dumps(args)}).encode()
    with urllib.request.urlopen(f"{url}/api/{service}", data, timeout=timeout_s) as resp:
        return json.loads(resp.read())


def login(url: str) -> str:
    return api(url, "login", {"apikey": "any key"})["session"]


def wait_done(url: str, job_id: int, timeout_s: float = SOLVE_TIMEOUT_S, poll_s=0.2) -> str:
    """Poll ``api/jobs/N`` until it is "success" or "failure"; returns that."""
    deadline = time.monotonic() + timeout_s
    while True:
        status = api(url, f"jobs/{job_id}")["status"]
        if status in ("success", "failure"):
            return status
        if time.monotonic() > deadline:
            raise TimeoutError(f"job {job_id} still {status!r} after {timeout_s:g} s")
        time.sleep(poll_s)


def fetch(url: str, timeout_s: float = 30.0) -> bytes:
    with urllib.request.urlopen(url, timeout=timeout_s) as resp:
        return resp.read()


def centre_offset_arcsec(header: fits.Header, name: str) -> float:
    """How far the sky at the image centre (0-based pixel ((W-1)/2, (H-1)/2)) under the WCS
    ``header`` is from the peers' reference for image ``name`` (tests/data/images)."""
    ref = REFERENCE[name]
    w, h = ref["file"]["width"], ref["file"]["height"]
    ra, dec = WCS(header, naxis=2).all_pix2world([[(w - 1) / 2.0, (h - 1) / 2.0]], 0)[0]
    got = SkyCoord(ra, dec, unit="deg")
    return float(got.separation(SkyCoord(ref["ra_deg"], ref["dec_deg"], unit="deg")).arcsec)
