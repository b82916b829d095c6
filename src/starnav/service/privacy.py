"""Who may read a job: with an API key, its session's client, or anyone when it is public.

nova's upload field ``publicly_visible`` ("y" or "n"; nova's API takes "y" when it is absent,
``net/api.py``) says whether a job is public. With ``--api-key``, a job submitted with "n" is
readable (its status, answers, files, its submission) only by a request that presents the
session which submitted it, and ``api/myjobs`` lists a session's own jobs; any other request
is answered "no such job" (404), as for a job there is none of, so that it learns nothing of
the job. Without an API key, every job is readable by anyone, as on a local ansvr.

A request presents a session (``presented_sessions``) as ``?session=KEY`` in the query string,
as ``"session"`` in its ``request-json`` (astrometry.net's ``client.py`` sends it so), or as the
cookie ``api/login`` sets (``SESSION_COOKIE``: a browser and a cookie-keeping client such as
astroquery send it back by themselves).
"""

from __future__ import annotations

from starlette.requests import Request
from starlette.responses import Response

from starnav.service.errors import RequestError, echo
from starnav.service.store import Job

SESSION_COOKIE = "starnav_session"
VISIBILITY = {"y": True, "n": False}  # nova's publicly_visible
DEFAULT_VISIBILITY = "y"  # nova's, for an upload without the field


def access(args: dict) -> dict:
    """The ``owner`` (the request's session) and ``public`` flag of a job submitted with nova's
    request ``args`` (its session already checked); ``RequestError`` for a
    ``publicly_visible`` other than "y" or "n"."""
    visible = args.get("publicly_visible", DEFAULT_VISIBILITY)
    if not isinstance(visible, str) or visible not in VISIBILITY:
        raise RequestError(f'publicly_visible must be "y" or "n", got "{echo(visible)}"')
    return {"owner": args["session"], "public": VISIBILITY[visible]}


def open_to_all(job: Job, api_key: str | None) -> bool:
    """Whether anyone may read ``job``: it is public, or the server has no API key."""
    return api_key is None or job.public


def presented_sessions(request: Request, args: dict | None) -> set[str]:
    """The session keys ``request`` presents (``args``: its ``request-json``, None when it
    has none)."""
    keys = (request.query_params.get("session"), request.cookies.get(SESSION_COOKIE),
            (args or {}).get("session"))  # fmt: skip
    return {k for k in keys if isinstance(k, str)}


def set_session_cookie(response: Response, session: str) -> None:
    """``api/login``'s answer sets the session as a cookie for this server's pages and files
    (not sent to other sites; not readable by scripts)."""
    response.set_cookie(SESSION_COOKIE, session, httponly=True, samesite="strict", path="/")
