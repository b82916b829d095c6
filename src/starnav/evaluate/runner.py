"""Lost-in-space evaluation: simulate frames, solve them with the real solve path, score them.

Frames are remade from (seed, index) wherever they are solved, so a run is the same on one core,
on N processes or on a Dask cluster. Each frame's outcome is data (``FrameResult``), never an
exception half way through a run (the sgp4 batch style): a frame the simulator leaves with fewer
than 3 points is scored "none" with that reason. Besides the simulated sky, frames can be
adversarial (``starnav.evaluate.kinds``): frame i is of kind ``kinds[i % len(kinds)]``.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import as_completed
from dataclasses import asdict, dataclass

import numpy as np
from tqdm import tqdm

from starnav.camera import Camera, CameraModel, camera_from_dict
from starnav.catalog import load_catalog
from starnav.errors import StarnavError, shown
from starnav.evaluate.kinds import KINDS, NO_ANSWER_KINDS, make_frame, parse_kinds
from starnav.evaluate.sampling import Boresights, frame_rng
from starnav.evaluate.score import score_solution
from starnav.geometry import angle_between
from starnav.identify import make_identifier
from starnav.pipeline import (
    DEFAULT_MAX_FALSE_MATCH_PROBABILITY,
    Solver,
    SolveSettings,
    get_database,
)
from starnav.runtime.caches import process_cache
from starnav.runtime.pools import dask_client, process_pool
from starnav.simulate import FALSE_STAR_ID, SimulatedFrame, simulate_frame
from starnav.starlist import check_star_list

STAR_COUNT_BINS = ("0-2", "3", "4", "5", "6", ">=7")  # true stars among a frame's points
STAR_COUNT_KINDS = ("true", "few", "crowded")  # kinds broken down by those bins
_CHUNK = 40  # frames per task sent to a worker


@dataclass(frozen=True)
class EvalConfig:
    """Everything that defines the frames and how they are solved.

    Camera: ``camera``, a camera file's items ((key, value) pairs of ``CameraModel.to_dict``,
    any lens model; see ``camera_items``), else a pinhole of ``fov_deg`` (horizontal) across
    ``width``/``height`` (px); ``make_camera`` makes it. Stars to Hipparcos ``mag_limit``.
    Errors: ``noise_px`` (1-sigma centroid noise), ``false_stars`` per frame, ``missing_frac``
    of stars dropped, ``mag_noise`` (1-sigma, magnitudes; changes the brightness order).
    Solver: ``algorithm``, its ``algorithm_options`` ((name, value) pairs), ``sigma_px`` told to it,
    ``max_false_match_probability``. ``seed`` makes every frame reproducible; ``kinds``: the
    kinds of frame (``starnav.evaluate.kinds.KINDS``), frame i of ``kinds[i % len(kinds)]``.
    """

    fov_deg: float = 12.0
    width: int = 512
    height: int | None = None
    mag_limit: float = 6.0
    noise_px: float = 0.5
    false_stars: int = 2
    missing_frac: float = 0.1
    mag_noise: float = 0.0
    algorithm: str = "pyramid"
    algorithm_options: tuple[tuple[str, object], ...] = ()  # (name, value): hashable
    sigma_px: float | None = None
    max_false_match_probability: float = DEFAULT_MAX_FALSE_MATCH_PROBABILITY
    seed: int = 0
    camera: tuple[tuple[str, object], ...] = ()  # (key, value): hashable and picklable
    kinds: tuple[str, ...] = ("true",)

    def kind(self, index: int) -> str:
        """The kind of frame ``index``."""
        return self.kinds[index % len(self.kinds)]

    def make_camera(self) -> CameraModel:
        """The camera the frames are simulated and solved with."""
        if self.camera:
            return camera_from_dict(dict(self.camera), "the evaluation's camera")
        return Camera.from_fov(self.fov_deg, self.width, self.height)

    @property
    def solver_sigma_px(self) -> float:
        """The centroid sigma the solver is told: ``sigma_px``, else the noise (>= 0.1 px)."""
        return self.sigma_px if self.sigma_px is not None else max(self.noise_px, 0.1)

    def check(self) -> None:
        """Raise ``StarnavError`` naming the first bad value."""
        camera = self.make_camera()
        make_identifier(self.algorithm, **self.identifier_options)
        if not (np.isfinite(self.mag_limit) and -2.0 <= self.mag_limit <= 12.0):
            raise StarnavError(f"mag limit must be between -2 and 12, got {shown(self.mag_limit)}")
        if self.sigma_px is not None and not (np.isfinite(self.sigma_px) and self.sigma_px > 0):
            raise StarnavError(f"sigma_px must be a positive number of pixels, got {self.sigma_px}")
        if parse_kinds(",".join(self.kinds)) != tuple(self.kinds):
            raise StarnavError(f"kinds must be distinct names of {KINDS}, got {self.kinds!r}")
        SolveSettings(max_false_match_probability=self.max_false_match_probability)
        # the simulator checks noise, false stars and the missing fraction
        simulate_frame(
            load_catalog(None, mag_limit=self.mag_limit),
            camera,
            noise_px=self.noise_px,
            false_stars=self.false_stars,
            missing_frac=self.missing_frac,
            mag_noise=self.mag_noise,
            seed=0,
        )

    @property
    def identifier_options(self) -> dict:
        return dict(self.algorithm_options)


def camera_items(camera: CameraModel) -> tuple[tuple[str, object], ...]:
    """``EvalConfig.camera`` for ``camera``."""
    return tuple(camera.to_dict().items())


@dataclass(frozen=True)
class FrameResult:
    """One frame: its boresight and roll (degrees), ``n_in_view`` catalog stars inside the
    image, ``n_points`` points given to the solver of which ``n_true`` are real stars,
    ``outcome`` (correct / wrong / none), ``time_ms`` (identification and fit), stars
    identified and wrongly identified, attitude errors (None when not solved), whether the
    errors are beyond the fixed tolerance (0.05° / 0.5°: "correct" then means within 5 of
    the solver's own 1-sigma, as with 2 px noise and few stars), and the solver's reason
    when it refused. ``kind``: the kind of frame (``starnav.evaluate.kinds``);
    ``false_match_probability``: the solver's claim for its answer (NaN when not solved);
    ``focal_factor``: the focal length that made the points over the solver's (1 but for
    ``fov-off`` frames)."""

    index: int
    ra_deg: float
    dec_deg: float
    roll_deg: float
    n_in_view: int
    n_points: int
    n_true: int
    outcome: str
    time_ms: float
    n_identified: int
    n_wrong_ids: int
    boresight_error_arcsec: float | None
    roll_error_arcsec: float | None
    beyond_tolerance: bool
    reason: str
    kind: str = "true"
    false_match_probability: float = float("nan")
    focal_factor: float = 1.0


_SOLVERS = process_cache("evaluation solvers")


def config_solver(config: EvalConfig) -> Solver:
    """The prepared solver of a configuration (one per process)."""
    solver = _SOLVERS.get(config)
    if solver is None:
        solver = _SOLVERS[config] = Solver(
            config.make_camera(),
            load_catalog(None, mag_limit=config.mag_limit),
            config.algorithm,
            SolveSettings(
                sigma_px=config.solver_sigma_px,
                max_false_match_probability=config.max_false_match_probability,
            ),
            algorithm_options=config.identifier_options,
        )
    return solver


def config_frame(
    config: EvalConfig, boresights: Boresights, index: int
) -> tuple[SimulatedFrame, float]:
    """Frame ``index`` of ``boresights`` as ``config`` makes it (its kind, errors and
    generator ``frame_rng(seed, index)``) and its focal factor (``kinds.make_frame``)."""
    solver = config_solver(config)
    return make_frame(
        config.kind(index),
        solver.catalog,
        solver.camera,
        frame_rng(config.seed, index),
        ra_deg=float(boresights.ra_deg[index]),
        dec_deg=float(boresights.dec_deg[index]),
        roll_deg=float(boresights.roll_deg[index]),
        noise_px=config.noise_px,
        false_stars=config.false_stars,
        missing_frac=config.missing_frac,
        mag_noise=config.mag_noise,
        mag_limit=config.mag_limit,
    )


def solve_frame(config: EvalConfig, boresights: Boresights, index: int) -> FrameResult:
    """Simulate frame ``index`` of ``boresights`` and score the solver's answer."""
    solver = config_solver(config)
    catalog, camera = solver.catalog, solver.camera
    ra, dec, roll = (
        float(boresights.ra_deg[index]),
        float(boresights.dec_deg[index]),
        float(boresights.roll_deg[index]),
    )
    kind = config.kind(index)
    frame, focal_factor = config_frame(config, boresights, index)
    n_true = int(np.sum(frame.true_id != FALSE_STAR_ID))
    common = dict(
        index=index,
        ra_deg=ra,
        dec_deg=dec,
        roll_deg=roll,
        n_in_view=frame.n_in_view,
        n_points=len(frame.xy),
        n_true=n_true,
        kind=kind,
        focal_factor=focal_factor,
    )
    if len(frame.xy) < 3:
        return FrameResult(
            **common,
            outcome="none",
            time_ms=0.0,
            n_identified=0,
            n_wrong_ids=0,
            boresight_error_arcsec=None,
            roll_error_arcsec=None,
            beyond_tolerance=False,
            reason=f"{len(frame.xy)} points in the image (3 needed)",
        )
    stars = check_star_list(
        frame.xy, width=camera.width, height=camera.height, brightness=frame.brightness
    )
    result = solver.solve(stars)
    s = result.solution
    if s is None:
        return FrameResult(
            **common,
            outcome="none",
            time_ms=result.time_ms,
            n_identified=0,
            n_wrong_ids=0,
            boresight_error_arcsec=None,
            roll_error_arcsec=None,
            beyond_tolerance=False,
            reason=result.reason,
        )
    score = score_solution(s, frame.R_cam_from_icrs)  # the rule of starnav.evaluate.score
    ids = s.star_table.catalog_id
    correct = kind not in NO_ANSWER_KINDS and score.correct
    return FrameResult(
        **common,
        outcome="correct" if correct else "wrong",
        time_ms=s.time_ms,
        n_identified=int(np.sum(ids != -1)),
        n_wrong_ids=_wrong_ids(ids, frame.true_id, catalog, camera, config.noise_px),
        boresight_error_arcsec=score.boresight_arcsec,
        roll_error_arcsec=score.roll_arcsec,
        beyond_tolerance=not score.within_tolerance,
        reason="",
        false_match_probability=float(s.false_match_probability),
    )


