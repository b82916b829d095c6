"""Many image files in one process: ``starnav solve A.jpg B.fits DIR/ ...``.

One catalog / table / machine-code load serves every file. The first file is solved here,
which loads them; the others then go to ``workers`` processes forked from this one, which
share what it loaded, or to a Dask cluster (``dask_address``; each Dask worker process loads
them once, from its disk cache). Per file the cost is then decoding, detection and the
in-process solve.

A file that fails (missing, unreadable, too few stars, a camera of another size, ...) becomes
a record whose reason starts with "error:"; it never stops the batch. A sequence (``track``)
hands each solved frame's attitude and fitted camera to the next frame (tracking, falling back
to lost in space with that camera; after an unsolved frame the next is solved as if it were
the first). Several workers cut a sequence into contiguous runs, one per worker, each tracked
on its own.

Outputs named per file (``ImageOutputs``): a WCS header, the image as FITS with the WCS in its
header (astrometry.net's ``.new``), an annotated PNG — each written by the process that solved
the file, into a directory, as ``<stem>.wcs``, ``<stem>.new.fits``, ``<stem>.png``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from starnav.detect.header import fits_hints
from starnav.detect.read import read_image, readable_suffixes
from starnav.errors import StarnavError
from starnav.pipeline.image import solve_image, write_outputs
from starnav.results import Solution
from starnav.runtime.pools import dask_client, process_pool, worker_count


def image_paths(inputs: Sequence[str | Path], skipped: list[Path] | None = None) -> list[Path]:
    """The files of ``inputs`` in order: a directory gives the files ``read_image`` reads (by
    suffix: ``readable_suffixes``; sorted, not recursing), and its other entries (other files,
    subdirectories) go to ``skipped`` when a list is given; a file is taken as given (even if
    missing: its record will say so). ``StarnavError`` when there is nothing to solve."""
    suffixes = readable_suffixes()
    out: list[Path] = []
    left: list[Path] = []
    for item in map(Path, inputs):
        if not item.is_dir():
            out.append(item)
            continue
        for entry in sorted(item.iterdir()):
            read = entry.is_file() and entry.name.lower().endswith(suffixes)
            (out if read else left).append(entry)
    if skipped is not None:
        skipped.extend(left)
    if not out:
        others = f" ({skipped_line(left)})" if left else ""
        raise StarnavError(f"no image files in {', '.join(map(str, inputs))}{others}")
    return out


def skipped_line(skipped: Sequence[Path], at_most: int = 10) -> str:
    """The directories' entries that are not image files (``image_paths``), named in one
    line (the first ``at_most`` of them)."""
    names = [f"{p}/" if p.is_dir() else str(p) for p in skipped]
    more = f" and {len(names) - at_most} more" if len(names) > at_most else ""
    return (
        f"skipped {len(names)} {'entry' if len(names) == 1 else 'entries'} that are not image "
        f"files starnav reads: {', '.join(names[:at_most])}{more}"
    )


@dataclass(frozen=True)
class ImageOutputs:
    """Directories (None: not written) for each file's WCS header (``wcs_dir``), FITS copy
    with the WCS (``new_fits_dir``) and annotated picture (``annotate_dir``)."""

    wcs_dir: Path | None = None
    new_fits_dir: Path | None = None
    annotate_dir: Path | None = None

    @classmethod
    def make(cls, **dirs: str | Path | None) -> ImageOutputs:
        """The outputs of ``wcs``, ``new_fits``, ``annotate`` (directory names or None),
        the directories made; a one-line error when one is an existing file."""
        made = {}
        for kind, value in dirs.items():
            if value is None:
                continue
            path = Path(value)
            if path.exists() and not path.is_dir():
                flag = f"--{kind.replace('_', '-')}"
                raise StarnavError(f"{flag} of a batch is a directory, got {str(value)!r}")
            path.mkdir(parents=True, exist_ok=True)
            made[f"{kind}_dir"] = path
        return cls(**made)

    def paths(self, image: Path) -> dict[str, Path | None]:
        """The output paths of one image file, by kind ("wcs", "new_fits", "annotate")."""
        stem = image.name.split(".")[0] or image.name
        dirs = (self.wcs_dir, self.new_fits_dir, self.annotate_dir)
        names = (f"{stem}.wcs", f"{stem}.new.fits", f"{stem}.png")
        keys = ("wcs", "new_fits", "annotate")
        return {k: None if d is None else d / n for k, d, n in zip(keys, dirs, names, strict=True)}


@dataclass(frozen=True, eq=False)
class FileSolve:
    """One file of a batch: its JSON ``record`` (``ImageSolveResult.to_dict`` and the outputs
    written; for an error ``solved`` false and the reason "error: ..."), the ``solution``
    (None when unsolved; the next frame's prior in a sequence) and ``wall_ms``, the file's
    whole time in its process (reading, detection, solve, outputs)."""

    record: dict
    solution: Solution | None
    wall_ms: float

    @property
    def bad_input(self) -> bool:
        """The file could not be solved for a reason of its own (unreadable, ...)."""
        return self.solution is None and str(self.record.get("reason", "")).startswith("error:")

    def line(self) -> str:
        """One line of text: the file and its answer or why it has none."""
        r = self.record
        if not r.get("solved"):
            return f"{r['file']}: not solved: {r['reason']}"
        return (
            f"{r['file']}: RA {r['ra_deg']:.5f}° Dec {r['dec_deg']:+.5f}° roll "
            f"{r['roll_deg']:.4f}° FOV {r['fov_deg']:.4f}° parity {r['parity']:+d}, "
            f"{r['n_matched']} stars, {r['solve_ms']:.0f} ms"
            + (" (tracked)" if r.get("tracked") else "")
        )


def solve_file(
    path: Path, options: dict, outputs: ImageOutputs, prior: Solution | None = None
) -> FileSolve:
    """Read, solve (``solve_image`` with ``options``) and write the outputs of one file;
    ``prior``: the previous frame's solution of a sequence (its camera and attitude are
    used). Never raises for a problem of the file: it becomes the record's reason."""
    t0 = time.perf_counter()
    try:
        pixels = read_image(path)
        read_ms = (time.perf_counter() - t0) * 1e3
        opts = dict(options)
        opts.setdefault("hints", fits_hints(path))  # unless given (--no-hints: none)
        if prior is not None and prior.camera is not None:
            size = (prior.camera.width, prior.camera.height)
            if size == (pixels.shape[1], pixels.shape[0]):
                opts.update(camera=prior.camera, prior=prior.R_cam_from_icrs, fov_deg=None)
        res = replace(solve_image(pixels, **opts), read_ms=read_ms)
        written = write_outputs(outputs.paths(path), path, pixels, res)
    except StarnavError as exc:
        record = {"file": str(path), "solved": False, "reason": f"error: {exc}"}
        return FileSolve(record, None, (time.perf_counter() - t0) * 1e3)
    except Exception as exc:  # a bug must not stop the batch either: say what it was
        reason = f"error: internal error ({type(exc).__name__}: {exc})"
        record = {"file": str(path), "solved": False, "reason": reason}
        return FileSolve(record, None, (time.perf_counter() - t0) * 1e3)
    record = res.to_dict(str(path))
    record.update(written=written, tracked=prior is not None and res.solution is not None)
    return FileSolve(record, res.solution, (time.perf_counter() - t0) * 1e3)


