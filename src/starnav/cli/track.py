"""``starnav track``: a stream of frames (JSON lines) to one answer line each, tracking from the
last attitude (``starnav.pipeline.track``), on stdin/stdout or a loopback TCP socket.

Runs until the input ends (stdin) or a signal (SIGINT, SIGTERM): the frame in hand is answered
first, then it exits 0. A frame that cannot be read gets one error line; the stream goes on.
"""

from __future__ import annotations

import argparse
import ipaddress
import signal
import socket
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace

from starnav.camera import MODELS
from starnav.cli.common import (
    EXIT_OK,
    Subparsers,
    add_acceptance,
    add_algorithm,
    add_catalog,
    add_deep_mag_limit,
    add_time_budget,
    finite,
    positive_int,
)
from starnav.cli.identify import solve_options
from starnav.cli.output import to_json
from starnav.errors import StarnavError
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.track import DEFAULT_MAX_GAP_S, Tracker


def add_parser(subparsers: Subparsers) -> None:
    """The ``track`` command and its options."""
    p = subparsers.add_parser(
        "track",
        help="answer a stream of centroid frames (JSON lines on stdin or a loopback socket), "
        "tracking from the last attitude",
    )
    field = p.add_mutually_exclusive_group()
    field.add_argument("--fov-deg", type=finite, help="horizontal field of view (degrees; "
                       "default: none, give it or --camera)")  # fmt: skip
    field.add_argument("--camera", help="camera file (any lens model; width and height from it)")
    p.add_argument("--lens", choices=tuple(MODELS), default="pinhole",
                   help="the lens model with --fov-deg (default %(default)s)")  # fmt: skip
    p.add_argument("--width", type=positive_int, help="image width (px; or give --camera)")
    p.add_argument("--height", type=positive_int, help="image height (px; default: width)")
    add_catalog(p)
    add_deep_mag_limit(p)
    p.add_argument("--sigma-px", type=finite, help="centroid error, 1 sigma (px; default: "
                   "not known, as for starnav identify)")  # fmt: skip
    add_acceptance(p)
    add_algorithm(p)
    p.add_argument("--prior-sigma-deg", type=finite, default=SolveOptions.prior_sigma_deg,
                   help="1-sigma error of the last attitude as a prior for the next frame "
                   "(degrees; default %(default)g)")  # fmt: skip
    p.add_argument("--max-gap-s", type=finite, default=DEFAULT_MAX_GAP_S,
                   help="track only from an attitude solved at most this long before (s, by "
                   "the frames' t, else when received; default %(default)g)")  # fmt: skip
    add_time_budget(p)
    p.add_argument("--listen", metavar="HOST:PORT",
                   help="read frames from and answer on a TCP connection to this loopback "
                   "address (one client at a time; port 0: any free port) instead of "
                   "stdin/stdout")  # fmt: skip
    p.add_argument("--json", action="store_true",
                   help="the answers are JSON lines anyway; with --listen also print the "
                   "address as one JSON line on stdout")  # fmt: skip
    p.set_defaults(run=run, fov_range=None, fit_focal=False)


def listen_address(text: str) -> tuple[str, int]:
    """(host, port) of --listen HOST:PORT ([::1]:PORT for IPv6), refused unless the host is a
    loopback address or localhost: the stream has no authentication."""
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port_text.isdigit() or int(port_text) > 65535:
        raise StarnavError(f"--listen takes HOST:PORT (port 0-65535), got {text!r}")
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise StarnavError(
            f"--listen {text}: {host} is not a loopback address; the stream has no "
            "authentication, so it listens on 127.0.0.1, ::1 or localhost only"
        )
    return host, int(port_text)


class Stop(Exception):
    """A signal asked the stream to stop while it waited for input."""


