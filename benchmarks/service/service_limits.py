"""The issue's attack files against a worker of ``starnav serve`` with its default limits.

Each file (built here, small on disk: ``tests/bomb_files.py``) is solved as a job by a fresh
worker process (``starnav.service.processes.WorkerProcess``, the server's own, with the
default time budgets, 200 MP pixel limit and 4000 MB memory limit): the answer's reason, the
time from sending the job to its answer, and the worker's peak RSS (VmHWM).

    python benchmarks/service/service_limits.py   # writes docs/service.md's "service-limits"
"""

from __future__ import annotations

import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, machine, replace_block, table_head, table_row

sys.path.insert(0, str(ROOT / "tests"))
from bomb_files import gzip_fits, png_claiming, tiff_claiming, zero_png16
from starnav.service.processes import Limits, WorkerProcess


def attacks(tmp: Path) -> dict[str, Path]:
    """What each file is, and the file."""
    return {
        "the issue's FITS: 14000 x 14000 uint8, gzip": gzip_fits(
            tmp / "a.fits.gz", (14000, 14000), 8
        ),
        "the same as float64, gzip": gzip_fits(tmp / "b.fits.gz", (14000, 14000), -64),
        "16-bit RGB PNG of zeros, 8000 x 8000 (whole)": zero_png16(tmp / "c.png", 8000, 8000),
        "the same, its rows Paeth-filtered (pypng: ~13x slower)": zero_png16(
            tmp / "p.png", 8000, 8000, paeth=True
        ),
        "16-bit RGB PNG claiming 30000 x 20000": png_claiming(tmp / "d.png", 30000, 20000),
        "float RGB TIFF (Pillow cannot open) claiming 60000 x 50000": tiff_claiming(
            tmp / "e.tif", 60000, 50000
        ),
    }


async def one(path: Path) -> tuple[str, float, float]:
    """(reason, seconds to the answer, the worker's peak RSS in MB) of ``path`` as a job."""
    worker = WorkerProcess(Limits())
    try:
        await worker.run((None, {"x": [1.0] * 4, "y": [1.0] * 4}, {}, None))  # started
        t0 = time.perf_counter()
        answer = await worker.run((path.read_bytes(), None, {}, None))
        took = time.perf_counter() - t0
        status = Path(f"/proc/{worker.process.pid}/status").read_text()
        hwm = next(line for line in status.splitlines() if line.startswith("VmHWM"))
        return answer["reason"], took, int(hwm.split()[1]) / 1e3
    finally:
        worker.stop()


def main() -> None:
    lines = [
        "Each file sent as a job to a fresh worker process of `starnav serve` with its defaults "
        "(starnav's time budgets, 200 MP, 4000 MB). Seconds from sending the job to its answer; "
        "the worker's peak RSS (VmHWM: its imports and a source-list job before it included; "
        "— for a worker killed at its deadline).",
        "",
        *table_head("file", "bytes", "answer", "s", "peak MB"),
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for what, path in attacks(Path(tmp)).items():
            reason, took, peak = asyncio.run(one(path))
            stopped = "worker process was stopped" in reason
            reason = reason.replace(f"image file '{path.name}'", "").split(": its worker")[0]
            row = table_row(what, path.stat().st_size, reason[:160], f"{took:.1f}",
                            "—" if stopped else f"{peak:.0f}")  # fmt: skip
            print(row, flush=True)
            lines.append(row)
    lines += ["", machine(load_at_end=True) + "; `python benchmarks/service/service_limits.py`."]
    replace_block(DOCS / "service.md", "service-limits", "\n".join(lines))


if __name__ == "__main__":
    main()
