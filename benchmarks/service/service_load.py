"""A bounded load on ``starnav serve``: concurrent nova clients on the loopback address.

Starts the server (``--workers`` worker processes, a fresh data dir), answers as many jobs
at once first (the workers load their tables), then ``--clients`` client threads submit
``--jobs`` jobs in all: the real images of the peers' reference
(tests/data/images/reference.json, the files in ``../shared/data``) uploaded as files, and source
lists of the stars starnav detects in them, each list moved by a random shift of up to 20 px
so that no two are alike. Each client polls its job (every 0.25 s) until it is answered,
then checks the answer against its input (the WCS at the input's centre within 60″ of the
peers' reference; for a list, every identified star one of its points). Reports the jobs
answered and lost, the latency from the start of the upload to the answer, the throughput
and the solve times.

    python benchmarks/service/service_load.py   # writes the block "service-load" of docs/service.md
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, machine, replace_block, table_head, table_row

sys.path.insert(0, str(ROOT / "tests"))
from service_helpers import (
    REFERENCE,
    Server,
    load_jobs,
    login,
    run_load,
    upload_list,
    wait_done,
)

DOC = DOCS / "service.md"
TOLERANCE_ARCSEC = 60.0
PERCENTILES = (50, 90, 99)


def warm_up(url: str, workers: int, image: str) -> float:
    """Seconds until ``workers`` concurrent jobs are answered (the workers load their tables)."""
    t0 = time.perf_counter()
    ref = REFERENCE[image]["file"]
    jobs = load_jobs(workers, [image], kinds=("list",), seed=1)

    def one(job):
        job_id = upload_list(url, login(url), job.x, job.y, ref["width"], ref["height"])
        wait_done(url, job_id)

    threads = [threading.Thread(target=one, args=(job,)) for job in jobs]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return time.perf_counter() - t0


def latency_cells(outcomes) -> list[str]:
    lat = np.array([o.latency_s for o in outcomes if o.latency_s is not None])
    if not len(lat):
        return ["-"] * (len(PERCENTILES) + 1)
    return [f"{np.percentile(lat, p):.2f}" for p in PERCENTILES] + [f"{lat.max():.2f}"]


def row(label: str, outcomes) -> str:
    answered = [o for o in outcomes if o.status is not None]
    success = [o for o in answered if o.status == "success"]
    wrong = [
        o
        for o in success
        if o.offset_arcsec is None
        or o.offset_arcsec > TOLERANCE_ARCSEC
        or o.stars_from_input is False
    ]
    return table_row(
        label,
        len(outcomes),
        len(answered),
        len(outcomes) - len(answered),
        len(success),
        len(wrong),
        *latency_cells(answered),
        median([o.queued_s for o in answered], 1, 1.0),
        median([o.worker_ms for o in answered], 2, 1e-3),
    )


def median(values, digits: int, scale: float) -> str:
    """The median of ``values`` (None left out) times ``scale``, or "-"."""
    known = [v for v in values if v is not None]
    return f"{np.median(known) * scale:.{digits}f}" if known else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=200)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--no-doc", action="store_true", help="print only")
    args = ap.parse_args()
    t_start = time.perf_counter()
    images = sorted(REFERENCE)
    jobs = load_jobs(args.jobs, images, seed=args.seed)
    with tempfile.TemporaryDirectory(prefix="starnav-load-") as tmp:
        server = Server(
            Path(tmp) / "data", workers=args.workers, cache_dir=os.environ.get("STARNAV_CACHE_DIR")
        ).start()
        try:
            warm_s = warm_up(server.url, args.workers, images[0])
            t0 = time.perf_counter()
            outcomes = run_load(server.url, jobs, args.clients)
            wall = time.perf_counter() - t0
        finally:
            server.stop()
    lost = [o for o in outcomes if o.status is None]
    for o in lost[:5]:
        print(f"lost: {o.job.image} {o.job.kind} job {o.job_id}: {o.error}", file=sys.stderr)
    for o in outcomes:
        if o.status == "failure":
            print(f"failure: {o.job.image} {o.job.kind} job {o.job_id}", file=sys.stderr)
    answered = len(outcomes) - len(lost)
    rows = [row("all", outcomes)]
    for kind in ("image", "list"):
        rows.append(row(f"{kind}s", [o for o in outcomes if o.job.kind == kind]))
    for name in images:
        for kind in ("image", "list"):
            part = [o for o in outcomes if o.job.image == name and o.job.kind == kind]
            if part:
                rows.append(row(f"`{name}`, {kind}", part))
    text = "\n".join(
        [
            f"{args.jobs} jobs from {args.clients} concurrent clients (threads) to "
            f"`starnav serve --workers {args.workers}` on 127.0.0.1: the {len(images)} images "
            "of the peers' reference uploaded as files and their detected stars (40) as source "
            "lists moved by up to 20 px at random, in turn; each client polls its job every "
            "0.25 s. Latency: from the start of the upload to the poll that saw the answer; "
            "queued: the server's time from the upload to the start of the solve. "
            "Wrong: solved, but the WCS at the input's centre is over 60″ from the reference "
            "or an identified star is not one of the list's points.",
            "",
            *table_head(
                "jobs",
                "submitted",
                "answered",
                "lost",
                "solved",
                "wrong",
                *(f"p{p} s" for p in PERCENTILES),
                "max s",
                "queued s (median)",
                "solve s (median, in the worker)",
            ),
            *rows,
            "",
            f"{answered} of {len(outcomes)} answered in {wall:.1f} s: {answered / wall:.2f} "
            f"jobs/s. Before the load, {args.workers} jobs at once (the workers loading their "
            f"tables) took {warm_s:.1f} s.",
            "",
            f"{machine(load_at_end=True)}; `python benchmarks/service/service_load.py --jobs "
            f"{args.jobs} --clients {args.clients} --workers {args.workers}`, "
            f"{time.perf_counter() - t_start:.0f} s.",
        ]
    )
    print(text)
    if not args.no_doc:
        replace_block(DOC, "service-load", text)


if __name__ == "__main__":
    main()
