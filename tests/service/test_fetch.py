"""URL uploads under attack (``starnav.service.fetch``), with real sockets on the loopback:
image hosts are ``http.server`` threads in the test that count the requests they see. A
server that drips its answer a byte at a time fails within the whole-fetch deadline while
other uploads are answered; many of them at once get 503 "busy"; a body over the size cap is
refused; and no request reaches a loopback, private, link-local, metadata or otherwise
non-public address (nor one a redirect or a second DNS answer points to) unless the operator
allows it with ``--allow-url-hosts``. The last tests run the real ``starnav serve``."""

from __future__ import annotations

import contextlib
import http.server
import io
import json
import shutil
import socket
import ssl
import subprocess
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from email.message import Message

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("starlette", reason="the serve extra is not installed: pip install '.[serve]'")

from service_helpers import Server, login, upload_image, wait_done
from starnav.cli import main as cli_main
from starnav.errors import StarnavError
from starnav.service.fetch import (
    AllowedHosts,
    FetchError,
    FetchPolicy,
    fetch_url,
    not_public,
)

pytestmark = pytest.mark.service

DEADLINE_S = 2.0  # the fetches' deadline in the tests of fetch_url
SERVER_DEADLINE_S = 4.0  # starnav serve's --url-timeout here (room for a busy machine)
DRIP_S = 0.4  # a byte every DRIP_S seconds, for DRIP_BYTES bytes: a minute without a deadline
DRIP_BYTES = 150
CAP = 10_000  # bytes, the size cap of the fetches here
GENEROUS_S = 15.0  # an upper bound only to show that a deadline exists (a busy machine)
REFUSED = "this server does not fetch from such hosts"


def _png() -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("L", (64, 48)).save(buf, format="PNG")
    return buf.getvalue()


