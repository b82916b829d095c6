"""A soak test of ``starnav serve``: many clients on the loopback address, good jobs mixed with
every bad input it was attacked with, bounded in count and time.

Starts the server (``--workers`` worker processes, a fresh data dir, uploads up to
``--max-upload-mb``, and ``--allow-url-hosts 127.0.0.1`` when the server has that option,
for the drip server), answers one job per worker first (the workers load their tables), then
``--clients`` client threads run ``--jobs`` jobs in a shuffled mix of the kinds in ``KINDS``
(inputs: ``soak_inputs``), submitting for at most ``--minutes``. Each job's outcome is checked
against what its kind expects:

* solve: answered "success" and right: a simulated frame's attitude by starnav's rule of a
  correct answer (``benchmarks.harness.CORRECT_RULE``), a real image's WCS at its centre
  within 60″ of the peers' reference; a file name with path tricks must solve too, and no
  file may appear where the name points;
* fail: the upload refused with nova's JSON error (any status but 500) or the job answered
  "failure" with a reason;
* answer: the same, or solved (a 16-bit RGB PNG of a simulated frame may solve: the attack is
  on the time and memory it takes);
* refuse: nova's JSON error (any status but 500).

A 503 "busy" answer to a good job is retried after its Retry-After (the wait counts in its
latency). Latency: from the first request of a job to the answer that ended it (the poll that
saw it finished, or the refusal). The memory of the server and every process under it (the
workers, the forkserver, the resource tracker) is summed from /proc every half second: the
peak of that sum and the largest single process.

    python benchmarks/service/service_soak.py                      # 1000 jobs, 50 clients, 10 min
    python benchmarks/service/service_soak.py --jobs 100 --clients 10 --out -   # print only
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import (
    DOCS,
    ROOT,
    machine,
    replace_block,
    score_answer,
    table_head,
    table_row,
    verdict,
)
from benchmarks.service import soak_inputs as inputs

sys.path.insert(0, str(ROOT / "tests"))
from service_helpers import REFERENCE, Server, centre_offset_arcsec, source_list
from shared_data import PEER_FILES

DOC = DOCS / "service.md"
TOLERANCE_ARCSEC = 60.0
PERCENTILES = (50, 90, 99)
POLL_S = 0.5
JOB_TIMEOUT_S = 300.0
REQUEST_TIMEOUT_S = 180.0  # a drip URL's upload waits on the server's fetch
MAX_UPLOAD_MB = 30.0
SIM_FRAMES = 12
NOT_RUN = "not run: --minutes passed"  # left out of the table, counted under it

# kind -> (what it must end as, share of the jobs in %)
KINDS = {
    "sim image": ("solve", 33),
    "sim list": ("solve", 25),
    "real image": ("solve", 6),
    "real list": ("solve", 6),
    "path-trick name": ("solve", 3),
    "not an image": ("fail", 3),
    "truncated PNG": ("fail", 3),
    "PNG bomb 30000²": ("fail", 2),
    "gzip FITS 14000²": ("fail", 2),
    "16-bit RGB PNG": ("answer", 2),
    "float64 TIFF 14000²": ("fail", 2),
    "over the size limit": ("refuse", 1),
    "nested request-json": ("refuse", 2),
    "lone surrogate": ("refuse", 2),
    "job id ≥ 2^63": ("refuse", 3),
    "internal URL": ("refuse", 3),
    "drip URL": ("fail", 2),
}
# the kinds that need the peers' real images (../shared/data)
REAL_KINDS = ("real image", "real list")


@dataclass(frozen=True)
class Outcome:
    """How one job ended: ``ok`` (as its kind expects), ``what`` (correct, failed: reason,
    refused: message, HTTP 500, ...), ``latency_s`` (None: never ended), ``http_500``."""

    kind: str
    ok: bool
    what: str
    latency_s: float | None
    http_500: bool = False


class Soak:
    """The inputs, the server's address and one client per thread."""

    def __init__(self, url: str, port: int, drip_url: str, seed: int, escape: Path):
        self.url, self.port, self.drip_url, self.escape = url, port, drip_url, escape
        self.frames = inputs.sim_frames(SIM_FRAMES, seed)
        self.real = {name: PEER_FILES[name].read_bytes() for name in REFERENCE
                     if PEER_FILES[name].is_file()}  # fmt: skip
        self.real_lists = {name: source_list(name) for name in self.real}
        self.bad = {
            "not an image": b"this is not an image\n" * 100,
            "truncated PNG": self.frames[0].png[: len(self.frames[0].png) * 2 // 5],
            "PNG bomb 30000²": inputs.png_bomb(),
            "gzip FITS 14000²": inputs.fits_gzip_bomb(),
            "16-bit RGB PNG": inputs.rgb16_png(self.frames[1]),
            "float64 TIFF 14000²": inputs.tiff_bomb(),
        }
        self.oversized = os.urandom(int(MAX_UPLOAD_MB * 1e6) + 1000)
        self.internal = inputs.internal_urls(port)
        self._local = threading.local()

    def _http(self):
        import httpx2 as httpx

        if not hasattr(self._local, "http"):
            self._local.http = httpx.Client(timeout=REQUEST_TIMEOUT_S)
        return self._local.http

    def session(self) -> str:
        """This client thread's session (logged in on its first job)."""
        if not hasattr(self._local, "session"):
            self._local.session = self.call("api/login", {"apikey": "soak"})[1]["session"]
        return self._local.session

    def call(self, route: str, args: dict | None = None, *, raw: str | None = None,
             files: dict | None = None, get: bool = False):  # fmt: skip
        """(HTTP status, JSON answer or None when it is no JSON, Retry-After s or None)."""
        form = {"request-json": raw if raw is not None else json.dumps(args)}
        try:
            if get:
                resp = self._http().get(f"{self.url}/{route}")
            else:
                resp = self._http().post(f"{self.url}/{route}", data=form, files=files)
        except Exception as exc:
            raise type(exc)(f"{'GET' if get else 'POST'} {route.split('/')[1]}: {exc}") from exc
        try:
            body = resp.json()
        except ValueError:
            body = None
        retry = resp.headers.get("retry-after")
        return resp.status_code, body, (float(retry) if retry and retry.isdigit() else None)

    # ---- one job

    def run(self, kind: str, k: int, deadline: float) -> Outcome:
        t0 = time.monotonic()
        try:
            return self._run(kind, k, t0, deadline)
        except Exception as exc:  # a lost job: counted, never raised
            return Outcome(kind, False, f"lost: {type(exc).__name__}: {exc}"[:200], None)

    def _run(self, kind: str, k: int, t0: float, deadline: float) -> Outcome:
        session = self.session()
        if KINDS[kind][0] == "refuse" or kind == "drip URL":
            return self._refusal(kind, k, t0, session)
        frame = self.frames[k % len(self.frames)]
        if kind in ("sim image", "path-trick name"):
            name = "frame.png" if kind == "sim image" else f"../../{self.escape.name}"
            submit = ("api/upload", {"session": session}, {"file": (name, frame.png)})
        elif kind == "sim list":
            size = {"image_width": inputs.SIM_WIDTH, "image_height": inputs.SIM_HEIGHT}
            submit = ("api/url_upload", {"session": session, "x": frame.x, "y": frame.y, **size},
                      None)  # fmt: skip
        elif kind == "real image":
            name = sorted(self.real)[k % len(self.real)]
            submit = ("api/upload", {"session": session}, {"file": (name, self.real[name])})
        elif kind == "real list":
            name = sorted(self.real)[k % len(self.real)]
            x, y = self.real_lists[name]
            ref = REFERENCE[name]["file"]
            size = {"image_width": ref["width"], "image_height": ref["height"]}
            submit = ("api/url_upload", {"session": session, "x": x, "y": y, **size}, None)
        else:  # a bad file
            submit = ("api/upload", {"session": session}, {"file": ("bad.bin", self.bad[kind])})
        status, body, job_id = self._submit(*submit, deadline)
        if job_id is None:
            return self._refused(kind, t0, status, body)
        state = self._wait(job_id, deadline)
        latency = time.monotonic() - t0
        record = self.call(f"api/jobs/{job_id}/starnav", get=True)[1] or {}
        if KINDS[kind][0] in ("fail", "answer"):
            reason = record.get("reason") or ""
            ok = (state == "failure" and bool(reason)) or (
                KINDS[kind][0] == "answer" and state == "success"
            )
            return Outcome(kind, ok, f"{state}: {reason}"[:160], latency)
        if state != "success":
            return Outcome(kind, False, f"{state}: {record.get('reason')}"[:160], latency)
        if kind.startswith("real"):
            return Outcome(kind, *self._real_check(job_id, name), latency)
        score = verdict(score_answer(record.get("result") or {}, frame.R_cam_from_icrs))
        return Outcome(kind, score == "correct", score, latency)

    def _submit(self, route, args, files, deadline):
        """Submit, retrying after a "busy" answer; (status, answer, job id or None)."""
        while True:
            status, body, retry = self.call(route, args, files=files)
            if body and body.get("status") == "success":
                return status, body, int(body["subid"])
            if status != 503 or time.monotonic() > deadline:
                return status, body, None
            time.sleep(retry or 1.0)

    def _wait(self, job_id: int, deadline: float) -> str:
        end = min(deadline, time.monotonic() + JOB_TIMEOUT_S)
        while True:
            state = (self.call(f"api/jobs/{job_id}", get=True)[1] or {}).get("status")
            if state in ("success", "failure") or time.monotonic() > end:
                return state or "unknown"
            time.sleep(POLL_S)

    def _real_check(self, job_id: int, name: str) -> tuple[bool, str]:
        from astropy.io import fits

        text = self._http().get(f"{self.url}/wcs_file/{job_id}").content.decode("latin-1")
        offset = centre_offset_arcsec(fits.Header.fromstring(text), name)
        return offset <= TOLERANCE_ARCSEC, f"{offset:.0f}″ from the reference"

    def _refusal(self, kind: str, k: int, t0: float, session: str) -> Outcome:
        if kind == "over the size limit":
            status, body, _ = self.call("api/upload", {"session": session},
                                        files={"file": ("big.fits", self.oversized)})  # fmt: skip
        elif kind == "nested request-json":
            status, body, _ = self.call("api/upload", raw=inputs.nested_json())
        elif kind == "lone surrogate":
            route = ("api/myjobs", "api/upload", "api/url_upload")[k % 3]
            status, body, _ = self.call(route, raw=inputs.LONE_SURROGATE_JSON)
        elif kind == "job id ≥ 2^63":
            job = inputs.HUGE_JOB_IDS[k % len(inputs.HUGE_JOB_IDS)]
            route = (f"api/jobs/{job}", f"api/submissions/{job}", f"wcs_file/{job}")[k % 3]
            status, body, _ = self.call(route, get=True)
        else:  # a URL: an internal address, or the drip server
            url = self.drip_url if kind == "drip URL" else self.internal[k % len(self.internal)]
            status, body, _ = self.call("api/url_upload", {"session": session, "url": url})
            if body and body.get("status") == "success":  # fetched: the job must fail
                state = self._wait(int(body["subid"]), time.monotonic() + JOB_TIMEOUT_S)
                ok = kind == "drip URL" and state == "failure"
                return Outcome(kind, ok, f"fetched, job {state}", time.monotonic() - t0)
        return self._refused(kind, t0, status, body)

    def _refused(self, kind: str, t0: float, status: int, body) -> Outcome:
        latency = time.monotonic() - t0
        if status >= 500 and status != 503:
            return Outcome(kind, False, f"HTTP {status}", latency, http_500=status == 500)
        if not body or body.get("status") != "error" or not body.get("errormessage"):
            return Outcome(kind, False, f"HTTP {status}, not nova's JSON error", latency)
        what = f"refused ({status}): {body['errormessage']}"[:160]
        return Outcome(kind, KINDS[kind][0] != "solve", what, latency)


def job_kinds(n: int, kinds: list[str], seed: int) -> list[str]:
    """``n`` kinds in the shares of ``KINDS`` (each at least once), shuffled."""
    total = sum(KINDS[k][1] for k in kinds)
    counts = {k: max(1, round(n * KINDS[k][1] / total)) for k in kinds}
    while sum(counts.values()) > n:
        counts[max(counts, key=counts.get)] -= 1
    while sum(counts.values()) < n:
        counts[kinds[0]] += 1
    out = [k for k in kinds for _ in range(counts[k])]
    random.Random(seed).shuffle(out)
    return out


def tree_rss(pid: int) -> tuple[int, int]:
    """(summed RSS bytes of process ``pid`` and every process under it, the largest one's)."""
    parents, rss = {}, {}
    page = os.sysconf("SC_PAGE_SIZE")
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                stat = fh.read()
            with open(f"/proc/{entry}/statm") as fh:
                rss[int(entry)] = int(fh.read().split()[1]) * page
        except (OSError, IndexError, ValueError):
            continue
        parents[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    tree, todo = set(), [pid]
    while todo:
        p = todo.pop()
        tree.add(p)
        todo += [c for c, parent in parents.items() if parent == p and c not in tree]
    sizes = [rss.get(p, 0) for p in tree]
    return sum(sizes), max(sizes, default=0)


class RssPeak:
    """Samples ``tree_rss`` every half second in a thread until ``stop``."""

    def __init__(self, pid: int):
        self.total = self.largest = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, args=(pid,), daemon=True)
        self._thread.start()

    def _sample(self, pid: int) -> None:
        while not self._stop.wait(0.5):
            total, largest = tree_rss(pid)
            self.total, self.largest = max(self.total, total), max(self.largest, largest)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def has_option(option: str) -> bool:
    """Whether ``starnav serve`` has ``option`` (its help names it)."""
    help_text = subprocess.run([sys.executable, "-m", "starnav.cli", "serve", "--help"],
                               capture_output=True, text=True).stdout  # fmt: skip
    return option in help_text


def percentiles(values: list[float]) -> list[str]:
    if not values:
        return ["-"] * (len(PERCENTILES) + 1)
    return [f"{np.percentile(values, p):.2f}" for p in PERCENTILES] + [f"{max(values):.2f}"]


def report(outcomes: list[Outcome], kinds: list[str]) -> list[str]:
    by_kind = defaultdict(list)
    for o in outcomes:
        by_kind[o.kind].append(o)
    lines = table_head("kind", "must", "jobs", "as it must", "not", "HTTP 500",
                       *(f"p{p} s" for p in PERCENTILES), "max s")  # fmt: skip
    for label, part in [("all", outcomes)] + [(k, by_kind[k]) for k in kinds if by_kind[k]]:
        ok = sum(o.ok for o in part)
        must = "-" if label == "all" else KINDS[label][0]
        lat = [o.latency_s for o in part if o.latency_s is not None]
        lines.append(table_row(label, must, len(part), ok, len(part) - ok,
                               sum(o.http_500 for o in part), *percentiles(lat)))  # fmt: skip
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1000)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--minutes", type=float, default=10.0, help="submitting stops after this")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--skip", default="", help="kinds left out, comma-separated")
    ap.add_argument("--out", default=str(DOC),
                    help="markdown file whose block service-soak gets the table; - prints only",
                    )  # fmt: skip
    args = ap.parse_args()
    t_start = time.perf_counter()
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    unknown = skip - set(KINDS)
    if unknown:
        ap.error(f"unknown kinds in --skip: {', '.join(sorted(unknown))}")
    serve_args = ["--max-upload-mb", f"{MAX_UPLOAD_MB:g}"]
    if has_option("--allow-url-hosts"):
        serve_args += ["--allow-url-hosts", "127.0.0.1"]
    drip = inputs.DripServer()
    with tempfile.TemporaryDirectory(prefix="starnav-soak-") as tmp:
        escape = Path(tmp) / f"escaped-{os.getpid()}.png"
        server = Server(Path(tmp) / "data", workers=args.workers, options=serve_args,
                        cache_dir=os.environ.get("STARNAV_CACHE_DIR")).start()  # fmt: skip
        try:
            soak = Soak(server.url, server.port, drip.url, args.seed, escape)
            kinds = [k for k in KINDS if k not in skip
                     and (k not in REAL_KINDS or soak.real)]  # fmt: skip
            jobs = job_kinds(args.jobs, kinds, args.seed)
            warm = [soak.run("sim list", k, time.monotonic() + 600) for k in range(args.workers)]
            rss = RssPeak(server.proc.pid)
            t0 = time.monotonic()
            stop_at = t0 + args.minutes * 60.0
            deadline = stop_at + JOB_TIMEOUT_S

            def one(item):
                k, kind = item
                if time.monotonic() > stop_at:
                    return Outcome(kind, False, NOT_RUN, None)
                return soak.run(kind, k, deadline)

            with concurrent.futures.ThreadPoolExecutor(args.clients) as pool:
                outcomes = list(pool.map(one, enumerate(jobs)))
            wall = time.monotonic() - t0
            rss.stop()
            places = (Path(tmp), Path(tmp).parent, server.data_dir, Path.cwd(), Path.cwd().parent)
            escaped = [p / escape.name for p in places if (p / escape.name).exists()]
        finally:
            server.stop()
            drip.close()
            log = [line for line in server.log().splitlines() if "Error" in line]
    for line in log[:20]:
        print(f"server log: {line}", file=sys.stderr)
    not_run = sum(o.what == NOT_RUN for o in outcomes)
    outcomes = [o for o in outcomes if o.what != NOT_RUN]
    for o in outcomes:
        if not o.ok:
            print(f"not as it must: {o.kind}: {o.what}", file=sys.stderr)
    if escaped:
        print(f"a file name escaped the data dir: {escaped}", file=sys.stderr)
    ok = sum(o.ok for o in outcomes)
    text = "\n".join(
        [
            f"{len(jobs)} jobs from {args.clients} concurrent clients (threads) to `starnav serve "
            f"--workers {args.workers} {' '.join(serve_args)}` on 127.0.0.1, submitted for at "
            f"most {args.minutes:g} min: the kinds below, shuffled (inputs: "
            "benchmarks/service/soak_inputs.py; left out: "
            f"{', '.join(sorted(skip)) or 'none'}). Latency: from a job's first request to the "
            "answer that ended it (a finished job seen by a poll every 0.5 s, or a refusal).",
            "",
            *report(outcomes, kinds),
            "",
            f"{ok} of {len(outcomes)} as they must in {wall:.0f} s ({not_run} not submitted "
            f"within the {args.minutes:g} min); "
            f"{sum(o.http_500 for o in outcomes)} HTTP 500; file names escaping the data dir: "
            f"{len(escaped)}. Peak memory of the server and every process under it: "
            f"{rss.total / 1e9:.2f} GB together, {rss.largest / 1e9:.2f} GB the largest one. "
            f"Warm-up ({args.workers} source lists, one per worker): "
            f"{sum(w.ok for w in warm)} of {len(warm)} right.",
            "",
            f"{machine(load_at_end=True)}; `python benchmarks/service/service_soak.py --jobs "
            f"{args.jobs} --clients {args.clients} --minutes {args.minutes:g}"
            f"{' --skip ' + repr(args.skip) if skip else ''}`, "
            f"{time.perf_counter() - t_start:.0f} s.",
        ]
    )
    print(text)
    if args.out != "-":
        replace_block(args.out, "service-soak", text, missing="\n## Soak test\n")


if __name__ == "__main__":
    main()
