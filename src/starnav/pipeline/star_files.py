"""A set of star-list files, read and then solved on all cores (``pipeline.batch``), as
``starnav identify DIRECTORY`` solves them; a file that cannot be read is reported, not raised.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from starnav.errors import StarnavError
from starnav.pipeline.batch import solve_frames
from starnav.pipeline.options import SolveOptions
from starnav.results import Solution, solve_dict
from starnav.starlist import StarList, read_star_csv


@dataclass(frozen=True)
class StarFiles:
    """Star-list files read: ``paths`` in order, ``lists`` of those read (path -> StarList),
    ``errors`` of those that could not be (path -> the one-line message)."""

    paths: tuple[Path, ...]
    lists: dict[Path, StarList]
    errors: dict[Path, str]


def read_star_files(paths: Sequence[str | Path]) -> StarFiles:
    """Read every star-list CSV of ``paths``; a file that cannot be read is recorded in
    ``errors``, not raised."""
    lists, errors = {}, {}
    for path in map(Path, paths):
        try:
            lists[path] = read_star_csv(path)
        except StarnavError as exc:
            errors[path] = str(exc)
    return StarFiles(tuple(map(Path, paths)), lists, errors)


@dataclass(frozen=True, eq=False)
class FileResult:
    """One star-list file solved: the ``solution`` (None with the ``reason`` when unsolved;
    "error: ..." for bad input), ``time_ms`` (None: the file was not read) and ``error``,
    the one-line message when the file could not be read or its list was refused."""

    path: Path
    solution: Solution | None
    reason: str
    time_ms: float | None
    error: str | None = None

    @property
    def bad_input(self) -> bool:
        """The file could not be read or its list was refused (not merely unsolved)."""
        return self.error is not None

    def to_dict(self) -> dict:
        """One JSON line: ``file``, then the solve's JSON (``solve_dict``) or ``solved``
        false, ``reason`` and ``time_ms`` (left out for a file not read)."""
        out: dict = {"file": str(self.path)}
        if self.solution is not None:
            out.update(solve_dict(self.solution), reason=None, time_ms=self.time_ms)
            return out
        out.update(solved=False, reason=self.reason)
        if self.time_ms is not None:
            out["time_ms"] = self.time_ms
        return out


def solve_star_files(
    files: StarFiles,
    options: SolveOptions,
    *,
    width: float | None = None,
    height: float | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[FileResult]:
    """Solve the lists read (``pipeline.batch.solve_frames``: one known field, ``options``,
    on ``workers`` processes; ``progress`` called per list finished); one result per path in
    order, the files not read with their ``error``."""
    read = [p for p in files.paths if p in files.lists]
    results = solve_frames(
        [files.lists[p].xy for p in read],
        options,
        width=width,
        height=height,
        brightness=[files.lists[p].brightness for p in read],
        workers=workers,
        progress=progress,
    )
    solved = dict(zip(read, results, strict=True))
    out = []
    for path in files.paths:
        if path in files.errors:
            error = files.errors[path]
            out.append(FileResult(path, None, f"error: {error}", None, error))
        else:
            r = solved[path]
            reason = r.reason if r.error is None else f"error: {r.error}"
            out.append(FileResult(path, r.solution, reason, r.time_ms, r.error))
    return out