class _Handler(http.server.BaseHTTPRequestHandler):
    """``/image``: a small PNG; ``/big``: CAP + 1 bytes with their length, ``/big-unsized``
    without (the end of the body is the end of the connection); ``/drip``: the head at once,
    then a byte every DRIP_S; ``/drip-head``: the status line itself a byte at a time;
    ``/redirect?to=URL``: 302 to URL; ``/loop``: 302 to itself; anything else 404."""

    def do_GET(self):
        host: ImageHost = self.server.host
        path, _, query = self.path.partition("?")
        host.seen(path, self.headers.get("Host"))
        host.add_open(+1)
        try:
            self._answer(path, urllib.parse.parse_qs(query))
        except OSError:  # the client gave up (a deadline): nothing more to send
            pass
        finally:
            host.add_open(-1)

    def _answer(self, path: str, query: dict) -> None:
        if path == "/image":
            return self._send(200, self.server.host.image)
        if path == "/big":
            return self._send(200, b"\0" * (CAP + 1))
        if path == "/big-unsized":
            self.close_connection = True
            self.send_response(200)
            self.end_headers()
            for _ in range(CAP // 1000 + 2):
                self.wfile.write(b"\0" * 1000)
            return
        if path in ("/redirect", "/loop"):
            self.send_response(302)
            self.send_header("Location", query["to"][0] if path == "/redirect" else "/loop")
            self.send_header("Content-Length", "0")
            return self.end_headers()
        if path == "/drip":
            self.send_response(200)
            self.send_header("Content-Length", str(DRIP_BYTES))
            self.end_headers()
            return self._drip(b"x" * DRIP_BYTES)
        if path == "/drip-head":
            return self._drip(
                f"HTTP/1.0 200 OK\r\nContent-Length: 1\r\n{'X: y' * 30}\r\n\r\nx".encode()
            )
        return self._send(404, b"no such file")

    def _send(self, status: int, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def _drip(self, data: bytes) -> None:
        for k in range(len(data)):
            self.wfile.write(data[k : k + 1])
            self.wfile.flush()
            time.sleep(DRIP_S)

    def log_message(self, *args):
        pass


class ImageHost:
    """An HTTP server on ``address`` (a loopback address) in a thread of the test: ``url``,
    ``requests`` it has seen (path, Host header), ``open`` the answers it is sending now."""

    def __init__(self, address: str = "127.0.0.1"):
        family = socket.AF_INET6 if ":" in address else socket.AF_INET
        server_class = type(
            "Server", (http.server.ThreadingHTTPServer,), {"address_family": family}
        )
        self.httpd = server_class((address, 0), _Handler)
        self.httpd.host = self
        self.port = self.httpd.server_address[1]
        shown = f"[{address}]" if family == socket.AF_INET6 else address
        self.url = f"http://{shown}:{self.port}"
        self.image = _png()
        self.requests: list[tuple[str, str | None]] = []
        self.open = 0
        self._lock = threading.Condition()
        threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True).start()

    def seen(self, path: str, host_header: str | None) -> None:
        with self._lock:
            self.requests.append((path, host_header))

    def add_open(self, delta: int) -> None:
        with self._lock:
            self.open += delta
            self._lock.notify_all()

    def wait_open(self, count: int, timeout_s: float = 30.0) -> None:
        with self._lock:
            assert self._lock.wait_for(lambda: self.open >= count, timeout_s), self.open

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture
def host():
    h = ImageHost("127.0.0.1")
    yield h
    h.close()


@pytest.fixture
def other_host():
    """A second loopback host, 127.0.0.2 (outside 127.0.0.1/32)."""
    h = ImageHost("127.0.0.2")
    yield h
    h.close()


@pytest.fixture
def host6():
    """A host on ::1, None without IPv6 on the loopback."""
    try:
        h = ImageHost("::1")
    except OSError:
        yield None
        return
    yield h
    h.close()


def _policy(allow: str = "", deadline_s: float = DEADLINE_S) -> FetchPolicy:
    return FetchPolicy(CAP, deadline_s, AllowedHosts.parse(allow))


# --- fetch_url: limits ------------------------------------------------------------------


def test_an_allowed_loopback_host_is_fetched_with_the_urls_host_header(host):
    assert fetch_url(f"{host.url}/image", _policy("127.0.0.1")) == host.image
    assert host.requests == [("/image", f"127.0.0.1:{host.port}")]
    # by name: connected to the address checked, the Host header is the name
    assert fetch_url(f"http://LocalHost:{host.port}/image", _policy("localhost")) == host.image
    assert host.requests[-1] == ("/image", f"localhost:{host.port}")


@pytest.mark.parametrize("path", ["/drip", "/drip-head"])
def test_a_dripping_server_fails_at_the_whole_fetch_deadline(host, path):
    t0 = time.monotonic()
    with pytest.raises(FetchError, match=f"no whole answer within {DEADLINE_S:g} s"):
        fetch_url(f"{host.url}{path}", _policy("127.0.0.1"))
    elapsed = time.monotonic() - t0
    assert DEADLINE_S * 0.99 <= elapsed < DEADLINE_S + GENEROUS_S  # the drip lasts a minute


@pytest.mark.parametrize("path", ["/big", "/big-unsized"])
def test_a_body_over_the_cap_is_refused(host, path):
    with pytest.raises(FetchError, match=f"larger than this server's limit of {CAP / 1e6:g} MB"):
        fetch_url(f"{host.url}{path}", _policy("127.0.0.1"))


def test_http_errors_and_redirects(host):
    policy = _policy("127.0.0.1")
    with pytest.raises(FetchError, match="the server answered HTTP 404 Not Found"):
        fetch_url(f"{host.url}/nothing-here", policy)
    # a relative Location, followed
    assert fetch_url(f"{host.url}/redirect?to=/image", policy) == host.image
    host.requests.clear()
    with pytest.raises(FetchError, match="more than 5 redirects"):
        fetch_url(f"{host.url}/loop", policy)
    assert len(host.requests) == 6


# --- fetch_url: no requests to addresses that are not public ----------------------------


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("http://127.0.0.1:{port}/image", "127.0.0.1 is a loopback address"),
        ("http://localhost:{port}/image", "localhost resolves to (127.0.0.1|::1), a loopback"),
        ("http://127.1:{port}/image", "127.1 resolves to 127.0.0.1, a loopback address"),
        ("http://2130706433:{port}/image", "resolves to 127.0.0.1, a loopback address"),
        ("http://0.0.0.0:{port}/image", "0.0.0.0 is an unspecified address"),
        ("http://[::ffff:127.0.0.1]:{port}/image", "an IPv6 form of 127.0.0.1, a loopback"),
        ("http://[::1]:{port6}/image", "::1 is a loopback address"),
        ("http://10.1.2.3/", "10.1.2.3 is a private address"),
        ("http://192.168.0.1/", "a private address"),
        ("http://169.254.169.254/latest/meta-data/", "a cloud metadata address"),
        ("http://[fd00:ec2::254]/latest/meta-data/", "a cloud metadata address"),
        ("http://[::ffff:169.254.169.254]/", "an IPv6 form of 169.254.169.254, a cloud metadata"),
        ("http://[64:ff9b::a9fe:a9fe]/", "an IPv6 form of 169.254.169.254"),
        ("http://169.254.1.1/", "a link-local address"),
        ("http://[fe80::1]/", "a link-local address"),
        ("http://100.64.0.1/", "a carrier-grade NAT address"),
        ("http://224.0.0.1/", "a multicast address"),
        ("http://240.0.0.1/", "a reserved address"),
        ("http://[fc00::1]/", r"a private \(unique local\) address"),
    ],
)
def test_non_public_addresses_are_refused_before_any_connection(host, host6, url, says):
    if host6 is None and "{port6}" in url:
        pytest.skip("no IPv6 on the loopback")
    url = url.format(port=host.port, port6=host6.port if host6 else 0)
    with pytest.raises(FetchError, match=f"{says}.*{REFUSED}.*--allow-url-hosts"):
        fetch_url(url, _policy())
    assert host.requests == [] and (host6 is None or host6.requests == [])


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("http://user:secret@127.0.0.1:{port}/image", "with a user name or password"),
        ("ftp://127.0.0.1:{port}/image", "only http and https URLs are fetched, not 'ftp'"),
        ("file:///etc/passwd", "only http and https URLs are fetched, not 'file'"),
        ("http://127.0.0.1:99999/image", "not a valid URL: Port out of range"),
        ("http:///image", "the URL has no host"),
        ("http://127.0.0.1:0/image", "not a valid URL: port 0"),
        ("http://127.0.0.1:{port}/\ud800", "a character that is not text"),
    ],
)
def test_other_urls_are_refused(host, url, says):
    with pytest.raises(FetchError, match=says):
        fetch_url(url.format(port=host.port), _policy("127.0.0.1"))
    assert host.requests == []


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    netloc=st.sampled_from(["127.0.0.1:{port}", "[::ffff:127.0.0.1]:{port}", "0.0.0.0:{port}",
                            "169.254.169.254", "[fd00:ec2::254]", "10.0.0.1"]),
    tail=st.tuples(st.sampled_from("/?#:@"), st.text()).map("".join),
)  # fmt: skip
def test_any_url_to_these_hosts_is_refused_with_a_message(host, netloc, tail):
    """Whatever follows an internal host (path, query, port, user info, odd characters):
    a FetchError, never another exception, and no request."""
    with pytest.raises(FetchError):
        fetch_url(f"http://{netloc.format(port=host.port)}{tail}", _policy())
    assert host.requests == []


