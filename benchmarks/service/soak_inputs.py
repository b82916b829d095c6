"""The inputs of the soak test (``service_soak.py``): good ones with their answers, and every
bad input the service was attacked with, made here in memory (nothing fetched, nothing kept).

Good: star images simulated at a known attitude (``starnav.simulate``: Hipparcos stars through a
15° 1024 x 768 pinhole camera, 16-bit PNG) and their stars as source lists; the real images of
the peers' reference (tests/data/images/reference.json, files in ``../shared/data``) and their
detected stars, when those files are there.

Bad: a text file, a truncated PNG, a PNG bomb (30000 x 30000 grey, under 1 MB), a gzip FITS
claiming 14000 x 14000 16-bit pixels (under 0.5 MB), a 16-bit RGB PNG, a tiled float64 TIFF of
14000 x 14000 that Pillow cannot open (read by tifffile), an upload over the size limit, a file
name with path tricks (a good image: it must solve, the name only recorded), a deeply nested
``request-json``, a session key with a lone surrogate, job ids at and above 2^63, URLs of
internal addresses and URLs of a local server that drips one byte every few seconds.
"""

from __future__ import annotations

import gzip
import io
import struct
import threading
import time
import zlib
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

SIM_FOV_DEG, SIM_WIDTH, SIM_HEIGHT = 15.0, 1024, 768
LIST_STARS = 40  # the brightest stars of a frame sent as its source list
DRIP_EVERY_S = 5.0  # the drip server's pace: one byte every this many seconds,
DRIP_FOR_S = 90.0  # for at most this long, then it closes the connection


@dataclass(frozen=True)
class SimFrame:
    """A simulated frame: its 16-bit PNG, its stars (FITS pixels, brightest first) and the
    true attitude ``R_cam_from_icrs``."""

    png: bytes
    x: tuple[float, ...]
    y: tuple[float, ...]
    R_cam_from_icrs: np.ndarray


def sim_frames(count: int, seed: int) -> list[SimFrame]:
    """``count`` frames at random attitudes, each with at least 25 stars drawn."""
    from PIL import Image

    from starnav.camera import Camera
    from starnav.catalog import load_catalog
    from starnav.geometry import attitude_from_radec_roll
    from starnav.simulate import draw_radec_roll
    from starnav.simulate.render import RenderSettings, render_frame

    catalog = load_catalog(None, mag_limit=7.5)
    camera = Camera.from_fov(SIM_FOV_DEG, SIM_WIDTH, SIM_HEIGHT)
    rng = np.random.default_rng(seed)
    frames = []
    while len(frames) < count:
        R = attitude_from_radec_roll(*draw_radec_roll(rng))
        frame = render_frame(catalog, camera, R, RenderSettings(seed=int(rng.integers(1 << 30))))
        if len(frame.xy) < 25:
            continue
        buf = io.BytesIO()
        Image.fromarray(frame.image).save(buf, format="PNG", compress_level=1)
        xy = frame.xy[:LIST_STARS] + 0.5  # FITS pixels: the first pixel's centre is 1
        frames.append(SimFrame(buf.getvalue(), tuple(map(float, xy[:, 0])),
                               tuple(map(float, xy[:, 1])), R))  # fmt: skip
    return frames


def png(width: int, height: int, bit_depth: int, colour_type: int, rows) -> bytes:
    """A PNG of ``rows`` (an iterable of each row's raw bytes, filter byte included),
    compressed as it goes (a bomb's pixels never exist at once)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = struct.pack(">I", zlib.crc32(kind + data))
        return struct.pack(">I", len(data)) + kind + data + crc

    z = zlib.compressobj(9)
    idat = b"".join(z.compress(row) for row in rows) + z.flush()
    head = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", head) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def png_bomb(side: int = 30000) -> bytes:
    """A ``side`` x ``side`` 8-bit grey PNG of zeros (under 1 MB)."""
    row = bytes(side + 1)
    return png(side, side, 8, 0, (row for _ in range(side)))


def rgb16_png(frame: SimFrame, factor: int = 3) -> bytes:
    """A simulated frame as a 16-bit RGB PNG, ``factor`` times larger each way."""
    from PIL import Image

    grey = np.asarray(Image.open(io.BytesIO(frame.png)), dtype=">u2")
    big = np.kron(grey, np.ones((factor, factor), dtype=">u2"))
    rgb = np.repeat(big[:, :, None], 3, axis=2)
    return png(rgb.shape[1], rgb.shape[0], 16, 2, (b"\0" + r.tobytes() for r in rgb))


def fits_gzip_bomb(side: int = 14000) -> bytes:
    """A gzip FITS whose header claims ``side`` x ``side`` 16-bit pixels, all zero."""
    from astropy.io import fits

    header = fits.Header([("SIMPLE", True), ("BITPIX", 16), ("NAXIS", 2), ("NAXIS1", side),
                          ("NAXIS2", side)])  # fmt: skip
    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as gz:
        gz.write(header.tostring().encode("ascii"))
        left = side * side * 2
        block = bytes(1 << 24)
        while left > 0:
            gz.write(block[: min(left, len(block))])
            left -= len(block)
        gz.write(bytes(-(side * side * 2) % 2880))
    return out.getvalue()


def tiff_bomb(side: int = 14000, tile: int = 1024) -> bytes:
    """A tiled, zlib-compressed float64 TIFF of ``side`` x ``side`` zeros: Pillow reads no
    64-bit float, so starnav reads it with tifffile."""
    import tifffile

    zeros = np.zeros((tile, tile))
    per_side = -(-side // tile)
    n = per_side * per_side
    out = io.BytesIO()
    tifffile.imwrite(out, (zeros for _ in range(n)), shape=(side, side), dtype="float64",
                     tile=(tile, tile), compression="zlib")  # fmt: skip
    return out.getvalue()


def nested_json(depth: int = 100_000) -> str:
    """``request-json`` nested ``depth`` arrays deep."""
    return "[" * depth + "]" * depth


LONE_SURROGATE_JSON = '{"session": "\\ud800", "apikey": "\\ud800"}'
HUGE_JOB_IDS = (2**63, 2**63 + 1, 2**64, 10**30)


def internal_urls(server_port: int) -> list[str]:
    """URLs of addresses a public service must not fetch from."""
    return [
        "http://169.254.169.254/latest/meta-data/",  # the cloud metadata address
        "http://10.255.255.1/image.png",
        "http://192.168.255.1/image.png",
        f"http://[::1]:{server_port}/api/status",
        f"http://127.0.0.2:{server_port}/api/status",
        f"http://0.0.0.0:{server_port}/api/status",
    ]


class DripServer:
    """A local HTTP server whose every answer claims 100 kB of PNG and sends one byte every
    ``DRIP_EVERY_S`` seconds, for ``DRIP_FOR_S`` at most (``url``: its address)."""

    def __init__(self):
        stop = self._stop = threading.Event()

        class Drip(BaseHTTPRequestHandler):
            def do_GET(self):
                self.send_response(200)
                self.send_header("Content-Type", "image/png")
                self.send_header("Content-Length", "100000")
                self.end_headers()
                t0 = time.monotonic()
                try:
                    while time.monotonic() - t0 < DRIP_FOR_S and not stop.is_set():
                        self.wfile.write(b"\x89")
                        self.wfile.flush()
                        stop.wait(DRIP_EVERY_S)
                except OSError:
                    pass

            def log_message(self, *args):
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), Drip)
        self._server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self._server.server_port}/drip.png"
        threading.Thread(target=self._server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self._stop.set()
        self._server.shutdown()
        self._server.server_close()
