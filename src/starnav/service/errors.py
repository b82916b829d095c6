"""The service's errors as nova's JSON, and a request's JSON read within bounds.

Every error answers ``{"status": "error", "errormessage": ...}``. The HTTP status: 200 for the
errors nova itself answers so (no or bad ``request-json``, no or unknown session, a bad
``apikey``, a bad upload: clients such as astrometry-net-client read the message only from a
200 and log in again on "no session with key"); 400 for a request refused by a limit nova
does not have (``request-json`` nested too deeply); 404 for an unknown job or route; 405 for
a method a route does not take; 413 for a body or ``request-json`` over its limit; 500
("internal error", logged) only for a bug.
"""

from __future__ import annotations

import json
import logging
import re

from starlette.convertors import Convertor, register_url_convertor
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import JSONResponse

from starnav.errors import StarnavError

log = logging.getLogger("starnav.service")

MAX_JSON_BYTES = 1 << 20  # 20 000 stars' x and y (random pixels, Python's floats): 0.78 MB
MAX_JSON_DEPTH = 16  # nova's request is an object of numbers, strings and lists: depth 2
ECHO_CHARS = 100  # how much of a client's text an error message repeats


class NovaJSON(JSONResponse):
    """A JSON answer as nova sends it: ``text/plain`` (astrometry.net's net/api.py,
    ``json_type``), which some clients check before they parse (astrometry-net-client
    refuses anything else), and ASCII with ``\\u`` escapes as nova's ``python2json``, so that
    any text a client sent (a lone surrogate included) can be echoed."""

    media_type = "text/plain"

    def render(self, content) -> bytes:
        return json.dumps(content, allow_nan=False, separators=(",", ":")).encode("ascii")


def error(message: str, status_code: int = 200) -> NovaJSON:
    """nova's error answer (HTTP 200 like nova's, unless ``status_code`` says otherwise)."""
    return NovaJSON({"status": "error", "errormessage": message}, status_code=status_code)


class RequestError(StarnavError):
    """A request the service refuses: answered as nova's error ``message`` with HTTP
    ``status_code`` (see the module's docstring for which)."""

    def __init__(self, message: str, status_code: int = 200):
        super().__init__(message)
        self.status_code = status_code


def echo(text: object) -> str:
    """A client's value as an error message repeats it: at most ``ECHO_CHARS`` characters,
    on one line, anything unprintable (a newline, a NUL, a lone surrogate, a right-to-left
    mark) as its Python escape."""
    text = str(text)
    short = text if len(text) <= ECHO_CHARS else text[:ECHO_CHARS] + "..."
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in short)


def parse_request_json(raw: str | bytes) -> dict:
    """nova's ``request-json``: a JSON object, at most ``MAX_JSON_BYTES`` long and
    ``MAX_JSON_DEPTH`` deep (checked before it is parsed), without NaN or Infinity.
    ``RequestError`` saying what is wrong otherwise."""
    if len(raw) > MAX_JSON_BYTES:
        raise RequestError(
            f"request-json is {len(raw) / 1e6:.1f} MB, over this server's limit of "
            f"{MAX_JSON_BYTES / 1e6:.1f} MB",
            413,
        )
    try:
        text = raw if isinstance(raw, str) else raw.decode("utf-8")
    except UnicodeDecodeError:
        raise RequestError('failed to parse JSON: "request-json" is not UTF-8 text') from None
    if json_depth_over(text, MAX_JSON_DEPTH):
        raise RequestError(f"request-json is nested deeper than {MAX_JSON_DEPTH} levels", 400)
    try:
        args = json.loads(text, parse_constant=_no_constant)
    except ValueError:  # bad JSON, NaN or Infinity, an integer of over 4300 digits
        args = None
    if not isinstance(args, dict):
        raise RequestError(f'failed to parse JSON: "{echo(text)}"')
    return args


def _no_constant(name: str):
    raise ValueError(f"{name} is not JSON")


_JSON_SPECIAL = re.compile(r'[\[\]{}"\\]')


def json_depth_over(text: str, limit: int) -> bool:
    """Whether the JSON ``text`` nests arrays and objects deeper than ``limit`` (brackets in
    strings do not count); one pass over its brackets, quotes and backslashes, stopping at
    the first level past ``limit``."""
    depth, in_string, escaped_at = 0, False, -1
    for m in _JSON_SPECIAL.finditer(text):
        c, at = m.group(), m.start()
        if in_string:
            if at == escaped_at:
                continue
            if c == "\\":
                escaped_at = at + 1
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            if depth > limit:
                return True
        elif c in "]}":
            depth -= 1
    return False


class JobNumber(Convertor[int]):
    """A job number in a path (``{job_id:job}``): any integer, so that a negative one or one
    past SQLite's 64 bits is answered "no such job" (``JobStore.get`` checks the range), not
    "no such route"; one of over 20 digits is 0, which no job has."""

    regex = "-?[0-9]+"

    def convert(self, value: str) -> int:
        return int(value) if len(value) <= 20 else 0

    def to_string(self, value: int) -> str:
        return str(int(value))


register_url_convertor("job", JobNumber())


async def request_error(request: Request, exc: RequestError) -> NovaJSON:
    return error(str(exc), exc.status_code)


async def http_error(request: Request, exc: HTTPException) -> NovaJSON:
    """Starlette's own refusals (an unknown route, a method a route does not take) as
    nova's JSON."""
    path = echo(request.url.path)
    message = {404: f"no such route: {path}",
               405: f"{echo(request.method)} is not allowed on {path}"}  # fmt: skip
    return NovaJSON(
        {"status": "error", "errormessage": message.get(exc.status_code, str(exc.detail))},
        status_code=exc.status_code,
        headers=exc.headers,
    )


async def internal_error(request: Request, exc: Exception) -> NovaJSON:
    """The last resort: a bug answers nova's JSON 500 "internal error", with a log line."""
    log.error(
        "internal error answering %s %s: %s: %s",
        request.method,
        echo(request.url.path),
        type(exc).__name__,
        echo(exc),
        exc_info=exc,
    )
    return error("internal error", 500)


EXCEPTION_HANDLERS = {RequestError: request_error, HTTPException: http_error,
                      Exception: internal_error}  # fmt: skip
