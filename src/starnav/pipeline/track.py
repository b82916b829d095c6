"""A stream of frames of one camera, each answered as it comes: tracking from the last attitude,
lost in space when there is none to track from.

A frame is one JSON object (one line of a stream, ``parse_frame``)::

    {"x": [...], "y": [...]}            or  {"xy": [[x, y], ...]}      pixels, origin top-left
    "brightness": [...] or "mag": [...]  optional, one per point (larger / smaller is brighter)
    "t": seconds                         optional, any epoch, the time the frame was taken
    "id": "..." or 17                    optional, echoed in the answer

Keys starting with ``true_`` (a simulation's truth carried beside the input) are ignored;
other keys are refused, as a star list's unknown columns are.

``Tracker`` holds the prepared ``Solver`` of the camera and the last solved attitude. A frame
is tracked from that attitude (``Solver.solve`` with it as the prior, which falls back to lost
in space by itself) when the last solved frame is at most ``max_gap_s`` older, by the frames'
``t`` or, for frames without one, by the clock when each was received; otherwise it is solved
lost in space. A frame that cannot be read is answered with its ``error`` and changes
nothing. ``TrackAnswer.to_dict`` is the line written per frame (``TRACK_KEYS``).
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from starnav.errors import StarListError, StarnavError, shown
from starnav.pipeline.conclude import elapsed_ms
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.solver import Solver
from starnav.pipeline.stars import known_budget_s, prepare_solver
from starnav.results import Solution, SolveResult
from starnav.runtime.budget import Deadline, check_budget
from starnav.starlist import StarList, brightness_of_mag, check_star_list

_log = logging.getLogger(__name__)
DEFAULT_MAX_GAP_S = 1.0  # track from an attitude at most this old (s)
TRACKED, LOST_IN_SPACE = "tracked", "lost_in_space"
# the warm-up's boresights: crowded and sparse fields, north and south (the paths of a solve)
WARM_UP_RADEC_DEG = ((10.0, 20.0), (83.8, -5.4), (200.0, 60.0), (280.0, -30.0))
WARM_UP_DEEP_MAG = 9.0  # with a deep stage, the warm-up frames hold stars to this magnitude
# the keys of every answer line, in this order (null where they do not apply)
TRACK_KEYS = (
    "frame",
    "id",
    "t",
    "solved",
    "mode",
    "prior_frame",
    "q_cam_from_icrs_xyzw",
    "ra_deg",
    "dec_deg",
    "roll_deg",
    "parity",
    "cov_cam_rad2",
    "sigma_boresight_arcsec",
    "sigma_roll_arcsec",
    "n_matched",
    "ids",
    "rms_px",
    "false_match_probability",
    "time_ms",
    "reason",
    "error",
)
_POSITIONS = {"x", "y", "xy"}
_KEYS = _POSITIONS | {"brightness", "mag", "t", "id"}
_FORMAT = 'a frame is {"x": [...], "y": [...]} or {"xy": [[x, y], ...]}, with optional '
_FORMAT += '"brightness" or "mag", "t" (s) and "id"'


@dataclass(frozen=True, eq=False)
class TrackFrame:
    """One frame of the stream: its ``stars`` (checked against the image), ``t_s`` (seconds,
    any epoch; None: not given) and ``id`` (echoed; None: not given)."""

    stars: StarList
    t_s: float | None = None
    id: str | int | None = None


@dataclass(frozen=True, eq=False)
class TrackAnswer:
    """The answer to frame number ``frame`` (0-based, counting every frame received, bad ones
    too) with the frame's ``id`` and ``t_s``: the ``solution`` or None; ``mode``
    (``TRACKED`` when the search near the prior answered, ``LOST_IN_SPACE`` when the whole
    sky did; None: not solved); ``prior_frame``: the frame whose attitude was the prior (None:
    none, solved lost in space); ``reason`` why there is no solution; ``error``: the frame
    could not be read (the message; then ``reason`` is the same); ``time_ms``: wall time from
    the line received to the answer made (reading, checking, solving; not ``to_dict``)."""

    frame: int
    solution: Solution | None
    time_ms: float
    mode: str | None = None
    prior_frame: int | None = None
    reason: str | None = None
    error: str | None = None
    id: str | int | None = None
    t_s: float | None = None

    @property
    def solved(self) -> bool:
        """Whether the frame has a solution."""
        return self.solution is not None

    def to_dict(self) -> dict:
        """The answer line, keys ``TRACK_KEYS``: the attitude as ``q_cam_from_icrs_xyzw``
        (the quaternion of ``R_cam_from_icrs``, scalar last, w >= 0: it takes a direction's
        ICRS components to its camera components; null for a mirrored image, parity -1,
        which no rotation gives) and RA/Dec/roll (degrees) with the parity; ``cov_cam_rad2``
        the covariance of the attitude error as a small rotation about the camera axes (x
        right, y down, z boresight; rad²); ``ids`` the catalog id of every point in input
        order (null: not a catalog star)."""
        out = dict.fromkeys(TRACK_KEYS)
        out.update(
            frame=self.frame,
            id=self.id,
            t=self.t_s,
            solved=self.solved,
            mode=self.mode,
            prior_frame=self.prior_frame,
            time_ms=self.time_ms,
            reason=self.reason,
            error=self.error,
        )
        s = self.solution
        if s is None:
            return out
        out.update(
            q_cam_from_icrs_xyzw=quaternion_xyzw(s.R_cam_from_icrs),
            ra_deg=s.ra_deg,
            dec_deg=s.dec_deg,
            roll_deg=s.roll_deg,
            parity=s.parity,
            sigma_boresight_arcsec=s.sigma_boresight_arcsec,
            sigma_roll_arcsec=s.sigma_roll_arcsec,
            n_matched=s.n_matched,
            ids=[m.catalog_id for m in s.stars],
            rms_px=s.rms_px,
            false_match_probability=s.false_match_probability,
        )
        if s.rotation_cov_rad2 is not None:
            out["cov_cam_rad2"] = np.asarray(s.rotation_cov_rad2).tolist()
        return out


def quaternion_xyzw(R_cam_from_icrs: np.ndarray) -> list[float] | None:
    """The unit quaternion [x, y, z, w] (scalar last, w >= 0) of the rotation
    ``R_cam_from_icrs`` (v_cam = R v_icrs), or None for a reflection (parity -1)."""
    R = np.asarray(R_cam_from_icrs, dtype=float)
    if np.linalg.det(R) < 0:
        return None
    from scipy.spatial.transform import Rotation  # only when a stream answers

    return Rotation.from_matrix(R).as_quat(canonical=True).tolist()


def parse_frame(line: bytes | str, *, width: float, height: float) -> TrackFrame:
    """The frame of one line of JSON (the module's format), its points checked against a
    ``width`` x ``height`` px image (``check_star_list``); a one-line ``StarListError``
    naming what is wrong otherwise."""
    if isinstance(line, bytes):
        try:
            line = line.decode("utf-8")
        except UnicodeDecodeError:
            raise StarListError("the line is not UTF-8 text") from None
    try:
        obj = json.loads(line)
    except (ValueError, RecursionError) as exc:
        raise StarListError(f"not JSON ({getattr(exc, 'msg', exc)}): {_FORMAT}") from None
    if not isinstance(obj, dict):
        raise StarListError(f"got a JSON {type(obj).__name__}: {_FORMAT}")
    unknown = sorted(k for k in obj if k not in _KEYS and not k.startswith("true_"))
    if unknown:
        raise StarListError(
            f"unknown key{'s' * (len(unknown) > 1)} {', '.join(unknown)}: {_FORMAT}"
        )
    frame_id = obj.get("id")
    if isinstance(frame_id, bool) or not isinstance(frame_id, str | int | None):
        raise StarListError(f'"id" must be a string or a whole number, got {shown(frame_id)}')
    t_s = obj.get("t")
    if t_s is not None and not _finite(t_s):
        raise StarListError(f'"t" must be a finite number of seconds, got {shown(t_s)}')
    brightness = _brightness(obj)
    stars = check_star_list(_positions(obj), width=width, height=height, brightness=brightness)
    return TrackFrame(stars, None if t_s is None else float(t_s), frame_id)


def _positions(obj: dict) -> np.ndarray:
    """The (n, 2) positions of ``"xy"`` or of ``"x"`` and ``"y"``."""
    given = _POSITIONS & set(obj)
    if given == {"xy"}:
        xy = obj["xy"]
        if not isinstance(xy, list) or not all(isinstance(p, list) and len(p) == 2 for p in xy):
            raise StarListError('"xy" must be a list of [x, y] pairs')
        return np.array([_numbers(p, "xy") for p in xy], dtype=float).reshape(-1, 2)
    if given == {"x", "y"}:
        x, y = _numbers(obj["x"], "x"), _numbers(obj["y"], "y")
        if len(x) != len(y):
            raise StarListError(f'"x" has {len(x)} numbers, "y" {len(y)}')
        return np.column_stack([x, y])
    raise StarListError(f"give the positions once, as x and y or as xy: {_FORMAT}")


def _brightness(obj: dict) -> np.ndarray | None:
    """Brightness per point (larger is brighter) from ``"brightness"`` or ``"mag"``."""
    if "brightness" in obj and "mag" in obj:
        raise StarListError('give "brightness" or "mag", not both')
    if "brightness" in obj:
        return _numbers(obj["brightness"], "brightness")
    if "mag" in obj:
        return brightness_of_mag(_numbers(obj["mag"], "mag"))  # as a star list's mag column
    return None


def _numbers(value: object, name: str) -> np.ndarray:
    """A JSON list of numbers as an array (NaN and infinities pass: the star list check
    names the point that has one)."""
    if isinstance(value, list) and all(_is_number(v) for v in value):
        try:
            return np.array(value, dtype=float)
        except OverflowError:  # a whole number beyond any float
            pass
    raise StarListError(f'"{name}" must be a list of numbers (within ±1.8e308)')


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _finite(value: object) -> bool:
    """A number a float holds, not NaN or infinite."""
    try:
        return _is_number(value) and math.isfinite(value)
    except OverflowError:  # a whole number beyond any float
        return False


@dataclass(frozen=True)
class _Solved:
    """The last solved frame: its attitude, number and time (and on which clock)."""

    R_cam_from_icrs: np.ndarray
    frame: int
    t_s: float
    frame_clock: bool  # t_s is the frame's own "t" (else the receiving clock's)


class Tracker:
    """Answers the frames of one camera in order (``answer``): tracking from the last solved
    attitude while it is at most ``max_gap_s`` old, good to ``prior_sigma_deg`` (1-sigma),
    else lost in space. ``solver``: the prepared ``Solver`` of the camera; ``budget_s``: each
    frame's time budget (s); ``clock``: seconds, the time of frames that carry no ``t``."""

    def __init__(
        self,
        solver: Solver,
        *,
        budget_s: float,
        prior_sigma_deg: float = 1.0,
        max_gap_s: float = DEFAULT_MAX_GAP_S,
        clock=time.monotonic,
    ) -> None:
        if not (_is_number(max_gap_s) and max_gap_s >= 0):
            raise StarnavError(
                f"max_gap_s must be a number of seconds >= 0, got {shown(max_gap_s)}"
            )
        self.solver = solver
        self.budget_s = budget_s
        self.prior_sigma_deg = prior_sigma_deg
        self.max_gap_s = float(max_gap_s)
        self.clock = clock
        self.frames = 0  # frames received
        self._last: _Solved | None = None

    @classmethod
    def prepare(
        cls,
        options: SolveOptions,
        *,
        width: float | None = None,
        height: float | None = None,
        max_gap_s: float = DEFAULT_MAX_GAP_S,
    ) -> Tracker:
        """The tracker of a known field (``options.fov_deg`` across ``width`` px, or
        ``options.camera``) with ``options``' catalog, identification, time budget and
        ``prior_sigma_deg``."""
        if not options.field_known:
            raise StarnavError(
                "a stream needs the camera: the field of view and width, or a camera file"
            )
        solver = prepare_solver(options, width=width, height=height)
        budget_s = check_budget(options.time_budget_s, known_budget_s(solver.camera))
        return cls(
            solver,
            budget_s=budget_s,
            prior_sigma_deg=options.prior_sigma_deg,
            max_gap_s=max_gap_s,
        )

    def warm_up(self) -> float:
        """Solve simulated frames (noisy, with false stars, with and without brightness) lost
        in space and tracked, so that the stream's first frames do not load machine code or
        modules a solve imports on first use; the seconds it took. The stream's state is
        untouched."""
        from starnav.simulate import simulate_frame

        t0 = time.perf_counter()
        cam = self.solver.camera
        deep = self.solver.settings.deep_catalog  # its stars in view: the deep stage's paths
        sky = self.solver.catalog if deep is None else deep.brighter_than(WARM_UP_DEEP_MAG)
        for ra_deg, dec_deg in WARM_UP_RADEC_DEG:
            frame = simulate_frame(sky, cam, ra_deg=ra_deg, dec_deg=dec_deg, roll_deg=30.0,
                                   noise_px=0.2, false_stars=2, seed=0)  # fmt: skip
            if len(frame.xy) < 3:
                continue
            for brightness in (frame.brightness, None):  # both paths of the verification
                stars = check_star_list(
                    frame.xy, width=cam.width, height=cam.height, brightness=brightness
                )
                for prior in (None, frame.R_cam_from_icrs):
                    self._solve(stars, prior)
        quaternion_xyzw(np.eye(3))  # imports scipy's rotations
        if deep is not None:  # what the deep stage imports on its first contested pair
            import scipy.optimize
            import scipy.sparse.csgraph  # noqa: F401
        return time.perf_counter() - t0

    def reset(self) -> None:
        """Start a new stream: the next frame is number 0, solved lost in space."""
        self.frames = 0
        self._last = None

    def answer(self, line: bytes | str) -> TrackAnswer:
        """The answer to one line of the stream (a frame, ``parse_frame``); a frame that cannot
        be read is answered with its ``error``, and the stream goes on."""
        t0 = time.perf_counter()
        received_s = self.clock()
        index = self.frames
        self.frames += 1
        cam = self.solver.camera
        try:
            frame = parse_frame(line, width=cam.width, height=cam.height)
        except StarnavError as exc:
            message = str(exc)
            return TrackAnswer(index, None, elapsed_ms(t0), reason=message, error=message)
        frame_clock = frame.t_s is not None
        t_s = frame.t_s if frame_clock else received_s
        last = self._last if self._recent(t_s, frame_clock) else None
        try:
            result = self._solve(frame.stars, None if last is None else last.R_cam_from_icrs)
        except Exception as exc:  # a fault of starnav's own: logged, and the stream goes on
            _log.exception("frame %d", index)
            self._last = None
            message = f"internal error ({type(exc).__name__}: {exc}): please report it"
            return TrackAnswer(index, None, elapsed_ms(t0), reason=message, error=message,
                               id=frame.id, t_s=frame.t_s)  # fmt: skip
        s = result.solution
        if s is not None:
            self._last = _Solved(s.R_cam_from_icrs, index, t_s, frame_clock)
        return TrackAnswer(
            index,
            s,
            elapsed_ms(t0),
            mode=None if s is None else TRACKED if s.algorithm == "tracking" else LOST_IN_SPACE,
            prior_frame=None if last is None else last.frame,
            reason=None if s is not None else result.reason,
            id=frame.id,
            t_s=frame.t_s,
        )

    def _solve(self, stars: StarList, prior: np.ndarray | None) -> SolveResult:
        """``stars`` solved within the budget, tracking from ``prior`` when given (a deadline
        or none takes other machine code: the warm-up solves as the stream does)."""
        return self.solver.solve(
            stars,
            prior=prior,
            prior_sigma_deg=self.prior_sigma_deg,
            deadline=Deadline.after(self.budget_s),
        )

    def _recent(self, t_s: float, frame_clock: bool) -> bool:
        """Whether the last solved frame is recent enough at ``t_s`` to track from: on the
        same clock, not later, at most ``max_gap_s`` before."""
        last = self._last
        if last is None or last.frame_clock != frame_clock:
            return False
        return 0.0 <= t_s - last.t_s <= self.max_gap_s
