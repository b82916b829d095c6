"""URL uploads fetched with limits: a whole-fetch deadline, a size cap, a bounded queue, and
no requests to addresses that are not public unless the operator allows them.

``fetch_url`` (blocking) resolves the URL's host once, refuses it when any of its addresses
is loopback, private, link-local, unspecified, multicast, reserved, carrier-grade NAT, a
cloud metadata address or an IPv4 one of those inside an IPv6 form (``not_public``), then
connects to the address it checked (the Host header and TLS name are the URL's), so a second
DNS answer cannot send the request elsewhere. Every socket operation's timeout is what is
left of the one deadline: connect, TLS handshake, request, headers and body together.
Redirects are followed by hand, each hop checked the same way. ``FetchQueue`` runs fetches
in threads of its own, a few at once, and answers ``FetchBusy`` rather than letting requests
pile up behind slow servers.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import http.client
import io
import ipaddress
import re
import socket
import ssl
import threading
import time
import urllib.parse
from dataclasses import dataclass, field

from starnav.errors import StarnavError
from starnav.runtime.limits import DEFAULT_URL_DEADLINE_S, DEFAULT_URL_FETCHES

QUEUE_WAIT_S = 1.0  # the longest a URL upload waits for a fetch slot before it is told "busy"
MAX_REDIRECTS = 5
READ_CHUNK = 1 << 16
# an answer past the deadline when the fetch's thread is stuck where no socket timeout
# reaches (the system's name resolver)
DEADLINE_GRACE_S = 1.0
REDIRECTS = (301, 302, 303, 307, 308)
USER_AGENT = "starnav-serve"
# the characters left as they are when a URL's path and query are percent-encoded
_URL_SAFE = "/%:@!$&'()*+,;=-._~?"
_LABEL = r"[a-z0-9_]([a-z0-9_-]{0,61}[a-z0-9_])?"
_HOST_NAME = re.compile(rf"^(?=.{{1,253}}$){_LABEL}(\.{_LABEL})*$")

IPNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address

_METADATA = {ipaddress.ip_address("169.254.169.254"), ipaddress.ip_address("fd00:ec2::254"),
             ipaddress.ip_address("100.100.100.200")}  # fmt: skip
_NOT_PUBLIC = tuple(
    (ipaddress.ip_network(net), what)
    for net, what in (
        ("0.0.0.0/8", "an unspecified address"),
        ("10.0.0.0/8", "a private address"),
        ("100.64.0.0/10", "a carrier-grade NAT address"),
        ("127.0.0.0/8", "a loopback address"),
        ("169.254.0.0/16", "a link-local address"),
        ("172.16.0.0/12", "a private address"),
        ("192.0.0.0/24", "an IETF protocol address"),
        ("192.0.2.0/24", "a documentation address"),
        ("192.88.99.0/24", "a 6to4 relay address"),
        ("192.168.0.0/16", "a private address"),
        ("198.18.0.0/15", "a benchmarking address"),
        ("198.51.100.0/24", "a documentation address"),
        ("203.0.113.0/24", "a documentation address"),
        ("224.0.0.0/4", "a multicast address"),
        ("240.0.0.0/4", "a reserved address"),
        ("::/128", "an unspecified address"),
        ("::1/128", "a loopback address"),
        ("::/8", "a reserved address"),
        ("64:ff9b:1::/48", "a local NAT64 address"),
        ("100::/64", "a discard address"),
        ("2001::/23", "an IETF protocol address"),
        ("2001:db8::/32", "a documentation address"),
        ("fc00::/7", "a private (unique local) address"),
        ("fe80::/10", "a link-local address"),
        ("fec0::/10", "a site-local address"),
        ("ff00::/8", "a multicast address"),
    )
)
_NAT64 = ipaddress.ip_network("64:ff9b::/96")


class FetchError(StarnavError):
    """A URL the service will not or cannot fetch; the message says why."""


class FetchBusy(Exception):
    """Every fetch slot is taken and the wait for one is full or over: try again later."""


def not_public(ip: IPAddress) -> str | None:
    """What kind of address ``ip`` is when it is not a public one ("a loopback address",
    ...; an IPv4 address inside an IPv6 form as the IPv4 one), None for a public address."""
    if ip in _METADATA:
        return "a cloud metadata address"
    if ip.version == 6:
        inner = ip.ipv4_mapped or ip.sixtofour
        if inner is None and ip in _NAT64:
            inner = ipaddress.IPv4Address(int(ip) & 0xFFFFFFFF)
        if inner is not None:
            what = not_public(inner)
            return None if what is None else f"an IPv6 form of {inner}, {what}"
    for network, what in _NOT_PUBLIC:
        if ip in network:
            return what
    return None if ip.is_global else "not a public address"


@dataclass(frozen=True)
class AllowedHosts:
    """Hosts a URL upload may reach although they are not public (``--allow-url-hosts``):
    ``names``, exact host names as the URL spells them (any case, no wildcards; every
    address the name resolves to is then accepted), and ``networks``, address ranges that
    the addresses a URL's host resolves to (or is) may fall in."""

    names: frozenset[str] = frozenset()
    networks: tuple[IPNetwork, ...] = ()

    @classmethod
    def parse(cls, text: str) -> AllowedHosts:
        """From a comma-separated list of host names, addresses and CIDR networks
        (``localhost,10.0.0.0/8,::1``); ``StarnavError`` naming an item that is neither."""
        names, networks = set(), []
        for item in (part.strip() for part in text.split(",")):
            if not item:
                continue
            try:
                networks.append(ipaddress.ip_network(item.strip("[]")))
                continue
            except ValueError as exc:
                if "/" in item or ":" in item:
                    raise StarnavError(f"--allow-url-hosts: {exc}") from None
            name = item.rstrip(".").lower()
            if not _HOST_NAME.match(name):
                raise StarnavError(
                    f"--allow-url-hosts: {item!r} is neither a host name nor an address or "
                    "network (CIDR, e.g. 10.0.0.0/8)"
                )
            names.add(name)
        return cls(frozenset(names), tuple(networks))

    def allows(self, ip: IPAddress) -> bool:
        """Whether ``ip`` is inside one of the allowed networks."""
        return any(ip in network for network in self.networks)


