"""``starnav serve`` as a real process for tests and benchmarks: start it on a free loopback
port, wait for it, stop or kill it; nova's calls (form-encoded ``request-json`` with urllib,
multipart uploads with httpx2); and a load runner (``load_jobs``, ``run_load``) of concurrent
clients that check each answer against its input."""

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
import warnings
from dataclasses import dataclass
from pathlib import Path

from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.wcs import WCS, FITSFixedWarning

from shared_data import PEER_REFERENCE as REFERENCE
from shared_data import peer_image
from starnav.service.app import wait_ready

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
    default cache); ``args``: more options of ``starnav serve``; ``env``: more environment."""

    def __init__(
        self, data_dir: Path, *, workers: int = 2, port: int | None = None, cache_dir=None,
        args: tuple[str, ...] = (), env: dict[str, str] | None = None,
    ):  # fmt: skip
        self.data_dir, self.workers, self.cache_dir = Path(data_dir), workers, cache_dir
        self.args, self.env = tuple(args), dict(env or {})
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen | None = None

    def start(self) -> Server:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "starnav.cli", "serve", "--port", str(self.port),
               "--data-dir", str(self.data_dir), "--workers", str(self.workers),
               *self.args]  # fmt: skip
        env = {k: v for k, v in os.environ.items() if k != "STARNAV_CACHE_DIR"} | self.env
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


def centre_offset_arcsec(header: fits.Header, name: str, shift_px=(0.0, 0.0)) -> float:
    """How far the sky at the image centre (0-based pixel ((W-1)/2, (H-1)/2), moved by
    ``shift_px`` for a source list moved so) under the WCS ``header`` is from the peers'
    reference for image ``name`` (tests/data/images/reference.json)."""
    ref = REFERENCE[name]
    x = (ref["file"]["width"] - 1) / 2.0 + shift_px[0]
    y = (ref["file"]["height"] - 1) / 2.0 + shift_px[1]
    with warnings.catch_warnings():  # a .wcs file has NAXIS = 0: astropy says so
        warnings.simplefilter("ignore", FITSFixedWarning)
        ra, dec = WCS(header, naxis=2).all_pix2world([[x, y]], 0)[0]
    got = SkyCoord(ra, dec, unit="deg")
    return float(got.separation(SkyCoord(ref["ra_deg"], ref["dec_deg"], unit="deg")).arcsec)


def upload_image(url: str, session: str, name: str, data: bytes, hints: dict | None = None):
    """nova's ``api/upload``: the file as the multipart field "file"; returns the job id."""
    import httpx2 as httpx

    args = json.dumps({"session": session, **(hints or {})})
    resp = httpx.post(f"{url}/api/upload", data={"request-json": args},
                      files={"file": (name, data)}, timeout=60.0)  # fmt: skip
    return _subid(resp.json())


def upload_list(url: str, session: str, x, y, width: int, height: int, hints=None) -> int:
    """nova's ``api/url_upload`` with a source list (FITS pixels); returns the job id."""
    args = {"session": session, "x": list(x), "y": list(y), "image_width": width,
            "image_height": height, **(hints or {})}  # fmt: skip
    return _subid(api(url, "url_upload", args))


def _subid(answer: dict) -> int:
    if answer.get("status") != "success":
        raise RuntimeError(f"upload refused: {answer}")
    return int(answer["subid"])


def source_list(name: str, max_stars: int = 40) -> tuple[list[float], list[float]]:
    """The brightest stars starnav detects in image ``name``, FITS pixels (1-based)."""
    from starnav.detect import detect_stars, read_image

    xy = detect_stars(read_image(peer_image(name)), max_stars=max_stars).xy + 0.5
    return [float(v) for v in xy[:, 0]], [float(v) for v in xy[:, 1]]


@dataclass(frozen=True)
class LoadJob:
    """One job of a load test: reference image ``image`` (``shared_data.PEER_FILES``)
    uploaded as a file (``x`` None), or its source list ``x``, ``y`` (FITS pixels) moved by
    ``shift_px``."""

    image: str
    x: tuple[float, ...] | None = None
    y: tuple[float, ...] | None = None
    shift_px: tuple[float, float] = (0.0, 0.0)

    @property
    def kind(self) -> str:
        return "image" if self.x is None else "list"