def solve_run(
    paths: Sequence[Path],
    options: dict,
    outputs: ImageOutputs,
    track: bool,
    progress: Callable[[int], None] | None = None,
    prior: Solution | None = None,
) -> list[FileSolve]:
    """Files one after the other; with ``track`` each solved frame is the next one's prior
    (the first's: ``prior``); ``progress`` called with 1 per file."""
    out: list[FileSolve] = []
    for path in paths:
        done = solve_file(path, options, outputs, prior if track else None)
        prior = done.solution
        out.append(done)
        if progress:
            progress(1)
    return out


_WORKER: dict = {}


def _init(options: dict, outputs: ImageOutputs, track: bool) -> None:
    _WORKER.update(options=options, outputs=outputs, track=track)


def _run(job: tuple[list[Path], Solution | None]) -> list[FileSolve]:
    paths, prior = job
    return solve_run(paths, _WORKER["options"], _WORKER["outputs"], _WORKER["track"], None, prior)


def _runs(paths: Sequence[Path], workers: int, track: bool) -> list[list[Path]]:
    """Units of work: a sequence in ``workers`` contiguous runs, else one file each."""
    if not track:
        return [[p] for p in paths]
    size = math.ceil(len(paths) / workers)
    return [list(paths[k : k + size]) for k in range(0, len(paths), size)]