@dataclass(frozen=True)
class FetchPolicy:
    """How a URL is fetched: at most ``max_bytes`` of body, everything within
    ``deadline_s`` seconds, at most ``max_redirects`` redirects, and only public hosts but
    those ``allowed``."""

    max_bytes: int
    deadline_s: float = DEFAULT_URL_DEADLINE_S
    allowed: AllowedHosts = field(default_factory=AllowedHosts)
    max_redirects: int = MAX_REDIRECTS


def deadline_message(deadline_s: float) -> str:
    return f"no whole answer within {deadline_s:g} s, this server's limit for fetching a URL"


def fetch_url(url: str, policy: FetchPolicy) -> bytes:
    """The body of ``url`` (http or https), following redirects; ``FetchError`` saying why
    when the URL is refused, the deadline passes, the body is over the size cap, the answer
    is not HTTP 200 or the connection fails."""
    deadline = time.monotonic() + policy.deadline_s
    for _ in range(policy.max_redirects + 1):
        target = _Target.of(url)
        addresses = _checked_addresses(target, policy.allowed)
        try:
            location, body = _get(target, addresses, policy.max_bytes, deadline)
        except FetchError:
            raise
        except TimeoutError:
            raise FetchError(deadline_message(policy.deadline_s)) from None
        except (OSError, ValueError, http.client.HTTPException) as exc:
            if time.monotonic() >= deadline:
                raise FetchError(deadline_message(policy.deadline_s)) from None
            raise FetchError(f"{type(exc).__name__}: {exc}".rstrip(": ")) from None
        if location is None:
            return body
        url = urllib.parse.urljoin(url, location)
    raise FetchError(f"more than {policy.max_redirects} redirects")