def _wrong_ids(ids, true_ids, catalog, camera, noise_px: float) -> int:
    """Points given a catalog id other than their own. A star confused with a catalog
    neighbour closer than max(1 px, 3 noise sigma) is not counted: such doubles cannot be told
    apart at that noise (the neighbour may be the one the simulator dropped). Pixels become
    angles at the lens's coarsest scale (the focal length of a pinhole)."""
    differ = np.flatnonzero((ids != -1) & (ids != true_ids))
    if len(differ) == 0:
        return 0
    close_rad = max(1.0, 3.0 * noise_px) / camera.scale_px_per_rad
    wrong = 0
    for n in differ:
        if true_ids[n] == FALSE_STAR_ID:
            wrong += 1
            continue
        a, b = catalog.vectors[catalog.rows([ids[n], true_ids[n]])]
        wrong += bool(angle_between(a, b) > close_rad)
    return wrong


_WARMED_UP = False  # whether this process has solved a frame


def solve_chunk(
    config: EvalConfig, boresights: Boresights, indices: Sequence[int]
) -> list[FrameResult]:
    """``solve_frame`` for each of ``indices`` (one task of a worker). The first task of a
    process solves its first frame once beforehand, untimed: that loads the machine code,
    which is no frame's time."""
    global _WARMED_UP
    if not _WARMED_UP and len(indices):
        solve_frame(config, boresights, int(indices[0]))
        _WARMED_UP = True
    return [solve_frame(config, boresights, int(i)) for i in indices]