@dataclass(frozen=True)
class LoadOutcome:
    """What a client saw of its job: ``status`` ("success", "failure"; None: lost, with the
    ``error``), ``latency_s`` from the start of the upload to the answer, ``offset_arcsec`` of
    the answer's WCS at the input's centre from the reference, ``stars_from_input`` (every
    identified star is a point of the input list; None for an image), ``worker_ms`` (the
    solve in its worker), ``queued_s`` (the server's time from the upload to the start of
    the solve)."""

    job: LoadJob
    job_id: int | None
    status: str | None
    latency_s: float | None = None
    offset_arcsec: float | None = None
    stars_from_input: bool | None = None
    worker_ms: float | None = None
    queued_s: float | None = None
    error: str | None = None


def load_jobs(n: int, images: list[str], *, kinds=("image", "list"), seed: int = 0,
              max_shift_px: float = 20.0) -> list[LoadJob]:  # fmt: skip
    """``n`` jobs cycling over ``images`` and ``kinds``; each list moved by a random shift of
    up to ``max_shift_px`` in x and y (no two jobs of a list alike)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    lists = {name: source_list(name) for name in images} if "list" in kinds else {}
    jobs = []
    for k in range(n):
        name, kind = images[k % len(images)], kinds[(k // len(images)) % len(kinds)]
        if kind == "image":
            jobs.append(LoadJob(name))
            continue
        dx, dy = (float(v) for v in rng.uniform(-max_shift_px, max_shift_px, 2))
        x, y = lists[name]
        jobs.append(LoadJob(name, tuple(v + dx for v in x), tuple(v + dy for v in y), (dx, dy)))
    return jobs


def run_load(url: str, jobs: list[LoadJob], clients: int, *, poll_s: float = 0.25,
             timeout_s: float = 600.0) -> list[LoadOutcome]:  # fmt: skip
    """``clients`` concurrent clients (threads, each logged in once) submit ``jobs`` and each
    polls its job until answered; then it checks the answer against its input. The outcomes
    in the order of ``jobs``."""
    import concurrent.futures
    import threading

    local = threading.local()
    files = {name: peer_image(name).read_bytes() for name in {j.image for j in jobs}}

    def one(job: LoadJob) -> LoadOutcome:
        job_id = None
        try:
            if not hasattr(local, "session"):
                local.session = login(url)
            ref = REFERENCE[job.image]["file"]
            t0 = time.perf_counter()
            if job.x is None:
                job_id = upload_image(url, local.session, job.image, files[job.image])
            else:
                job_id = upload_list(url, local.session, job.x, job.y, ref["width"],
                                     ref["height"])  # fmt: skip
            status = wait_done(url, job_id, timeout_s, poll_s)
            latency = time.perf_counter() - t0
            return _checked(url, job, job_id, status, latency)
        except Exception as exc:  # a lost job: counted, never raised
            return LoadOutcome(job, job_id, None, error=f"{type(exc).__name__}: {exc}")

    with concurrent.futures.ThreadPoolExecutor(clients) as pool:
        return list(pool.map(one, jobs))


def _checked(url: str, job: LoadJob, job_id: int, status: str, latency: float) -> LoadOutcome:
    record = api(url, f"jobs/{job_id}/starnav")
    result = record["result"] or {}
    times = {"worker_ms": result.get("worker_ms"),
             "queued_s": record["started"] - record["submitted"]}  # fmt: skip
    if status != "success":
        return LoadOutcome(job, job_id, status, latency, **times)
    header = fits.Header.fromstring(fetch(f"{url}/wcs_file/{job_id}").decode("latin-1"))
    offset = centre_offset_arcsec(header, job.image, shift_px=job.shift_px)
    from_input = None
    if job.x is not None:
        points = {(round(x, 6), round(y, 6)) for x, y in zip(job.x, job.y, strict=True)}
        from_input = all((round(s["x"] + 0.5, 6), round(s["y"] + 0.5, 6)) in points
                         for s in result["stars"])  # fmt: skip
    return LoadOutcome(job, job_id, status, latency, offset, from_input, **times)


JOB_WAIT_S = 180.0  # a fresh worker process loads the catalog and tables first


def wait_for_job(client, job_id: int, wait_s: float = JOB_WAIT_S) -> dict:
    """A job's starnav answer once nova's status is success or failure (``client``: a
    Starlette TestClient or anything with ``get``); AssertionError after ``wait_s``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < wait_s:
        if client.get(f"/api/jobs/{job_id}").json()["status"] in ("success", "failure"):
            return client.get(f"/api/jobs/{job_id}/starnav").json()
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} did not finish in {wait_s} s")
