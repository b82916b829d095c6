"""One job, solved where a worker runs it: bytes in, bytes out.

``run_job`` takes the upload's bytes (or a source list) and the client's request, and returns
the answer with every file's bytes, so it runs the same in a local worker process or on any
machine of a Dask cluster, which needs no shared disk. A bad file or hint becomes a failed
answer with the reason; the worker never raises for the client's mistakes.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from starnav.catalog.names import star_names
from starnav.detect.read import FITS_MAGIC, GZIP_MAGIC, MAX_PIXELS, TIFF_MAGICS
from starnav.errors import StarnavError
from starnav.pipeline.plate import XYList, read_xylist, solve_plate, write_plate_files
from starnav.runtime.budget import Deadline
from starnav.service.files import JOB_TMP_PREFIX
from starnav.service.nova import plate_hints

# magic bytes -> the name the input gets in the job's directory (never the client's name)
MAGIC = (
    (FITS_MAGIC, "input.fits"),
    (GZIP_MAGIC, "input.fits.gz"),  # read as FITS for its name (starnav.detect.read)
    (b"\x89PNG\r\n\x1a\n", "input.png"),
    (b"\xff\xd8\xff", "input.jpg"),
    *((magic, "input.tif") for magic in TIFF_MAGICS),
)
OUTPUTS = {
    "wcs": "wcs.fits",
    "new_fits": "new.fits",
    "annotate": "annotated.png",
    "axy": "axy.fits",
    "corr": "corr.fits",
    "rdls": "rdls.fits",
    "kmz": "image.kmz",
}
IMAGE_ONLY = ("new_fits", "kmz")  # files a source list has no picture for


def input_name(head: bytes) -> str:
    """The file name an upload is stored under, from its first bytes ("input.bin" for one
    that is no image format starnav reads: it then fails with the reader's reason)."""
    for magic, name in MAGIC:
        if head.startswith(magic):
            return name
    return "input.bin"


def run_job(
    data: bytes | None,
    xy: dict | None,
    request: dict,
    budget_s: float | None,
    *,
    max_pixels: int = MAX_PIXELS,
    told: Callable[[str, float | None], None] | None = None,
) -> dict:
    """Solve an upload (``data``: the file's bytes) or a source list (``xy``: "x", "y" FITS
    pixels, "image_width", "image_height"; without a size, nova's: the list's extent) with the
    nova ``request``'s hints, within the time budget ``budget_s`` (None: starnav's default),
    which the image's read and detection count against; images of at most ``max_pixels``.
    ``told(event, value)`` hears how it goes: ("budget", seconds the solve gets) once the
    image is read and detected, ("solved", None) when the files are written next.
    Returns "solved", "reason", "calibration" (nova's, None when unsolved), "result"
    (starnav's JSON, stars with names) and "files" (kind -> bytes: "wcs", "new_fits",
    "annotate")."""
    t0 = time.perf_counter()
    # in the system's temporary folder: ``starnav serve`` makes it DATA/tmp (service.files)
    with tempfile.TemporaryDirectory(prefix=JOB_TMP_PREFIX) as tmp:
        try:
            answer = _solve(Path(tmp), data, xy, request, budget_s, max_pixels, told)
        except StarnavError as exc:
            answer = failed_answer(f"error: {exc}")
        except MemoryError:
            answer = failed_answer(f"error: {out_of_memory()}")
        except Exception as exc:  # a bug must fail the job, never the server
            where = traceback.extract_tb(exc.__traceback__)[-1]
            answer = failed_answer(
                f"error: internal {type(exc).__name__}: {exc} ({Path(where.filename).name}:"
                f"{where.lineno})"
            )
        # a reason names the input by the service's name, not the worker's temporary path
        answer["reason"] = answer["reason"].replace(f"{tmp}{os.sep}", "")
    answer["worker_ms"] = (time.perf_counter() - t0) * 1e3
    return answer


def out_of_memory() -> str:
    """The reason of a job that ran out of memory, with this process's limit when it has one
    (``resource.RLIMIT_DATA``, set by ``starnav.service.processes``)."""
    text = "the image is too large for this server's memory"
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_DATA)[0]
    except (ImportError, OSError, ValueError):
        return text
    if limit == resource.RLIM_INFINITY:
        return text
    return f"{text}: the job needed more than its limit of {limit / 1e6:.0f} MB (--max-job-mb)"


def failed_answer(reason: str) -> dict:
    """A job's answer when it failed, with the ``reason`` (here or where it ran)."""
    return {"solved": False, "reason": reason, "calibration": None, "result": None, "files": {}}


def _solve(tmp: Path, data, xy, request, budget_s, max_pixels, told) -> dict:
    if xy is not None:
        x, y = xy.get("x") or [], xy.get("y") or []
        source = XYList.make(x, y, xy.get("image_width") or _extent(x),
                             xy.get("image_height") or _extent(y))  # fmt: skip
        path = None
    else:
        path = tmp / input_name(data[:16])
        path.write_bytes(data)
        # an xylist file (a FITS table of X, Y, sorted by its FLUX or magnitude column when
        # it has one), as nova takes one; else an image
        source = read_xylist(path) or path

    def hints(width: int, height: int):  # the width converts arcsec per pixel
        return plate_hints(request, width, height)

    started = Deadline.now(math.inf if budget_s is None else budget_s)
    told = told or (lambda event, value: None)
    res = solve_plate(source, hints, time_budget_s=budget_s, max_pixels=max_pixels,
                      budget_from=started, on_budget=lambda s: told("budget", s))  # fmt: skip
    told("solved", None)
    targets = {k: tmp / name for k, name in OUTPUTS.items()}
    if path is None:
        for kind in IMAGE_ONLY:
            targets.pop(kind)
    written = write_plate_files(res, path, **targets)
    files = {k: Path(p).read_bytes() for k, p in written.items()}
    result = _result_json(res)
    solved = res.plate is not None
    calibration = res.plate.calibration(jpeglike=res.jpeglike) if solved else None
    return {"solved": solved, "reason": "solved" if solved else res.reason,
            "calibration": calibration, "result": result, "files": files}  # fmt: skip


def _extent(values) -> int | None:
    """The size nova gives a source list sent without one: its largest coordinate, rounded up
    (``net/process_submissions.py``); None when there is none (``XYList.make`` says why)."""
    try:
        return math.ceil(max(float(v) for v in values))
    except (TypeError, ValueError, OverflowError):
        return None


def _result_json(res) -> dict:
    """starnav's JSON of the solve, each identified star with its name (when it has one) and
    catalog magnitude, and the image size."""
    from starnav.results import solve_dict

    out = solve_dict(res.solution, res.reason, res.time_ms, None, res.xy)
    names = star_names()
    cat = res.catalog
    for star in out["stars"]:
        hip = star.get("catalog_id")
        if hip is not None:
            star["name"] = names.get(int(hip))
            if cat is not None:
                star["mag"] = float(cat.mag[cat.rows([hip])[0]])
    out.update(width=res.width, height=res.height)
    if res.plate is not None:
        p = res.plate
        out["plate"] = {"ra_deg": p.ra_deg, "dec_deg": p.dec_deg, "radius_deg": p.radius_deg,
                        "pixscale_arcsec": p.pixscale_arcsec,
                        "orientation_deg": p.orientation_deg, "parity": p.parity_name}  # fmt: skip
    return out