def prepare(config: EvalConfig) -> int:
    """Load the catalog and build (or load) every table the algorithm searches, so workers
    find them in the disk cache; returns their size in bytes."""
    config.check()
    catalog = load_catalog(None, mag_limit=config.mag_limit)
    database = get_database(catalog, config.make_camera())
    return make_identifier(config.algorithm, **config.identifier_options).database_nbytes(database)


def _chunks(n: int, size: int) -> list[list[int]]:
    return [list(range(k, min(k + size, n))) for k in range(0, n, size)]


def _serial(config, boresights, chunks) -> Iterator[list[FrameResult]]:
    for chunk in chunks:
        yield solve_chunk(config, boresights, chunk)


def _processes(config, boresights, chunks, workers) -> Iterator[list[FrameResult]]:
    # spawn: fresh interpreters read the one-BLAS-thread setting
    with process_pool(workers, start="spawn") as pool:
        futures = [pool.submit(solve_chunk, config, boresights, c) for c in chunks]
        for future in as_completed(futures):
            yield future.result()


def _dask(config, boresights, chunks, address, workers) -> Iterator[list[FrameResult]]:
    with dask_client(address, workers) as (client, dask_completed):
        # the workers build their own tables from their disk cache (or once, if remote)
        futures = client.map(
            solve_chunk, [config] * len(chunks), [boresights] * len(chunks), chunks, pure=False
        )
        for future in dask_completed(futures):
            yield future.result()


