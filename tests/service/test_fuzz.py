"""Every route of ``starnav serve`` under random input (hypothesis, in process through
Starlette's TestClient, a real worker process behind it): random ``request-json`` (nested,
huge integers, NaN, odd unicode with lone surrogates, NUL and right-to-left marks) sent every
way nova's clients send it, random bytes as bodies and as multipart files, random query
strings, huge and negative job numbers, odd paths, GET, POST and other methods. Every answer
must be a real success or nova's JSON error with a status of ``ALLOWED``, never a 500.

A fixed profile (derandomized, a bounded number of examples) keeps it repeatable."""

from __future__ import annotations

import json
import logging
import urllib.parse

import pytest

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.testclient import TestClient

from service_helpers import wait_for_job
from starnav.service.app import ServiceConfig, create_app
from starnav.service.errors import MAX_JSON_DEPTH

pytestmark = pytest.mark.service

API_KEY = "fuzz key"
ALLOWED = {200, 400, 404, 405, 413, 429, 503}
MAX_UPLOAD = 2_000_000  # over request-json's own limit (1 MB)
FUZZ = settings(max_examples=400, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])  # fmt: skip

JOB_ROUTES = ["/api/submissions/{}", "/api/jobs/{}", "/api/jobs/{}/calibration",
              "/api/jobs/{}/info", "/api/jobs/{}/annotations", "/api/jobs/{}/tags",
              "/api/jobs/{}/machine_tags", "/api/jobs/{}/objects_in_field",
              "/api/jobs/{}/starnav", "/wcs_file/{}", "/new_fits_file/{}", "/corr_file/{}",
              "/rdls_file/{}", "/axy_file/{}", "/kml_file/{}", "/annotated_display/{}",
              "/annotated_full/{}", "/json_file/{}"]  # fmt: skip
JSON_ROUTES = ["/api/login", "/api/upload", "/api/url_upload", "/api/myjobs", "/api/status"]
NOVA_KEYS = ["session", "apikey", "x", "y", "image_width", "image_height", "url",
             "publicly_visible", "scale_units", "scale_type", "scale_lower", "scale_upper",
             "scale_est", "scale_err", "center_ra", "center_dec", "radius", "parity",
             "downsample_factor", "positional_error", "crpix_center"]  # fmt: skip
CONTENT_TYPES = ["application/x-www-form-urlencoded", "multipart/form-data",
                 "multipart/form-data; boundary=xyz", "application/json",
                 "application/octet-stream", "text/plain; charset=utf-16"]  # fmt: skip
PRINTABLE_ASCII = st.characters(min_codepoint=32, max_codepoint=126)
ODD = ["\ud800", "\udfff", "\x00", "\u202e", "\u200f", "\ufeff", "\U0010ffff", "\\", '"', "é"]

