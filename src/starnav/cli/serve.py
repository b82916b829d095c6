"""``starnav serve``: the nova-compatible HTTP service and its web page (``starnav.service``)."""

from __future__ import annotations

import argparse
import ipaddress
import math
import signal
import socket
import sys
from pathlib import Path

from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_dask,
    add_time_budget,
    finite,
    positive_int,
)
from starnav.errors import StarnavError
from starnav.runtime.limits import (
    DEFAULT_MAX_QUEUED,
    DEFAULT_MAX_UPLOAD_MB,
    DEFAULT_URL_DEADLINE_S,
    DEFAULT_WORKER_MEMORY_MB,
    MAX_PIXELS,
)
from starnav.service.files import (
    DEFAULT_CACHE_LIMIT_MB,
    clean_leftovers,
    lock_data_dir,
    use_data_dir,
)

DEFAULT_PORT = 8080


def add_parser(subparsers: Subparsers) -> None:
    """The ``serve`` command and its options."""
    p = subparsers.add_parser(
        "serve",
        help="an HTTP plate-solving service speaking astrometry.net's API, with a web page",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=_port, default=DEFAULT_PORT,
                   help=f"TCP port (default {DEFAULT_PORT})")  # fmt: skip
    p.add_argument("--data-dir", default="starnav-data",
                   help="jobs database and files (default ./starnav-data)")  # fmt: skip
    p.add_argument("--workers", type=positive_int, default=1,
                   help="jobs solved at once (worker processes; default 1)")  # fmt: skip
    p.add_argument("--api-key", help="the key api/login asks for (needed off the loopback)")
    p.add_argument("--max-upload-mb", type=finite, default=DEFAULT_MAX_UPLOAD_MB,
                   help="largest request body accepted "
                   f"(MB; default {DEFAULT_MAX_UPLOAD_MB:g})")  # fmt: skip
    p.add_argument("--max-queued", type=positive_int, default=DEFAULT_MAX_QUEUED,
                   help="jobs waiting for a worker before uploads are answered 503 busy "
                   f"(default {DEFAULT_MAX_QUEUED})")  # fmt: skip
    p.add_argument("--allow-url-hosts", default="", metavar="LIST",
                   help="non-public hosts api/url_upload may fetch from: host names, addresses "
                   "and CIDR networks, comma-separated (default: none)")  # fmt: skip
    p.add_argument("--url-timeout", type=finite, default=DEFAULT_URL_DEADLINE_S,
                   metavar="SECONDS", help="limit of a whole URL fetch "
                   f"(s; default {DEFAULT_URL_DEADLINE_S:g})")  # fmt: skip
    p.add_argument("--cache-limit-mb", type=finite, default=DEFAULT_CACHE_LIMIT_MB,
                   help="tables the workers may write in DATA/cache (MB; default "
                        f"{DEFAULT_CACHE_LIMIT_MB:g}; past it new ones stay in memory)",
                   )  # fmt: skip
    add_time_budget(p)
    p.add_argument("--max-pixels-mp", type=_positive, default=MAX_PIXELS / 1e6,
                   help="largest image a job reads, checked from its header (megapixels; "
                   f"default {MAX_PIXELS / 1e6:g})")  # fmt: skip
    p.add_argument("--max-job-mb", type=_megabytes, default=DEFAULT_WORKER_MEMORY_MB,
                   help="memory of a worker process solving a job (MB; default "
                   f"{DEFAULT_WORKER_MEMORY_MB:g}; 'none': no limit)")  # fmt: skip
    add_dask(p, "the jobs")
    p.add_argument("--json", action="store_true",
                   help="print one JSON line with the address when listening")  # fmt: skip
    p.set_defaults(run=run)


def _port(text: str) -> int:
    """Argument type: a TCP port, 1-65535."""
    value = positive_int(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"a TCP port is 1-65535, got {text}")
    return value


def _positive(text: str) -> float:
    """Argument type: a positive finite number."""
    value = finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _megabytes(text: str) -> float:
    """Argument type: a positive number of MB, or "none" (``math.inf``: no limit)."""
    return math.inf if text.strip().lower() == "none" else _positive(text)


def check_host(host: str, api_key: str | None) -> None:
    """Refuse to listen beyond the loopback without an API key."""
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback and not api_key:
        raise StarnavError(
            f"listening on {host} would let anyone on the network use this server: give "
            "--api-key KEY (clients log in with it)"
        )


def _check_port(host: str, port: int) -> None:
    """A one-line error now rather than uvicorn's log line later when the port is taken."""
    try:
        with socket.create_server((host, port)):
            pass
    except OSError as exc:
        raise StarnavError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted."""
    check_host(args.host, args.api_key)
    if args.max_upload_mb <= 0:
        raise StarnavError(f"--max-upload-mb must be positive, got {args.max_upload_mb:g}")
    if args.url_timeout <= 0:
        raise StarnavError(f"--url-timeout must be positive, got {args.url_timeout:g}")
    if args.cache_limit_mb < 0:
        raise StarnavError(f"--cache-limit-mb must be 0 or more, got {args.cache_limit_mb:g}")
    from starnav.service.fetch import AllowedHosts  # the standard library's only

    allowed = AllowedHosts.parse(args.allow_url_hosts)  # a bad list before anything is made
    data_dir = Path(args.data_dir)
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StarnavError(f"cannot make --data-dir {str(data_dir)!r}: {exc.strerror}") from None
    lock_data_dir(data_dir)  # held until this process ends
    cleaned = clean_leftovers(data_dir)
    use_data_dir(data_dir, args.cache_limit_mb)  # before the imports below load numba
    try:
        import uvicorn

        from starnav.service.app import ServiceConfig, create_app
    except ImportError as exc:
        raise StarnavError(
            f"starnav serve needs the serve extra ({exc.name} is missing): "
            "pip install 'starnav[serve]'"
        ) from None
    config = ServiceConfig(
        data_dir=data_dir,
        workers=args.workers,
        api_key=args.api_key,
        max_upload_bytes=int(args.max_upload_mb * 1e6),
        time_budget_s=args.time_budget,
        dask_address=args.dask,
        max_queued=args.max_queued,
        url_deadline_s=args.url_timeout,
        allow_url_hosts=allowed,
        max_pixels=max(int(args.max_pixels_mp * 1e6), 1),
        max_job_bytes=None if math.isinf(args.max_job_mb) else int(args.max_job_mb * 1e6),
    )
    _check_port(args.host, args.port)
    url = f"http://{args.host}:{args.port}/"
    if args.json:
        import json

        print(json.dumps({"url": url, "data_dir": str(data_dir.resolve()),
                          "cleaned": str(cleaned)}), flush=True)  # fmt: skip
    else:
        said = f"; {cleaned}" if str(cleaned) else ""
        print(f"starnav serve: {url} (data in {data_dir.resolve()}){said}", file=sys.stderr,
              flush=True)  # fmt: skip
    # uvicorn stops cleanly on SIGTERM, then raises it again: exit through Python then, so
    # that multiprocessing removes its folder in DATA/tmp as it does after Ctrl-C
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    uvicorn.run(create_app(config), host=args.host, port=args.port, log_level="warning")
    return EXIT_OK


def _exit_on_sigterm(signum, frame) -> None:
    raise SystemExit(128 + signal.SIGTERM)