def run_evaluation(
    config: EvalConfig,
    boresights: Boresights,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[FrameResult]:
    """Solve every frame of ``boresights``; results in frame order.

    ``workers``: processes (default all cores; 1 runs in this process); ``dask_address``: a
    Dask scheduler address, or "local" for a LocalCluster of ``workers`` processes;
    ``progress``: called with the number of frames finished by each task.
    """
    workers = workers or os.cpu_count() or 1
    chunks = _chunks(len(boresights), _CHUNK)
    if dask_address:
        stream = _dask(config, boresights, chunks, dask_address, workers)
    elif workers == 1:
        stream = _serial(config, boresights, chunks)
    else:
        stream = _processes(config, boresights, chunks, workers)
    results: list[FrameResult] = []
    for chunk in stream:
        results.extend(chunk)
        if progress:
            progress(len(chunk))
    return sorted(results, key=lambda r: r.index)


@dataclass(frozen=True)
class OutcomeCounts:
    """Outcomes of the frames of one ``kind`` (and, when ``true_stars`` is not empty, of
    those with that many true stars among their points, one of ``STAR_COUNT_BINS``); times
    in ms over the frames that reached the solver (NaN when none did)."""

    kind: str
    true_stars: str
    frames: int
    correct: int
    wrong: int
    none: int
    median_ms: float
    p95_ms: float

    def to_dict(self) -> dict:
        return {k: v for k, v in asdict(self).items() if k not in ("kind", "true_stars")}


def star_count_bin(n_true: int) -> str:
    """The ``STAR_COUNT_BINS`` label of ``n_true`` true stars."""
    return "0-2" if n_true < 3 else ">=7" if n_true >= 7 else str(n_true)


def _solver_times(results: Sequence[FrameResult]) -> np.ndarray:
    """Times (ms) of the frames that reached the solver ([NaN] when none did)."""
    return np.array([r.time_ms for r in results if r.n_points >= 3] or [np.nan])


def _counts(kind: str, true_stars: str, results: Sequence[FrameResult]) -> OutcomeCounts:
    times = _solver_times(results)
    return OutcomeCounts(
        kind=kind,
        true_stars=true_stars,
        frames=len(results),
        correct=sum(r.outcome == "correct" for r in results),
        wrong=sum(r.outcome == "wrong" for r in results),
        none=sum(r.outcome == "none" for r in results),
        median_ms=float(np.nanmedian(times)) if np.isfinite(times).any() else float("nan"),
        p95_ms=float(np.nanpercentile(times, 95)) if np.isfinite(times).any() else float("nan"),
    )


def breakdown(
    results: Sequence[FrameResult],
) -> tuple[tuple[OutcomeCounts, ...], tuple[OutcomeCounts, ...]]:
    """Outcomes by kind (kinds in ``KINDS`` order), and for the kinds of
    ``STAR_COUNT_KINDS`` by the number of true stars among the points (empty bins left out)."""
    by_kind, by_stars = [], []
    for kind in KINDS:
        rs = [r for r in results if r.kind == kind]
        if not rs:
            continue
        by_kind.append(_counts(kind, "", rs))
        if kind in STAR_COUNT_KINDS:
            for label in STAR_COUNT_BINS:
                in_bin = [r for r in rs if star_count_bin(r.n_true) == label]
                if in_bin:
                    by_stars.append(_counts(kind, label, in_bin))
    return tuple(by_kind), tuple(by_stars)


@dataclass(frozen=True)
class Summary:
    """Counts and rates of an evaluation (rates are fractions of ``frames``); ``*_ge4``: the
    same over frames with at least 4 real stars among the points; ``imprecise``: correct
    frames beyond the fixed tolerance (within 5 of their reported sigmas); times in ms over
    frames that reached the solver; ``db_bytes``: the tables searched; ``wall_s``: elapsed time;
    ``by_kind``, ``by_true_stars``: the outcomes broken down (``breakdown``)."""

    frames: int
    correct: int
    wrong: int
    none: int
    imprecise: int
    correct_rate: float
    wrong_rate: float
    frames_ge4: int
    correct_rate_ge4: float
    wrong_ids: int
    median_ms: float
    p95_ms: float
    max_ms: float
    median_boresight_error_arcsec: float | None
    db_bytes: int
    wall_s: float
    by_kind: tuple[OutcomeCounts, ...] = ()
    by_true_stars: tuple[OutcomeCounts, ...] = ()

    def to_dict(self) -> dict:
        """The fields; ``by_kind`` as {kind: counts}, ``by_true_stars`` as
        {kind: {bin: counts}}."""
        d = {k: v for k, v in asdict(self).items() if k not in ("by_kind", "by_true_stars")}
        d["by_kind"] = {c.kind: c.to_dict() for c in self.by_kind}
        stars: dict[str, dict] = {}
        for c in self.by_true_stars:
            stars.setdefault(c.kind, {})[c.true_stars] = c.to_dict()
        d["by_true_stars"] = stars
        return d


def summarize(results: Sequence[FrameResult], *, db_bytes: int, wall_s: float) -> Summary:
    """Aggregate frame results."""
    n = len(results)
    every = _counts("", "", results)
    ge4 = [r for r in results if r.n_true >= 4]
    errors = [r.boresight_error_arcsec for r in results if r.outcome == "correct"]
    by_kind, by_true_stars = breakdown(results)
    return Summary(
        frames=n,
        correct=every.correct,
        wrong=every.wrong,
        none=every.none,
        imprecise=sum(r.outcome == "correct" and r.beyond_tolerance for r in results),
        correct_rate=every.correct / n if n else 0.0,
        wrong_rate=every.wrong / n if n else 0.0,
        frames_ge4=len(ge4),
        correct_rate_ge4=(sum(r.outcome == "correct" for r in ge4) / len(ge4)) if ge4 else 0.0,
        wrong_ids=sum(r.n_wrong_ids for r in results),
        median_ms=every.median_ms,
        p95_ms=every.p95_ms,
        max_ms=float(np.nanmax(_solver_times(results))),
        median_boresight_error_arcsec=float(np.median(errors)) if errors else None,
        db_bytes=db_bytes,
        wall_s=wall_s,
        by_kind=by_kind,
        by_true_stars=by_true_stars,
    )


def evaluate(
    config: EvalConfig,
    boresights: Boresights,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    progress_bar: bool = True,
) -> tuple[Summary, list[FrameResult]]:
    """Prepare the tables, run every frame (progress bar on stderr) and summarise."""
    db_bytes = prepare(config)
    t0 = time.perf_counter()
    with tqdm(
        total=len(boresights),
        desc=f"{config.algorithm}",
        unit="frame",
        file=sys.stderr,
        disable=not progress_bar,
    ) as bar:
        results = run_evaluation(
            config, boresights, workers=workers, dask_address=dask_address, progress=bar.update
        )
    return summarize(results, db_bytes=db_bytes, wall_s=time.perf_counter() - t0), results