@pytest.mark.parametrize(
    ("target", "says"),
    [
        ("http://127.0.0.2:{other}/image", "127.0.0.2 is a loopback address"),
        ("http://[::1]:{other}/image", "::1 is a loopback address"),
        ("http://10.0.0.1/image", "10.0.0.1 is a private address"),
        ("http://169.254.169.254/", "a cloud metadata address"),
        ("file:///etc/passwd", "only http and https"),
    ],
)
def test_a_redirect_is_checked_like_the_first_url(host, other_host, target, says):
    """127.0.0.1 is allowed; its redirects to other loopback addresses and internal hosts
    are not followed."""
    target = urllib.parse.quote(target.format(other=other_host.port), safe="")
    with pytest.raises(FetchError, match=says):
        fetch_url(f"{host.url}/redirect?to={target}", _policy("127.0.0.1/32"))
    assert [path for path, _ in host.requests] == ["/redirect"]
    assert other_host.requests == []


def test_the_name_is_resolved_once(host, other_host, monkeypatch):
    """A DNS answer that changes after the check (rebinding): the connection goes to the
    address that was checked. The resolver answers the real address first, then
    127.0.0.2 (not allowed), which a second lookup would connect to."""
    real = socket.getaddrinfo
    calls = []

    def rebinding(name, port, *args, **kwargs):
        calls.append(name)
        return real(name if len(calls) == 1 else "127.0.0.2", port, *args, **kwargs)

    monkeypatch.setattr(socket, "getaddrinfo", rebinding)
    assert fetch_url(f"http://localhost:{host.port}/image", _policy("127.0.0.1/32")) == host.image
    assert calls == ["localhost"] and other_host.requests == []