odd_text = st.text(st.one_of(st.characters(), st.sampled_from(ODD)), max_size=30)
numbers = st.one_of(
    st.integers(),
    st.integers(min_value=2**63 - 2, max_value=2**70),
    st.integers(max_value=-(2**63)),
    st.floats(allow_nan=True, allow_infinity=True),
)
json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), numbers, odd_text),
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(st.one_of(st.sampled_from(NOVA_KEYS), odd_text), inner, max_size=5),
    ),
    max_leaves=20,
)
job_numbers = st.one_of(
    st.integers(min_value=-3, max_value=6).map(str),
    st.sampled_from([str(2**63 - 1), str(2**63), str(2**64), "9" * 25, "9" * 5000, "-0"]),
    st.text("0123456789-+.eE x%", min_size=1, max_size=12),
)
methods = st.sampled_from(["GET", "POST", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", "HEAD"])


@pytest.fixture(scope="module")
def app_client(tmp_path_factory):
    """The service with an API key and one worker process (a 1 s budget: a random source list
    that is queued costs little), raising nothing to the test: a 500 is seen as one. Job 1 is
    private, job 2 public (source lists of the fuzz's session)."""
    config = ServiceConfig(data_dir=tmp_path_factory.mktemp("fuzz"), workers=1, api_key=API_KEY,
                           max_upload_bytes=MAX_UPLOAD, time_budget_s=1.0)  # fmt: skip
    with TestClient(create_app(config), raise_server_exceptions=False) as client:
        client.session_key = client.post(
            "/api/login", data={"request-json": json.dumps({"apikey": API_KEY})}
        ).json()["session"]
        client.cookies.clear()  # the login's cookie: sent only where a test says so
        for visible in ("n", "y"):
            args = {"session": client.session_key, "x": [1, 2, 3, 4, 5], "y": [5, 1, 4, 2, 3],
                    "image_width": 10, "image_height": 10, "publicly_visible": visible}  # fmt: skip
            client.post("/api/url_upload", data={"request-json": json.dumps(args)})
        assert client.get("/api/jobs/1").status_code == 404  # private
        assert client.get(f"/api/jobs/1?session={client.session_key}").status_code == 200
        yield client


def check(r, *, json_only: bool = True) -> None:
    """An answer in the allowed set: nova's JSON error, or a success (JSON for an API route,
    a file or the page otherwise)."""
    assert r.status_code in ALLOWED, (r.status_code, r.text[:300])
    is_json = r.headers.get("content-type", "").startswith("text/plain")
    if r.status_code != 200 or json_only:
        assert is_json, (r.status_code, r.headers.get("content-type"), r.content[:100])
    if is_json and r.request.method != "HEAD":
        answer = json.loads(r.content.decode("ascii"))  # nova's JSON is ASCII
        assert isinstance(answer, dict)
        if r.status_code != 200 or answer.get("status") == "error":
            assert answer["status"] == "error" and isinstance(answer["errormessage"], str)
            assert answer["errormessage"] and "\n" not in answer["errormessage"]


def _json_text(value, raw: str | None) -> str:
    return raw if raw is not None else json.dumps(value)


def _bytes(text: str) -> bytes:
    """``text`` as a client may send it: UTF-8, a lone surrogate as its (invalid) bytes."""
    return text.encode("utf-8", "surrogatepass")


def urlencoded(pairs: dict) -> str:
    """A query string or form body of ``pairs``, percent-encoded from ``_bytes``."""
    quote = lambda t: urllib.parse.quote_plus(_bytes(t))  # noqa: E731
    return "&".join(f"{quote(k)}={quote(v)}" for k, v in pairs.items())


def multipart(request_json: str, filename: str, data: bytes, eol: bytes = b"\r\n") -> dict:
    """A multipart body (a ``request-json`` field and a ``file`` part named ``filename``) as
    the bytes a client sends, however odd the name (``eol`` b"\\n": the bare line ends of
    astrometry.net's client.py): the request's keyword arguments."""
    boundary = b"fuzzboundary7"
    head = b"Content-Disposition: form-data; "
    name = _bytes(filename).replace(b'"', b"%22").replace(b"\r", b"").replace(b"\n", b"")
    body = (b"--" + boundary + eol + head + b'name="request-json"' + eol + eol
            + _bytes(request_json) + eol + b"--" + boundary + eol + head
            + b'name="file"; filename="' + name + b'"' + eol + eol + data + eol + b"--"
            + boundary + b"--" + eol)  # fmt: skip
    content_type = "multipart/form-data; boundary=" + boundary.decode()
    return {"content": body, "headers": {"content-type": content_type}}


@FUZZ
@given(
    route=st.sampled_from(JSON_ROUTES + [r.format(1) for r in JOB_ROUTES[:3]]),
    args=st.one_of(json_values, st.dictionaries(st.sampled_from(NOVA_KEYS), json_values)),
    raw=st.one_of(st.none(), odd_text, st.integers(1, 5000).map(lambda n: "[" * n + "]" * n)),
    with_session=st.booleans(),
    channel=st.sampled_from(["query", "form", "multipart", "multipart-file"]),
    method=st.sampled_from(["GET", "POST"]),
)
def test_random_request_json(app_client, route, args, raw, with_session, channel, method):
    """Random ``request-json`` (or raw text in its place) in the query string, a URL-encoded
    body, a multipart field or a multipart file part named so."""
    if with_session and isinstance(args, dict) and raw is None:
        args = {**args, "session": app_client.session_key}
    text = _json_text(args, raw)
    kw: dict = {}
    if channel == "query" or method == "GET":
        route += "?" + urlencoded({"request-json": text})
    elif channel == "form":
        form_type = "application/x-www-form-urlencoded"
        kw.update(content=urlencoded({"request-json": text}), headers={"content-type": form_type})
    elif channel == "multipart":
        kw.update(multipart(text, "a.fits", b"SIMPLE  = junk"))
    else:
        kw["files"] = {"request-json": ("r.json", _bytes(text))}
    check(app_client.request(method, route, **kw))


@FUZZ
@given(
    route=st.sampled_from(JSON_ROUTES + JOB_ROUTES),
    body=st.one_of(st.binary(max_size=2000), st.just(b"\0" * (MAX_UPLOAD + 1))),
    content_type=st.one_of(st.sampled_from(CONTENT_TYPES), st.text(PRINTABLE_ASCII, max_size=40)),
    as_file=st.booleans(),
    filename=odd_text,
    eol=st.sampled_from([b"\r\n", b"\n"]),
)
def test_random_bodies_and_files(app_client, route, body, content_type, as_file, filename, eol):
    """Random bytes as the whole body (any content type), or as the multipart ``file`` of an
    upload with a good session (a random file name too; line ends CRLF or LF)."""
    route = route.format(1)
    if as_file:
        args = json.dumps({"session": app_client.session_key, "publicly_visible": "n"})
        r = app_client.post(route, **multipart(args, filename, body, eol))
    else:
        r = app_client.post(route, content=body, headers={"content-type": content_type})
    check(r, json_only=route in JSON_ROUTES)


@FUZZ
@given(
    route=st.sampled_from(JOB_ROUTES + JSON_ROUTES + ["/", "/static/{}", "/{}", "/api/{}"]),
    number=st.one_of(job_numbers, odd_text.filter(lambda t: "/" not in t)),
    query=st.one_of(st.none(), odd_text, st.dictionaries(odd_text, odd_text, max_size=3)),
    method=methods,
    slash=st.booleans(),
    cookie=st.one_of(st.none(), st.text(PRINTABLE_ASCII, max_size=60)),
    own=st.booleans(),
)
def test_random_paths_ids_and_queries(app_client, route, number, query, method, slash, cookie,
                                      own):  # fmt: skip
    """Job numbers (huge, negative, not numbers), odd paths and query strings, any method,
    a random Cookie header (read for job 1, which is private), the job's own session in the
    query string or not."""
    segment = urllib.parse.quote(number.encode("utf-8", "surrogatepass"), safe="")
    path = route.format(segment) + ("/" if slash else "")
    if isinstance(query, dict):
        path += "?" + urlencoded({**query, **({"session": app_client.session_key} if own else {})})
    elif query is not None:  # raw: its own & and = (and anything else as bytes)
        path += "?" + urllib.parse.quote(_bytes(query), safe="&=")
    headers = {} if cookie is None else {"cookie": cookie}
    r = app_client.request(method, path, headers=headers)
    check(r, json_only=route.startswith("/api/"))


def test_each_known_crash_is_answered(app_client):
    """The inputs that answered a plain-text 500 before, each with its clear answer."""
    deep = "[" * 100_000 + "]" * 100_000  # Python's JSON reader gives up at 1000
    r = app_client.post("/api/login", data={"request-json": deep})
    assert r.status_code == 400
    assert r.json()["errormessage"] == f"request-json is nested deeper than {MAX_JSON_DEPTH} levels"
    r = app_client.post("/api/upload", data={"request-json": json.dumps({"session": "\ud800"})})
    assert r.status_code == 200  # nova's answer: clients log in again on it
    assert r.json()["errormessage"] == 'no session with key "\\ud800"'
    for number in (2**63 - 1, 2**63, 10**30, -1):
        r = app_client.get(f"/api/jobs/{number}")
        assert (r.status_code, r.json()["errormessage"]) == (404, "no such job")
    r = app_client.get("/no/such/route")
    assert (r.status_code, r.json()["errormessage"]) == (404, "no such route: /no/such/route")
    r = app_client.delete("/api/upload")
    assert r.status_code == 405
    assert r.json()["errormessage"] == "DELETE is not allowed on /api/upload"
    big = json.dumps({"apikey": "k", "pad": "x" * (1 << 20)})
    r = app_client.post("/api/login", files={"request-json": ("r.json", big.encode())})
    assert r.status_code == 413 and "request-json is 1.0 MB" in r.json()["errormessage"]
    r = app_client.post("/api/login", data={"request-json": '{"apikey": NaN}'})
    assert r.json()["errormessage"].startswith("failed to parse JSON")


def test_a_job_with_odd_unicode_everywhere_ends_with_its_reason(app_client):
    """A file name and hints with a lone surrogate, NUL and a right-to-left mark: the job is
    stored, run by the worker and failed with its reason (none of it is lost on the way)."""
    args = {"session": app_client.session_key, "scale_units": "\ud800\x00\u202e",
            "scale_lower": 1, "scale_upper": 2}  # fmt: skip
    for eol in (b"\r\n", b"\n"):  # python-multipart's reader, and the lenient one
        body = multipart(json.dumps(args), "\ud800\x00\u202eevil.png", b"not an image", eol)
        r = app_client.post("/api/upload", **body)
        assert r.json()["status"] == "success", r.text
        job_id = r.json()["subid"]
        job = wait_for_job(app_client, job_id)  # public ("y" by default): no session needed
        assert job["status"] == "failure" and job["reason"], job
        name = app_client.get(f"/api/jobs/{job_id}/info").json()["original_filename"]
        assert name.endswith("evil.png") and name.isprintable(), name


def test_last_resort_handler_answers_json_500(tmp_path, caplog):
    """A bug (here a route added to the real app that raises) is answered nova's JSON 500
    "internal error" and logged; the fuzz above never sees one."""
    app = create_app(ServiceConfig(data_dir=tmp_path))

    async def broken(request):
        raise ZeroDivisionError("a bug")

    app.router.add_route("/broken", broken)
    with caplog.at_level(logging.ERROR, logger="starnav.service"):
        r = TestClient(app, raise_server_exceptions=False).get("/broken")
    assert r.status_code == 500
    assert r.json() == {"status": "error", "errormessage": "internal error"}
    assert "internal error answering GET /broken: ZeroDivisionError: a bug" in caplog.text
