"""Private and public jobs (nova's ``publicly_visible``) over real HTTP to ``starnav serve``
processes on the loopback: with ``--api-key`` a job sent with "n" is read only by the session
that submitted it (``?session=``, ``request-json``, or the cookie ``api/login`` sets), every
other request is answered "no such job" (404) on every route; "y" and no field (nova's
default) are public; without ``--api-key`` everything is readable, as before. astroquery (a
cookie-keeping client) solves a private job; a ``starnav.sqlite`` of the first schema opens
with its private requests kept private."""

from __future__ import annotations

import http.cookiejar
import json
import sqlite3
import time
import urllib.error
import urllib.parse
import urllib.request

import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")

from service_helpers import Server, api, source_list
from shared_data import LYRA, PEER_REFERENCE, USER_CACHE_DIR
from starnav.service.privacy import SESSION_COOKIE
from starnav.service.store import JobStore

pytestmark = pytest.mark.service
slow = pytest.mark.slow  # the tests of a server process: two servers and their solves

KEY = "the operator's key"
JOB_ROUTES = ["api/submissions/{}", "api/jobs/{}", "api/jobs/{}/calibration", "api/jobs/{}/info",
              "api/jobs/{}/annotations", "api/jobs/{}/tags", "api/jobs/{}/machine_tags",
              "api/jobs/{}/objects_in_field", "api/jobs/{}/starnav", "wcs_file/{}",
              "corr_file/{}", "rdls_file/{}", "axy_file/{}", "annotated_display/{}",
              "annotated_full/{}", "json_file/{}"]  # fmt: skip


def get(url: str, path: str, *, headers=None, data: dict | None = None) -> tuple[int, bytes]:
    """(HTTP status, body) of a GET (a POST of ``request-json`` ``data`` when given)."""
    body = None if data is None else urllib.parse.urlencode({"request-json": json.dumps(data)})
    req = urllib.request.Request(f"{url}/{path}", body and body.encode(), headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=30) as resp:
            return resp.status, resp.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def submit(url: str, session: str, visible: str | None) -> int:
    """A source list of the Lyra frame with a scale hint (solved in about a second)."""
    x, y = source_list(LYRA)
    ref = PEER_REFERENCE[LYRA]
    width = ref["file"]["width"]
    scale = ref["fov_deg"] * 3600 / width
    args = {"session": session, "x": x, "y": y, "image_width": width,
            "image_height": ref["file"]["height"], "scale_units": "arcsecperpix",
            "scale_lower": 0.9 * scale, "scale_upper": 1.1 * scale}  # fmt: skip
    if visible is not None:
        args["publicly_visible"] = visible
    answer = api(url, "url_upload", args)
    assert answer["status"] == "success", answer
    return answer["subid"]