def test_tls_goes_to_the_checked_address_with_the_names_sni(tmp_path):
    """An https URL by name: the TLS handshake reaches the address checked with the URL's
    host as its server name, and a certificate no authority signed is refused."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is not installed (to make a test certificate)")
    key, cert = tmp_path / "key.pem", tmp_path / "cert.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", str(key), "-out",
                    str(cert), "-days", "1", "-subj", "/CN=localhost"],
                   check=True, capture_output=True)  # fmt: skip
    names = []
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(cert, key)
    context.sni_callback = lambda sock, name, ctx: names.append(name)
    with socket.create_server(("127.0.0.1", 0)) as listener:
        port = listener.getsockname()[1]

        def serve():
            conn, _ = listener.accept()
            with conn, contextlib.suppress(OSError):  # the client refuses the certificate
                context.wrap_socket(conn, server_side=True)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        with pytest.raises(FetchError, match="certificate verify failed"):
            fetch_url(f"https://localhost:{port}/image", _policy("localhost"))
        thread.join(10)
    assert names == ["localhost"]


def test_not_public_and_the_allow_list():
    import ipaddress

    assert not_public(ipaddress.ip_address("93.184.215.14")) is None  # a public address
    assert not_public(ipaddress.ip_address("2606:4700::1")) is None
    assert not_public(ipaddress.ip_address("::127.0.0.1")) == "a reserved address"
    six_to_four = not_public(ipaddress.ip_address("2002:a00:1::"))
    assert six_to_four == "an IPv6 form of 10.0.0.1, a private address"
    allowed = AllowedHosts.parse(" Images.Example.org., 10.0.0.0/8,[::1], 192.168.1.7 ,")
    assert allowed.names == {"images.example.org"}
    assert allowed.allows(ipaddress.ip_address("10.20.30.40"))
    assert allowed.allows(ipaddress.ip_address("::1"))
    assert allowed.allows(ipaddress.ip_address("192.168.1.7"))
    assert not allowed.allows(ipaddress.ip_address("192.168.1.8"))
    for bad, says in (("10.0.0.1/8", "has host bits set"), ("a b", "neither a host name"),
                      ("::1/200", "::1/200"), ("-x", "neither")):  # fmt: skip
        with pytest.raises(StarnavError, match=says):
            AllowedHosts.parse(bad)


def test_serve_refuses_a_bad_allow_list_in_one_line(tmp_path, capsys):
    argv = ["serve", "--data-dir", str(tmp_path / "d"), "--allow-url-hosts", "localhost,10.0.0.1/8"]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "10.0.0.1/8 has host bits set" in err
    assert not (tmp_path / "d").exists()


# --- the real server --------------------------------------------------------------------


def _post(url: str, service: str, args: dict) -> tuple[int, Message, dict]:
    """(HTTP status, headers, JSON) of nova's form POST, an error status included."""
    data = urllib.parse.urlencode({"request-json": json.dumps(args)}).encode()
    try:
        with urllib.request.urlopen(f"{url}/api/{service}", data, timeout=60) as resp:
            return resp.status, resp.headers, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers, json.loads(exc.read())


@pytest.fixture(scope="module")
def fetching_server(tmp_path_factory):
    """``starnav serve`` allowing 127.0.0.1, with a short fetch deadline."""
    options = ("--allow-url-hosts", "127.0.0.1", "--url-timeout", str(SERVER_DEADLINE_S))
    server = Server(tmp_path_factory.mktemp("fetch") / "data", workers=1, options=options)
    yield server.start()
    server.stop()


def _url_upload(server: Server, session: str, url: str) -> tuple[float, int, dict, dict]:
    t0 = time.monotonic()
    status, headers, answer = _post(server.url, "url_upload", {"session": session, "url": url})
    return time.monotonic() - t0, status, headers, answer


