"""Star lists solved as ``starnav identify`` solves them: one list with the field of view known
(``solve_verbose``, tracking when a prior is given) or unknown (``solve_fov`` searches it), or
a set of star-list files, read and then solved on all cores (``solve_batch``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.api import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    solve_batch,
    solve_verbose,
)
from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.errors import StarnavError
from starnav.identify import DEFAULT_ALGORITHM
from starnav.pipeline.fov import DEFAULT_FOV_RANGE_DEG
from starnav.results import Solution, SolveResult, solve_dict
from starnav.starlist import StarList, read_star_csv


def solve_star_list(
    stars: StarList,
    *,
    width: int | None = None,
    height: int | None = None,
    fov_deg: float | None = None,
    camera: CameraModel | str | Path | None = None,
    lens: str = "pinhole",
    fov_range_deg: tuple[float, float] = DEFAULT_FOV_RANGE_DEG,
    catalog: Catalog | str | Path | None = None,
    mag_limit: float | None = None,
    epoch_year: float | None = None,
    parity: int | None = None,
    sigma_px: float | None = None,
    fit_focal: bool = False,
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    algorithm: str = DEFAULT_ALGORITHM,
    algorithm_options: Mapping[str, object] | None = None,
    prior: np.ndarray | None = None,
    prior_sigma_deg: float = 1.0,
    time_budget_s: float | None = None,
    deep_mag_limit: float | None = None,
) -> SolveResult:
    """Solve one star list: with ``fov_deg`` or a ``camera`` (model or file) by
    ``solve_verbose`` (options as there), without them by ``solve_fov``, which searches
    ``fov_range_deg`` (for the ``lens`` model) and fits the focal length. The pinhole FOV
    search picks the catalog depth of each FOV band and identifies by 4-star patterns, so a
    ``prior``, another ``algorithm``, ``algorithm_options`` and ``mag_limit`` need ``fov_deg``
    (``StarnavError`` otherwise; a fisheye lens's scan takes ``mag_limit``);
    ``deep_mag_limit``: the deep stage's depth (``starnav.pipeline.deep``), either way."""
    if fov_deg is None and camera is None:
        from starnav.pipeline.fov import solve_fov

        needing = {
            "prior": prior is not None,
            "algorithm": algorithm != DEFAULT_ALGORITHM,
            "algorithm_options": bool(algorithm_options),
            "mag_limit": mag_limit is not None and lens == "pinhole",
        }
        if any(needing.values()):
            names = ", ".join(name for name, given in needing.items() if given)
            raise StarnavError(f"{names} need fov_deg (the FOV search chooses its own)")
        return solve_fov(
            stars.xy,
            width=width,
            height=height,
            brightness=stars.brightness,
            labels=stars.labels,
            fov_range_deg=tuple(fov_range_deg),
            lens=lens,
            mag_limit=mag_limit,
            catalog=catalog,
            epoch_year=epoch_year,
            parity=parity,
            sigma_px=sigma_px,
            max_false_match_probability=max_false_match_probability,
            time_budget_s=time_budget_s,
            deep_mag_limit=deep_mag_limit,
        )
    return solve_verbose(
        stars.xy,
        width=width,
        height=height,
        fov_deg=fov_deg,
        camera=camera,
        lens=lens,
        brightness=stars.brightness,
        labels=stars.labels,
        catalog=catalog,
        mag_limit=mag_limit,
        epoch_year=epoch_year,
        parity=parity,
        sigma_px=sigma_px,
        fit_focal=fit_focal,
        max_false_match_probability=max_false_match_probability,
        algorithm=algorithm,
        algorithm_options=algorithm_options,
        prior=prior,
        prior_sigma_deg=prior_sigma_deg,
        time_budget_s=time_budget_s,
        deep_mag_limit=deep_mag_limit,
    )


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
    """One star-list file solved: the ``solution`` (None with the ``reason`` when unsolved; a
    reason starting with "error:" is bad input) and ``time_ms`` (None: the file was not read)."""

    path: Path
    solution: Solution | None
    reason: str
    time_ms: float | None

    @property
    def bad_input(self) -> bool:
        """The file could not be read or its list was refused (not merely unsolved)."""
        return self.solution is None and self.reason.startswith("error:")

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
    *,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    **options: object,
) -> list[FileResult]:
    """Solve the lists read (``solve_batch``: same camera and ``options``, ``fov_deg``
    included, on ``workers`` processes; ``progress`` called per list finished); one result
    per path in order, the files not read with "error: ..." reasons."""
    if options.get("fov_deg") is None and options.get("camera") is None:
        raise StarnavError("a set of star lists needs fov_deg or a camera")
    read = [p for p in files.paths if p in files.lists]
    results = solve_batch(
        [files.lists[p].xy for p in read],
        brightness=[files.lists[p].brightness for p in read],
        workers=workers,
        progress=progress,
        **options,
    )
    solved = dict(zip(read, results, strict=True))
    out = []
    for path in files.paths:
        if path in files.errors:
            out.append(FileResult(path, None, f"error: {files.errors[path]}", None))
        else:
            solution, reason, ms = solved[path]
            out.append(FileResult(path, solution, reason, ms))
    return out