class Signals:
    """SIGINT and SIGTERM as a request to stop: raised as ``Stop`` while the stream waits for
    input (``waiting``), else noted, so the frame in hand is answered first."""

    def __init__(self) -> None:
        self.requested = False
        self._waiting = False

    def handle(self, signum: int, _frame) -> None:
        self.requested = True
        if self._waiting:
            raise Stop

    @contextmanager
    def waiting(self) -> Iterator[None]:
        """Around a blocking read: a signal now (or one noted before) stops it."""
        if self.requested:
            raise Stop
        self._waiting = True
        try:
            yield
        finally:
            self._waiting = False

    @contextmanager
    def installed(self) -> Iterator[Signals]:
        """Handle SIGINT and SIGTERM here for the time of the block."""
        before = {s: signal.signal(s, self.handle) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for s, handler in before.items():
                signal.signal(s, handler)


def answer_stream(readline: Callable[[], bytes], write: Callable[[str], None], tracker: Tracker,
                  signals: Signals) -> None:  # fmt: skip
    """Answer every line of ``readline`` (blank ones skipped) with one line to ``write``
    until the input ends or a signal asks to stop."""
    while not signals.requested:
        with signals.waiting():
            line = readline()
        if not line:
            return
        if line.strip():
            write(to_json(tracker.answer(line).to_dict()) + "\n")


def run(args: argparse.Namespace) -> int:
    """Prepare the solver, then answer frames until the input ends or a signal."""
    if args.camera is None and (args.fov_deg is None or args.width is None):
        raise StarnavError("track needs the camera: --fov-deg and --width, or --camera FILE")
    if args.max_gap_s < 0:
        raise StarnavError(f"--max-gap-s must be >= 0, got {args.max_gap_s:g}")
    address = listen_address(args.listen) if args.listen else None
    options = replace(solve_options(args), prior_sigma_deg=args.prior_sigma_deg)
    # a signal while the solver is prepared stops the stream before its first frame
    with Signals().installed() as signals, bound(address) as server:
        tracker = Tracker.prepare(
            options, width=args.width, height=args.height, max_gap_s=args.max_gap_s
        )
        warm_s = tracker.warm_up()
        catalog = f"catalog {tracker.solver.catalog.name}"
        try:
            if server is None:
                _say(f"ready ({catalog}; machine code loaded in {warm_s:.2f} s)")
                answer_stream(sys.stdin.buffer.readline, _write_stdout, tracker, signals)
            else:
                serve(server, tracker, signals, json_line=args.json)
        except Stop:
            pass
    sys.stdout.flush()
    return EXIT_OK


@contextmanager
def bound(address: tuple[str, int] | None) -> Iterator[socket.socket | None]:
    """A TCP socket listening on ``address`` (None: none), or a one-line error before any
    work when it cannot."""
    if address is None:
        yield None
        return
    host, port = address
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        server = socket.create_server((host, port), family=family)
    except OSError as exc:
        raise StarnavError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    with server:
        yield server


def serve(server: socket.socket, tracker: Tracker, signals: Signals, *, json_line: bool) -> None:
    """Answer one client at a time of the listening ``server`` (lines in, lines out on the
    same connection; each client's stream starts anew: frame 0, lost in space) until a
    signal."""
    host, port = server.getsockname()[:2]
    _say(f"listening on {host}:{port} (catalog {tracker.solver.catalog.name})")
    if json_line:
        _write_stdout(to_json({"listen": f"{host}:{port}"}) + "\n")
    while True:
        with signals.waiting():
            conn, _ = server.accept()
        tracker.reset()
        with conn, conn.makefile("rb") as lines:
            try:
                answer_stream(lines.readline, _sender(conn), tracker, signals)
            except ConnectionError:  # the client went away: wait for the next
                pass
        if signals.requested:
            return


def _sender(conn: socket.socket) -> Callable[[str], None]:
    return lambda text: conn.sendall(text.encode())


def _write_stdout(text: str) -> None:
    sys.stdout.write(text)
    sys.stdout.flush()  # the reader acts on each line as it comes


def _say(text: str) -> None:
    print(f"starnav track: {text}", file=sys.stderr, flush=True)