def test_a_drip_fails_at_the_deadline_while_a_good_url_upload_is_served(fetching_server, host):
    session = login(fetching_server.url)
    result = {}
    drip = threading.Thread(target=lambda: result.update(
        drip=_url_upload(fetching_server, session, f"{host.url}/drip")))  # fmt: skip
    drip.start()
    host.wait_open(1)
    _, status, _, good = _url_upload(fetching_server, session, f"{host.url}/image")
    assert "drip" not in result, "the good upload waited for the drip"
    assert status == 200 and good["status"] == "success", good
    stored = fetching_server.data_dir / "jobs" / str(good["subid"]) / "input.png"
    assert stored.read_bytes() == host.image
    drip.join(SERVER_DEADLINE_S + GENEROUS_S)
    elapsed, status, _, answer = result["drip"]
    assert answer == {"status": "error", "errormessage": f"cannot fetch {host.url}/drip: "
                      f"no whole answer within {SERVER_DEADLINE_S:g} s, this server's limit "
                      "for fetching a URL"}  # fmt: skip
    assert elapsed < SERVER_DEADLINE_S + GENEROUS_S  # the drip lasts a minute


def test_many_drips_get_busy_while_file_uploads_go_through(fetching_server, host):
    """Eight dripping URLs at once: four fetch slots, the rest told 503 "busy" with a
    Retry-After (after at most a second's wait); a file upload meanwhile is answered at once,
    and once the drips are over a URL upload is fetched again."""
    session = login(fetching_server.url)
    results = []

    def one(k: int) -> None:
        results.append(_url_upload(fetching_server, session, f"{host.url}/drip?n={k}"))

    threads = [threading.Thread(target=one, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    host.wait_open(4)
    job_id = upload_image(fetching_server.url, session, "small.png", host.image)
    assert any(t.is_alive() for t in threads), "the file upload waited for the drips"
    for t in threads:
        t.join(SERVER_DEADLINE_S + GENEROUS_S)
    busy = [r for r in results if r[1] == 503]
    timed_out = [r for r in results if r[1] == 200]
    assert len(busy) + len(timed_out) == 8 and busy and timed_out
    for _, _, headers, answer in busy:
        assert headers.get("Retry-After") == "5" and answer["status"] == "error"
        assert answer["errormessage"].startswith("busy: all 4 URL fetch slots are taken")
    for _, _, _, answer in timed_out:
        assert f"no whole answer within {SERVER_DEADLINE_S:g} s" in answer["errormessage"]
    assert sum(path == "/drip" for path, _ in host.requests) == len(timed_out)
    _, status, _, good = _url_upload(fetching_server, session, f"{host.url}/image")
    assert status == 200 and good["status"] == "success", good
    assert wait_done(fetching_server.url, job_id) == "failure"  # 64 x 48 black: no stars


def test_the_job_queue_is_bounded_and_internal_urls_refused(tmp_path, host):
    """Without --allow-url-hosts the loopback image host is refused, unasked; with
    --max-queued 1, an upload while a job waits for the one worker is told 503 busy."""
    server = Server(tmp_path / "data", workers=1, options=("--max-queued", "1")).start()
    try:
        session = login(server.url)
        _, status, _, answer = _url_upload(server, session, f"{host.url}/image")
        assert answer["status"] == "error" and REFUSED in answer["errormessage"], answer
        assert "127.0.0.1 is a loopback address" in answer["errormessage"]
        assert host.requests == []
        status, _, answer = _post(server.url, "url_upload",
                                  {"session": session, "url": "http://\ud800/"})  # fmt: skip
        assert status in (200, 400) and answer["status"] == "error", answer  # no plain 500
        xy = {"session": session, "x": [10.0, 20.0], "y": [15.0, 25.0], "image_width": 64,
              "image_height": 48}  # fmt: skip
        answers = [_post(server.url, "url_upload", xy) for _ in range(3)]
        # the first solving (a fresh worker takes seconds to start), the second waiting
        assert [status for status, _, _ in answers] == [200, 200, 503], answers
        assert answers[2][1].get("Retry-After") == "5"
        assert answers[2][2]["errormessage"] == (
            "busy: 1 job waits for a worker, this server's limit (--max-queued); try again later"
        )
        for _, _, answer in answers[:2]:
            assert wait_done(server.url, answer["subid"]) == "failure"  # two stars
        status, _, answer = _post(server.url, "url_upload", xy)  # room again
        assert status == 200 and answer["status"] == "success", answer
    finally:
        server.stop()