@dataclass(frozen=True)
class _Target:
    """A URL's parts as fetched: ``tls`` (https), ``host`` (no brackets), ``port``, and
    ``path`` (with the query; percent-encoded)."""

    tls: bool
    host: str
    port: int
    path: str

    @classmethod
    def of(cls, url: str) -> _Target:
        try:
            parts = urllib.parse.urlsplit(url)
            port = parts.port
        except ValueError as exc:
            raise FetchError(f"not a valid URL: {exc}") from None
        if parts.scheme.lower() not in ("http", "https"):
            raise FetchError(f"only http and https URLs are fetched, not {parts.scheme!r}")
        if "@" in parts.netloc:
            raise FetchError("URLs with a user name or password are not fetched")
        if not parts.hostname:
            raise FetchError("the URL has no host")
        if port == 0:
            raise FetchError("not a valid URL: port 0")
        tls = parts.scheme.lower() == "https"
        try:
            path = urllib.parse.quote(parts.path or "/", safe=_URL_SAFE)
            if parts.query:
                path += "?" + urllib.parse.quote(parts.query, safe=_URL_SAFE)
        except UnicodeEncodeError:
            raise FetchError("not a valid URL: it holds a character that is not text") from None
        return cls(tls, parts.hostname, port or (443 if tls else 80), path)


def _checked_addresses(target: _Target, allowed: AllowedHosts) -> list[tuple]:
    """The addresses (``getaddrinfo`` entries) of ``target``'s host, all of them public or
    allowed; ``FetchError`` naming the first that is not."""
    try:
        infos = socket.getaddrinfo(target.host, target.port, type=socket.SOCK_STREAM)
    except (OSError, ValueError) as exc:  # no such name, an idna label too long, a NUL
        raise FetchError(f"cannot resolve {target.host}: {exc.args[-1]}") from None
    if target.host.rstrip(".").lower() in allowed.names:
        return infos
    for info in infos:
        ip = ipaddress.ip_address(info[4][0])
        what = None if allowed.allows(ip) else not_public(ip)
        if what is not None:
            shown = (
                f"{target.host} is" if _is_ip(target.host) else f"{target.host} resolves to {ip},"
            )
            raise FetchError(
                f"{shown} {what}: this server does not fetch from such hosts (its operator "
                "can allow them with starnav serve --allow-url-hosts)"
            )
    return infos


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _get(target: _Target, addresses: list[tuple], max_bytes: int, deadline: float):
    """(the redirect's Location, None) or (None, the body) of one GET."""
    conn = _PinnedConnection(target, addresses, deadline)
    try:
        conn.putrequest("GET", target.path, skip_accept_encoding=True)  # no gzip: bytes as sent
        conn.putheader("User-Agent", USER_AGENT)
        conn.putheader("Connection", "close")
        conn.endheaders()
        resp = conn.getresponse()
        if resp.status in REDIRECTS:
            location = resp.getheader("Location")
            if not location:
                raise FetchError(f"HTTP {resp.status} without a Location to go to")
            return location, None
        if resp.status != 200:
            raise FetchError(f"the server answered HTTP {resp.status} {resp.reason}")
        too_big = f"larger than this server's limit of {max_bytes / 1e6:g} MB"
        if resp.length is not None and resp.length > max_bytes:
            raise FetchError(f"{too_big} ({resp.length} bytes)")
        body = bytearray()
        while chunk := resp.read(READ_CHUNK):
            body += chunk
            if len(body) > max_bytes:
                raise FetchError(too_big)
        return None, bytes(body)
    finally:
        conn.close()


def _remaining(deadline: float) -> float:
    left = deadline - time.monotonic()
    if left <= 0:
        raise TimeoutError("the fetch's deadline passed")
    return left


@functools.cache
def _tls_context() -> ssl.SSLContext:
    return ssl.create_default_context()


class _PinnedConnection(http.client.HTTPConnection):
    """An HTTP(S) connection to addresses already checked (no second DNS lookup) with the
    Host header and TLS server name of the URL's host, each socket operation limited to
    what is left until ``deadline``."""

    def __init__(self, target: _Target, addresses: list[tuple], deadline: float):
        super().__init__(target.host, target.port)
        self.default_port = 443 if target.tls else 80  # the Host header omits it
        self._tls, self._addresses, self._deadline = target.tls, addresses, deadline

    def connect(self) -> None:
        error: OSError | None = None
        for family, kind, proto, _, address in self._addresses:
            sock = socket.socket(family, kind, proto)
            try:
                sock.settimeout(_remaining(self._deadline))
                sock.connect(address)
                break
            except OSError as exc:
                sock.close()
                error = exc
                if isinstance(exc, TimeoutError):
                    raise
        else:
            raise error or OSError("no address to connect to")
        if self._tls:
            try:
                sock.settimeout(_remaining(self._deadline))  # the whole handshake's limit
                sock = _tls_context().wrap_socket(sock, server_hostname=self.host)
            except BaseException:
                sock.close()
                raise
        self.sock = _DeadlineSocket(sock, self._deadline)