def wait_private(url: str, job_id: int, session: str, timeout_s: float = 180.0) -> str:
    """Poll ``api/jobs/N?session=`` until the job is done; its status."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = json.loads(get(url, f"api/jobs/{job_id}?session={session}")[1])["status"]
        if status in ("success", "failure"):
            return status
        time.sleep(0.2)
    raise TimeoutError(f"job {job_id} not done after {timeout_s:g} s")


def readers(session: str) -> dict:
    """The ways a request presents ``session``: (headers, request-json, query)."""
    return {"query": ({}, None, f"?session={session}"),
            "request-json": ({}, {"session": session}, ""),
            "cookie": ({"Cookie": f"{SESSION_COOKIE}={session}"}, None, "")}  # fmt: skip


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    """A server with --api-key, two sessions, and three finished jobs of session "a":
    private, public, and sent without the field."""
    server = Server(tmp_path_factory.mktemp("keyed"), workers=1, cache_dir=USER_CACHE_DIR,
                    api_key=KEY).start()  # fmt: skip
    try:
        a, b = (api(server.url, "login", {"apikey": KEY})["session"] for _ in range(2))
        jobs = {v: submit(server.url, a, v) for v in ("n", "y", None)}
        for job_id in jobs.values():
            assert wait_private(server.url, job_id, a) == "success"
        yield server, a, b, jobs
    finally:
        server.stop()


@slow
def test_a_private_job_is_read_only_by_its_session(keyed):
    server, a, b, jobs = keyed
    private = jobs["n"]
    for route in JOB_ROUTES:
        path = route.format(private)
        for how, (headers, data, query) in readers(a).items():
            status, body = get(server.url, path + query, headers=headers, data=data)
            assert status == 200, (path, how, body[:200])
        for who, (headers, data, query) in [("nobody", ({}, None, "")), *readers(b).items(),
                                            *readers("0" * 32).items()]:  # fmt: skip
            status, body = get(server.url, path + query, headers=headers, data=data)
            assert status == 404, (path, who, status)
            assert json.loads(body) == {"status": "error", "errormessage": "no such job"}


@slow
def test_public_jobs_are_read_by_anyone(keyed):
    server, _, _, jobs = keyed
    for job_id in (jobs["y"], jobs[None]):  # "y", and nova's default
        for route in JOB_ROUTES:
            status, body = get(server.url, route.format(job_id))
            assert status == 200, (route, body[:200])


@slow
def test_myjobs_lists_the_sessions_own_jobs(keyed):
    server, a, b, jobs = keyed
    assert api(server.url, "myjobs", {"session": a})["jobs"] == sorted(jobs.values())
    assert api(server.url, "myjobs", {"session": b})["jobs"] == []


@slow
def test_login_sets_the_cookie_a_client_keeps(keyed):
    """A client that keeps cookies (as a browser, or astroquery's requests session) reads its
    private job after api/login without sending the session itself."""
    server, *_ = keyed
    opener = urllib.request.build_opener(
        urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar())
    )
    login = urllib.parse.urlencode({"request-json": json.dumps({"apikey": KEY})}).encode()
    with opener.open(f"{server.url}/api/login", login) as resp:
        session = json.loads(resp.read())["session"]
        assert "HttpOnly" in resp.headers["Set-Cookie"]
    job_id = submit(server.url, session, "n")
    with opener.open(f"{server.url}/api/jobs/{job_id}") as resp:
        assert json.loads(resp.read())["status"] in ("processing", "solving", "success")
    assert get(server.url, f"api/jobs/{job_id}")[0] == 404


@slow
def test_a_bad_publicly_visible_is_refused(keyed):
    server, a, *_ = keyed
    args = {"session": a, "x": [1], "y": [1], "publicly_visible": "maybe"}
    answer = api(server.url, "url_upload", args)
    assert answer["errormessage"] == 'publicly_visible must be "y" or "n", got "maybe"'
    assert api(server.url, "myjobs", {"session": a})["jobs"] == sorted(keyed[3].values())


@slow
def test_astroquery_solves_a_private_job(keyed):
    """astroquery with ``publicly_visible="n"``: its polls carry the login's cookie, so it gets
    its WCS; the same job is hidden from a request without the session."""
    pytest.importorskip("astroquery", reason="astroquery is not installed: pip install '.[dev]'")
    from astroquery import cache_conf
    from astroquery.astrometry_net import AstrometryNetClass

    server, *_ = keyed
    client = AstrometryNetClass()
    client.URL, client.API_URL, client.api_key = server.url, server.url + "/api", KEY
    x, y = source_list(LYRA)
    ref = PEER_REFERENCE[LYRA]["file"]
    with cache_conf.set_temp("cache_active", False):
        header, job_id = client.solve_from_source_list(
            x, y, ref["width"], ref["height"], publicly_visible="n", verbose=False,
            solve_timeout=120, return_submission_id=True,
        )  # fmt: skip
    assert header["IMAGEW"] == ref["width"]
    assert get(server.url, f"wcs_file/{job_id}")[0] == 404


@slow
def test_without_a_key_everything_is_readable(tmp_path):
    """Without --api-key (sessions issued to any key), a job sent with "n" is read by anyone
    and api/myjobs lists every job, as before."""
    server = Server(tmp_path, workers=1, cache_dir=USER_CACHE_DIR).start()
    try:
        a, b = (api(server.url, "login", {"apikey": k})["session"] for k in ("a", "b"))
        private = submit(server.url, a, "n")
        assert get(server.url, f"api/jobs/{private}")[0] == 200
        assert get(server.url, f"api/submissions/{private}")[0] == 200
        assert api(server.url, "myjobs", {"session": b})["jobs"] == [private]
    finally:
        server.stop()


OLD_SCHEMA = """
CREATE TABLE sessions (key TEXT PRIMARY KEY, created REAL NOT NULL);
CREATE TABLE jobs (id INTEGER PRIMARY KEY AUTOINCREMENT, kind TEXT NOT NULL,
    original_filename TEXT NOT NULL, input_name TEXT, request TEXT NOT NULL,
    status TEXT NOT NULL, submitted REAL NOT NULL, started REAL, finished REAL, reason TEXT,
    calibration TEXT, result TEXT);
"""


@pytest.mark.parametrize("visible", ["n", "y", None])
def test_a_database_of_the_first_schema_opens(tmp_path, visible):
    """The columns are added; a job whose request said "n" stays private (its session was
    never stored: no session reads it), the others are public."""
    db = sqlite3.connect(tmp_path / "starnav.sqlite")
    db.executescript(OLD_SCHEMA)
    request = {} if visible is None else {"publicly_visible": visible}
    db.execute("INSERT INTO jobs (kind, original_filename, request, status, submitted) "
               "VALUES ('xy', 'json-xy', ?, 'queued', 0)", (json.dumps(request),))  # fmt: skip
    db.commit()
    db.close()
    store = JobStore(tmp_path)
    job = store.get(1)
    assert (job.owner, job.public) == (None, visible != "n")
    assert store.get(store.add_job("xy", "json-xy", {}, owner="k", public=False)).owner == "k"
    store.close()