def solve_files(
    paths: Sequence[Path],
    options: dict,
    *,
    outputs: ImageOutputs | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    track: bool = False,
    progress: Callable[[int], None] | None = None,
) -> list[FileSolve]:
    """Solve every file of ``paths`` (options of ``solve_image``), in order; see the module.
    ``workers``: processes (default: all cores; 1: here); ``dask_address``: a Dask
    scheduler, or "local" for a LocalCluster of ``workers`` processes; ``track``: a
    sequence; ``progress``: called with the number of files finished."""
    outputs = outputs or ImageOutputs()
    workers = worker_count(workers)
    progress = progress or (lambda n: None)
    paths = list(paths)
    if dask_address:
        return _on_dask(paths, options, outputs, workers, dask_address, track, progress)
    if workers == 1 or len(paths) < 3:
        return solve_run(paths, options, outputs, track, progress)
    # the first file here: it loads the catalog, tables and machine code the workers share
    first = solve_file(paths[0], options, outputs)
    progress(1)
    rest = paths[1:]
    out = [first]
    with process_pool(workers, initializer=_init, initargs=(options, outputs, track)) as pool:
        runs = _runs(rest, workers, track)
        jobs = [(run, first.solution if k == 0 and track else None) for k, run in enumerate(runs)]
        for done in pool.map(_run, jobs):
            out.extend(done)
            progress(len(done))
    return out


def _on_dask(paths, options, outputs, workers, address, track, progress) -> list[FileSolve]:
    runs = _runs(paths, workers, track)
    with dask_client(address, workers) as (client, dask_completed):
        futures = client.map(
            solve_run,
            runs,
            [options] * len(runs),
            [outputs] * len(runs),
            [track] * len(runs),
            pure=False,
        )
        index = {f.key: k for k, f in enumerate(futures)}
        done: dict[int, list[FileSolve]] = {}
        for future in dask_completed(futures):
            done[index[future.key]] = future.result()
            progress(len(done[index[future.key]]))
    return [r for k in range(len(runs)) for r in done[k]]


@dataclass(frozen=True)
class BatchSummary:
    """A batch in numbers: ``files``, ``solved``, ``unsolved``, ``errors`` (bad input);
    ``wall_s`` the whole batch; per file after the first (ms, median): ``file_ms`` its
    whole time in its process, ``read_ms``, ``detect_ms``, ``solve_ms``; ``first_ms`` the
    first file's (which loads the catalog, tables and machine code)."""

    files: int
    solved: int
    unsolved: int
    errors: int
    wall_s: float
    first_ms: float
    file_ms: float | None
    read_ms: float | None
    detect_ms: float | None
    solve_ms: float | None

    def to_dict(self) -> dict:
        """The JSON form."""
        return dict(self.__dict__)

    def line(self) -> str:
        """The summary in one line of text."""

        def ms(v: float | None) -> str:
            return "n/a" if v is None else f"{v:.0f} ms"

        return (
            f"{self.files} files: {self.solved} solved, {self.unsolved} not solved, "
            f"{self.errors} errors; {self.wall_s:.1f} s in all; first file {self.first_ms:.0f} ms "
            f"(loads the catalog, tables and machine code); per file after it (median): "
            f"{ms(self.file_ms)} = read {ms(self.read_ms)} + detect {ms(self.detect_ms)} + "
            f"solve {ms(self.solve_ms)}"
        )


def summarize(results: Sequence[FileSolve], wall_s: float) -> BatchSummary:
    """The summary of a batch's ``results`` that took ``wall_s`` seconds."""
    errors = sum(r.bad_input for r in results)
    solved = sum(r.solution is not None for r in results)
    rest = [r for r in results[1:] if not r.bad_input]

    def median(values) -> float | None:
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    return BatchSummary(
        files=len(results),
        solved=solved,
        unsolved=len(results) - solved - errors,
        errors=errors,
        wall_s=wall_s,
        first_ms=results[0].wall_ms if results else 0.0,
        file_ms=median(r.wall_ms for r in rest),
        read_ms=median(r.record.get("read_ms") for r in rest),
        detect_ms=median(r.record.get("detect_ms") for r in rest),
        solve_ms=median(r.record.get("solve_ms") for r in rest),
    )
