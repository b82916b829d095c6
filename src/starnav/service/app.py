"""The HTTP service: astrometry.net's nova API on Starlette, jobs run by a pool of workers.

Routes (GET and POST alike, with or without a trailing slash, as nova's ``net/urls.py``):
``api/login``, ``api/upload`` (multipart: ``request-json`` and ``file``), ``api/url_upload``
(a ``url``, or ``x``/``y`` with ``image_width``/``image_height``), ``api/submissions/N``,
``api/myjobs``, ``api/jobs/N`` and its ``calibration``, ``info``, ``annotations``, ``tags``,
``machine_tags``, ``objects_in_field``; ``wcs_file/N``, ``new_fits_file/N``,
``corr_file/N``, ``rdls_file/N``, ``axy_file/N``, ``kml_file/N`` (solve-field's side files,
``starnav.output.sidefiles``; the KMZ for images only), ``annotated_display/N`` and
``annotated_full/N``. starnav's own: ``api/jobs/N/starnav`` (the
whole solution: uncertainties, every star), ``json_file/N`` (the same as a download),
``api/status`` (queue and workers), and the web page at ``/``.

A request's JSON comes as nova's clients send it: the form field ``request-json`` (URL-encoded
or multipart body, or the query string). Errors are nova's ``{"status": "error",
"errormessage": ...}`` (``service.errors``: with which HTTP status). Uploads need a session
from ``api/login``; with ``api_key`` set, the login needs that key, and a job uploaded with
``publicly_visible`` "n" is read only with its session (``service.privacy``). A body over
``max_upload_bytes`` is refused (413) before it is read.
Files are stored under the data dir by job number with the service's own names.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from starnav.runtime.limits import (
    DEFAULT_MAX_QUEUED,
    DEFAULT_MAX_UPLOAD_MB,
    DEFAULT_URL_DEADLINE_S,
    DEFAULT_URL_FETCHES,
    DEFAULT_WORKER_MEMORY_MB,
    MAX_PIXELS,
)
from starnav.runtime.pools import dask_client, one_blas_thread
from starnav.service import nova, privacy
from starnav.service.errors import (
    EXCEPTION_HANDLERS,
    NovaJSON,
    RequestError,
    echo,
    error,
    parse_request_json,
)
from starnav.service.fetch import (
    AllowedHosts,
    FetchBusy,
    FetchError,
    FetchPolicy,
    FetchQueue,
)
from starnav.service.files import clean_job_tmp
from starnav.service.processes import GRACE_S, Limits, WorkerProcess, failed_answer
from starnav.service.store import JobStore
from starnav.service.worker import OUTPUTS, input_name, run_job

STATIC_DIR = Path(__file__).parent / "static"
# python-multipart logs each body it refuses; astrometry.net's client.py sends one on every
# upload, which _lenient_multipart then reads: not worth a warning per upload
logging.getLogger("python_multipart").setLevel(logging.ERROR)
RETRY_AFTER_S = 5
RESULT_FILE = "result.json"


@dataclass(frozen=True)
class ServiceConfig:
    """How the service runs: ``data_dir`` (SQLite file and job directories), ``workers``
    (processes solving at once; with ``dask_address``, jobs at once on that cluster),
    ``api_key`` (None: any key logs in), ``max_upload_bytes``, ``time_budget_s`` per job
    (None: starnav's defaults; reading and detecting count), ``max_pixels`` of an image,
    ``max_job_bytes`` of a worker process's memory (None: no limit); ``max_queued`` jobs
    waiting for a worker before uploads are answered 503 "busy"; URL uploads
    (``starnav.service.fetch``): ``url_deadline_s`` for a whole fetch, ``url_fetches`` at
    once, from public hosts and those ``allow_url_hosts``."""

    data_dir: Path
    workers: int = 1
    api_key: str | None = None
    max_upload_bytes: int = int(DEFAULT_MAX_UPLOAD_MB * 1e6)
    time_budget_s: float | None = None
    dask_address: str | None = None
    max_queued: int = DEFAULT_MAX_QUEUED
    url_deadline_s: float = DEFAULT_URL_DEADLINE_S
    url_fetches: int = DEFAULT_URL_FETCHES
    allow_url_hosts: AllowedHosts = field(default_factory=AllowedHosts)
    max_pixels: int = MAX_PIXELS
    max_job_bytes: int | None = int(DEFAULT_WORKER_MEMORY_MB * 1e6)

    @property
    def limits(self) -> Limits:
        """A job's limits (``starnav.service.processes``)."""
        return Limits(self.time_budget_s, self.max_pixels, self.max_job_bytes)


class Jobs:
    """The queue: each job waits for a free worker, is marked solving, runs (``run_job``) in
    a worker process (``starnav.service.processes``: stopped and replaced past the job's
    deadline) or on the Dask cluster (cancelled past it), and its answer and files are
    stored."""

    def __init__(self, config: ServiceConfig, store: JobStore):
        self.config, self.store = config, store
        self._slots = asyncio.Semaphore(config.workers)
        self._tasks: set[asyncio.Task] = set()
        self._dask = None
        self._stack = contextlib.ExitStack()
        self._idle: list[WorkerProcess] = []
        self._workers: list[WorkerProcess] = []
        self.running = 0

    async def start(self) -> None:
        """Start the workers (connect to the Dask cluster, in a thread: its client runs its
        own event loop) and give back the jobs still queued at the last stop."""
        if self.config.dask_address:
            self._dask = await asyncio.get_running_loop().run_in_executor(None, self._connect)
        else:
            one_blas_thread()  # before the worker processes start
            self._workers = [WorkerProcess(self.config.limits) for _ in range(self.config.workers)]
            self._idle = list(self._workers)
        for job_id in self.store.recover():
            self.enqueue(job_id)

    def _connect(self):
        client, _ = self._stack.enter_context(
            dask_client(self.config.dask_address, self.config.workers)
        )
        return client

    async def stop(self) -> None:
        """Stop: running jobs stay "solving" and are failed as interrupted at the next start;
        the worker processes are killed."""
        for task in list(self._tasks):
            task.cancel()
        for worker in self._workers:
            worker.stop()
        self._stack.close()  # the Dask client (and a local cluster)

    @property
    def queued(self) -> int:
        """Jobs waiting or running."""
        return len(self._tasks)

    def enqueue(self, job_id: int) -> None:
        """Queue job ``job_id`` (its input already stored)."""
        task = asyncio.get_running_loop().create_task(self._run(job_id))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _run(self, job_id: int) -> None:
        async with self._slots:
            job = self.store.get(job_id)
            if job is None or job.done:
                return
            data = xy = None
            if job.kind == "xy":
                xy = job.request
            else:
                data = (self.store.job_dir(job_id) / job.input_name).read_bytes()
            self.store.start(job_id)
            self.running += 1
            try:
                answer = await self._solve(data, xy, job.request)
            finally:
                self.running -= 1
            self._store_answer(job_id, answer)

    async def _solve(self, data, xy, request) -> dict:
        args = (data, xy, request, self.config.time_budget_s)
        if self._dask is None:
            worker = self._idle.pop()  # one is free: the slots count them
            try:
                return await worker.run(args)
            finally:
                self._idle.append(worker)
        limits = self.config.limits
        loop = asyncio.get_running_loop()
        future = self._dask.submit(run_job, *args, max_pixels=limits.max_pixels, pure=False)
        try:
            # no word from a Dask worker mid-job: the longest a job may take
            return await asyncio.wait_for(loop.run_in_executor(None, future.result), limits.whole_s)
        except TimeoutError:
            future.cancel()
            return failed_answer(limits.overrun(limits.whole_s - GRACE_S, "running on Dask"))
        except Exception as exc:  # the cluster lost the task, ...
            return failed_answer(f"error: the worker failed: {type(exc).__name__}: {exc}")

    def _store_answer(self, job_id: int, answer: dict) -> None:
        jdir = self.store.job_dir(job_id)
        for kind, blob in answer.get("files", {}).items():
            (jdir / OUTPUTS[kind]).write_bytes(blob)
        result = answer.get("result")
        if result is not None:
            result = dict(result, reason=answer["reason"], worker_ms=answer.get("worker_ms"))
            (jdir / RESULT_FILE).write_text(json.dumps(result, indent=1))
        self.store.finish(job_id, answer["solved"], answer["reason"], answer["calibration"],
                          result)  # fmt: skip


def busy(message: str) -> NovaJSON:
    """503 with Retry-After: the server is at one of its limits now; the same request may
    succeed later."""
    response = error(message, 503)
    response.headers["Retry-After"] = str(RETRY_AFTER_S)
    return response


class UploadLimit:
    """ASGI middleware: a request body over ``limit`` bytes gets 413 (by its Content-Length
    before anything is read, or once the bytes received pass the limit)."""

    def __init__(self, app, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope.get("headers") or []).get(b"content-length")
        too_big = f"the upload is larger than this server's limit of {self.limit / 1e6:g} MB"
        if length is not None and length.isdigit() and int(length) > self.limit:
            return await error(too_big, 413)(scope, receive, send)
        seen = 0

        async def counted():
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.limit:
                raise _TooBig(too_big)
            return message

        try:
            await self.app(scope, counted, send)
        except _TooBig as exc:
            await error(str(exc), 413)(scope, receive, send)


class _TooBig(Exception):
    pass


async def _request_json(request: Request) -> tuple[dict | None, object]:
    """The ``request-json`` of a request (None when absent) and its form (for the file);
    ``errors.RequestError`` when it is no JSON object or over a limit."""
    form = None
    raw = request.query_params.get("request-json")
    if request.method == "POST":
        body = await request.body()  # bounded by UploadLimit; the form parsers read it again
        try:
            form = await request.form(max_part_size=1 << 20)
        except HTTPException:
            form = _lenient_multipart(request.headers.get("content-type", ""), body)
        raw = form.get("request-json", raw)
    if raw is None:
        return None, form
    return parse_request_json(raw if isinstance(raw, str) else await raw.read()), form


@dataclass(frozen=True)
class _Part:
    """A multipart file part (the ``UploadFile`` subset the service uses)."""

    filename: str
    data: bytes

    async def read(self) -> bytes:
        return self.data


def _lenient_multipart(content_type: str, body: bytes) -> dict:
    """A multipart body python-multipart refuses, read by the standard library's MIME parser:
    astrometry.net's own ``client.py`` ends its boundary lines with a bare LF, which nova's
    Django accepts. Fields as str, file parts as ``_Part``; {} when it is no multipart."""
    import email.parser
    import email.policy

    head = f"Content-Type: {content_type}\r\n\r\n".encode("latin-1", "replace")
    msg = email.parser.BytesParser(policy=email.policy.HTTP).parsebytes(head + body)
    if not msg.is_multipart():
        return {}
    out: dict = {}
    for part in msg.iter_parts():
        name = part.get_param("name", header="content-disposition")
        if not name:
            continue
        data = part.get_payload(decode=True) or b""
        filename = part.get_filename()
        if filename is None:
            out[name] = data.decode("utf-8", "replace").rstrip("\r\n")
        else:
            out[name] = _Part(filename, data)
    return out


class NovaApi:
    """The endpoints: nova's routes over the job store and queue (``routes``)."""

    def __init__(self, config: ServiceConfig, store: JobStore, jobs: Jobs):
        self.config, self.store, self.jobs = config, store, jobs
        policy = FetchPolicy(config.max_upload_bytes, config.url_deadline_s,
                             config.allow_url_hosts)  # fmt: skip
        self.fetches = FetchQueue(policy, slots=config.url_fetches)

    async def parsed(self, request: Request, *, session: bool):
        """(error response or None, the request's JSON, its form), as nova's decorators
        ``requires_json_args`` and ``requires_json_session`` check them."""
        args, form = await _request_json(request)
        if args is None:
            return error("no json"), None, None
        if session:
            key = args.get("session")
            if not key:
                return error('no "session" in JSON.'), None, None
            if not self.store.has_session(key):
                return error(f'no session with key "{echo(key)}"'), None, None
        return None, args, form

    async def login(self, request: Request):
        bad, args, _ = await self.parsed(request, session=False)
        if bad:
            return bad
        key = args.get("apikey")
        if key is None:
            return error('need "apikey"')
        if self.config.api_key is not None and str(key) != self.config.api_key:
            return error("bad apikey")
        session = self.store.new_session()
        answer = NovaJSON({"status": "success", "message": "authenticated user: starnav",
                           "session": session})  # fmt: skip
        privacy.set_session_cookie(answer, session)
        return answer

    def queue_full(self) -> NovaJSON | None:
        """503 "busy" when ``max_queued`` jobs wait for a worker, else None."""
        waiting = self.jobs.queued - self.jobs.running
        if waiting < self.config.max_queued:
            return None
        jobs = "1 job waits" if waiting == 1 else f"{waiting} jobs wait"
        return busy(f"busy: {jobs} for a worker, this server's limit (--max-queued); try "
                    "again later")  # fmt: skip

    def accepted(self, job_id: int) -> NovaJSON:
        self.jobs.enqueue(job_id)
        return NovaJSON({"status": "success", "subid": job_id, "hash": str(job_id)})

    async def upload(self, request: Request):
        bad, args, form = await self.parsed(request, session=True)
        if bad:
            return bad
        upfile = None if form is None else form.get("file")
        if upfile is None or isinstance(upfile, str):
            if "x" in args and "y" in args:
                return self.xy_job(args)
            return error('no file: send the image as the multipart field "file"')
        data = await upfile.read()
        return self.image_job(data, upfile.filename or "", args)

    def image_job(self, data: bytes, original_filename: str, args: dict) -> NovaJSON:
        if not data:
            return error("the uploaded file is empty")
        if (full := self.queue_full()) is not None:
            return full
        job_id = self.store.add_job("image", Path(original_filename).name, _hints_only(args),
                                    **privacy.access(args))  # fmt: skip
        name = input_name(data[:16])
        (self.store.job_dir(job_id) / name).write_bytes(data)
        self.store.set_input(job_id, name)
        return self.accepted(job_id)

    def xy_job(self, args: dict) -> NovaJSON:
        x, y = args.get("x"), args.get("y")
        if not isinstance(x, list) or not isinstance(y, list):
            return error('Failed to parse JSON "x" and "y" values -- should be lists of floats')
        if len(x) != len(y):
            return error('"x" and "y" lists must be the same length')
        if (full := self.queue_full()) is not None:
            return full
        access = privacy.access(args)
        return self.accepted(
            self.store.add_job("xy", "json-xy", _hints_only(args, keep_xy=True), **access)
        )

    async def url_upload(self, request: Request):
        bad, args, _ = await self.parsed(request, session=True)
        if bad:
            return bad
        if "x" in args and "y" in args:
            return self.xy_job(args)
        url = args.get("url")
        if not isinstance(url, str) or not url.lower().startswith(("http://", "https://")):
            return error('need "url" (http or https), or "x" and "y"')
        if (full := self.queue_full()) is not None:
            return full  # before fetching what could not be queued
        try:
            data = await self.fetches.fetch(url)
        except FetchBusy as exc:
            return busy(str(exc))
        except FetchError as exc:
            return error(f"cannot fetch {echo(url)}: {echo(exc)}")
        return self.image_job(data, url.rsplit("/", 1)[-1], args)

    async def job_or_404(self, request: Request):
        """(the job, None), or (None, the 404 answer) for a job there is none of or that this
        request may not read (``privacy``: private, and none of the sessions it presents is
        the job's)."""
        job = self.store.get(request.path_params["job_id"])
        if job is not None and not privacy.open_to_all(job, self.config.api_key):
            args = None
            with contextlib.suppress(RequestError):  # no or bad request-json: no session in it
                args, _ = await _request_json(request)
            if job.owner not in privacy.presented_sessions(request, args):
                job = None
        if job is None:
            return None, error("no such job", 404)
        return job, None

    def answer(self, view):
        """An endpoint answering ``view(job)`` (a function of the job record) as JSON."""

        async def endpoint(request: Request):
            job, missing = await self.job_or_404(request)
            return missing or NovaJSON(view(job))

        return endpoint

    def file_route(self, name: str, media_type: str, download: str | None):
        """An endpoint sending the job's file ``name`` (``download``: its file name for the
        browser, with the job number in ``{}``)."""

        async def endpoint(request: Request):
            job, missing = await self.job_or_404(request)
            if missing:
                return missing
            path = self.store.job_dir(job.id) / name
            if not path.is_file():
                return error(f"job {job.id} has no such file ({job.status})", 404)
            filename = None if download is None else download.format(job.id)
            return FileResponse(path, media_type=media_type, filename=filename)

        return endpoint

    async def myjobs(self, request: Request):
        """The session's jobs (with an API key; without one, every job, as before)."""
        bad, args, _ = await self.parsed(request, session=True)
        if bad:
            return bad
        owner = None if self.config.api_key is None else args["session"]
        return NovaJSON({"jobs": self.store.job_ids(owner), "status": "success"})

    async def status(self, request: Request):
        return NovaJSON({"status": "success", "workers": self.config.workers,
                             "queued_or_running": self.jobs.queued, "running": self.jobs.running,
                             "jobs": len(self.store.job_ids())})  # fmt: skip

    async def page(self, request: Request):
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    def routes(self) -> list:
        """Every route: GET and POST, with and without a trailing slash (a redirect would
        lose a POST), the page and its static files."""
        job = "{job_id:job}"  # errors.JobNumber
        names = lambda key: self.answer(lambda j: {key: nova.star_names(j)})  # noqa: E731
        files = self.file_route
        api = {
            "/api/login": self.login,
            "/api/upload": self.upload,
            "/api/url_upload": self.url_upload,
            f"/api/submissions/{job}": self.answer(nova.submission_status),
            "/api/myjobs": self.myjobs,
            f"/api/jobs/{job}": self.answer(nova.job_status),
            f"/api/jobs/{job}/calibration": self.answer(nova.calibration),
            f"/api/jobs/{job}/info": self.answer(nova.job_info),
            f"/api/jobs/{job}/annotations": self.answer(nova.annotations),
            f"/api/jobs/{job}/tags": names("tags"),
            f"/api/jobs/{job}/machine_tags": names("tags"),
            f"/api/jobs/{job}/objects_in_field": names("objects_in_field"),
            f"/api/jobs/{job}/starnav": self.answer(nova.starnav_answer),
            "/api/status": self.status,
            f"/wcs_file/{job}": files(OUTPUTS["wcs"], "application/fits", "wcs-{}.fits"),
            f"/new_fits_file/{job}": files(
                OUTPUTS["new_fits"], "application/fits", "new-image-{}.fits"
            ),
            f"/corr_file/{job}": files(OUTPUTS["corr"], "application/fits", "corr-{}.fits"),
            f"/rdls_file/{job}": files(OUTPUTS["rdls"], "application/fits", "rdls-{}.fits"),
            f"/axy_file/{job}": files(OUTPUTS["axy"], "application/fits", "axy-{}.fits"),
            f"/kml_file/{job}": files(
                OUTPUTS["kmz"], "application/x-zip-compressed", "image-{}.kmz"
            ),
            f"/annotated_display/{job}": files(OUTPUTS["annotate"], "image/png", None),
            f"/annotated_full/{job}": files(OUTPUTS["annotate"], "image/png", None),
            f"/json_file/{job}": files(RESULT_FILE, "application/json", "starnav-{}.json"),
        }
        routes = [Route(path + end, endpoint, methods=["GET", "POST"])
                  for path, endpoint in api.items() for end in ("", "/")]  # fmt: skip
        routes.append(Route("/", self.page))
        if STATIC_DIR.is_dir():
            routes.append(Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"))
        return routes


def create_app(config: ServiceConfig) -> Starlette:
    """The service's ASGI application (``starnav serve`` runs it with uvicorn)."""
    store = JobStore(config.data_dir)
    jobs = Jobs(config, store)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        await jobs.start()
        yield
        await jobs.stop()
        api.fetches.close()
        clean_job_tmp(config.data_dir)  # the stopped workers' inputs
        store.close()

    api = NovaApi(config, store, jobs)
    app = Starlette(routes=api.routes(), lifespan=lifespan, exception_handlers=EXCEPTION_HANDLERS)
    app.state.store, app.state.jobs = store, jobs
    app.add_middleware(UploadLimit, limit=config.max_upload_bytes)
    return app


def _hints_only(args: dict, keep_xy: bool = False) -> dict:
    """The request as stored: without the session (a credential) and, unless ``keep_xy``,
    without a source list."""
    drop = {"session"} | (set() if keep_xy else {"x", "y"})
    return {k: v for k, v in args.items() if k not in drop}


def wait_ready(url: str, timeout_s: float = 30.0) -> None:
    """Wait until the service at ``url`` answers ``api/status`` (for scripts and tests)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(url.rstrip("/") + "/api/status", timeout=2):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