class _DeadlineSocket:
    """The socket of a ``_PinnedConnection`` as ``http.client`` uses it (``sendall``,
    ``makefile``, ``close``): every send and receive gets what is left of the deadline as
    its timeout, so a server sending a byte at a time cannot stretch the fetch. As with a
    socket's own files, the socket is closed once it and its readers all are (``http.client``
    closes the connection and reads the answer on)."""

    def __init__(self, sock: socket.socket, deadline: float):
        self.sock, self.deadline = sock, deadline
        self._readers, self._closed = 0, False

    def sendall(self, data) -> None:
        self.sock.settimeout(_remaining(self.deadline))
        self.sock.sendall(data)

    def makefile(self, mode: str = "rb", *args, **kwargs) -> io.BufferedReader:
        self._readers += 1
        return io.BufferedReader(_DeadlineReader(self))

    def close(self) -> None:
        self._closed = True
        self.reader_closed(0)

    def reader_closed(self, count: int = 1) -> None:
        self._readers -= count
        if self._closed and self._readers == 0:
            self.sock.close()


class _DeadlineReader(io.RawIOBase):
    def __init__(self, owner: _DeadlineSocket):
        self._owner = owner

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        self._owner.sock.settimeout(_remaining(self._owner.deadline))
        return self._owner.sock.recv_into(buffer)

    def close(self) -> None:
        if not self.closed:
            self._owner.reader_closed()
        super().close()


class FetchQueue:
    """URL fetches for the event loop: at most ``slots`` at once, each in a thread of its own
    (a daemon: a fetch running when the server stops does not hold up its exit), and at most
    ``slots`` more requests waiting up to ``wait_s`` seconds for a slot; past either,
    ``FetchBusy`` at once."""

    def __init__(self, policy: FetchPolicy, slots: int = DEFAULT_URL_FETCHES,
                 wait_s: float = QUEUE_WAIT_S):  # fmt: skip
        self.policy, self.slots, self.wait_s = policy, slots, wait_s
        self._free = asyncio.Semaphore(slots)
        self._waiting = 0
        self._closed = False

    async def fetch(self, url: str) -> bytes:
        """The body of ``url`` (``fetch_url`` in a thread); ``FetchBusy`` or
        ``FetchError``."""
        busy = f"busy: all {self.slots} URL fetch slots are taken; try again in a few seconds"
        if self._free.locked() and self._waiting >= self.slots:
            raise FetchBusy(busy)
        self._waiting += 1
        try:
            await asyncio.wait_for(self._free.acquire(), self.wait_s)
        except TimeoutError:
            raise FetchBusy(busy) from None
        finally:
            self._waiting -= 1
        if self._closed:
            self._free.release()
            raise FetchBusy("busy: the server is stopping")
        loop = asyncio.get_running_loop()
        work: concurrent.futures.Future = concurrent.futures.Future()
        work.set_running_or_notify_cancel()  # running: nothing cancels it half way
        # the slot is free when the thread is, not when this request gives up waiting
        work.add_done_callback(lambda _: _call_soon(loop, self._free.release))
        thread = threading.Thread(target=_run, args=(work, url, self.policy),
                                  name="starnav-fetch", daemon=True)  # fmt: skip
        thread.start()
        answer = asyncio.wrap_future(work)
        answer.add_done_callback(lambda f: f.cancelled() or f.exception())  # retrieved
        try:
            limit = self.policy.deadline_s + DEADLINE_GRACE_S
            return await asyncio.wait_for(asyncio.shield(answer), limit)
        except TimeoutError:
            raise FetchError(deadline_message(self.policy.deadline_s)) from None

    def close(self) -> None:
        """No more fetches (those running end by their deadline or with the process)."""
        self._closed = True


def _run(work: concurrent.futures.Future, url: str, policy: FetchPolicy) -> None:
    try:
        work.set_result(fetch_url(url, policy))
    except Exception as exc:  # handed to the request waiting for it
        work.set_exception(exc)


def _call_soon(loop: asyncio.AbstractEventLoop, callback) -> None:
    try:
        loop.call_soon_threadsafe(callback)
    except RuntimeError:  # the loop is closed: nobody waits for a slot any more
        pass
