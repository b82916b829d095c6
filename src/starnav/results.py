"""Result types of a solve: ``Solution`` (a verified attitude), its ``StarMatch`` rows and
``SolveResult`` (the solution or the reason there is none), and the JSON of a solve that the
command line prints (``SOLVE_KEYS``, ``solve_dict``)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from starnav.camera import CameraModel
    from starnav.catalog import Catalog

# The JSON of a solve, solved or not (``solve_dict``): these keys in this order; an unsolved
# one has null for every number, 0 matched and its input points as the stars.
SOLVE_KEYS = (
    "solved",
    "reason",
    "ra_deg",
    "dec_deg",
    "roll_deg",
    "parity",
    "focal_px",
    "fov_deg",
    "camera_model",
    "rms_px",
    "sigma_boresight_arcsec",
    "sigma_roll_arcsec",
    "sigma_focal_px",
    "false_match_probability",
    "time_ms",
    "n_matched",
    "algorithm",
    "catalog",
    "R_cam_from_icrs",
    "stars",
)


@dataclass(frozen=True)
class StarMatch:
    """One input point: its ``label``, position (px), the ``catalog_id`` it was identified as
    (None: no catalog star) and the length of its residual after the fit (px, None if unmatched).
    With the deep stage (``pipeline.deep``): ``match_probability``, P(the id is right) (None
    if unmatched or without the deep stage), and ``double``, whether the point was taken
    for an unresolved double (given its brightest star).
    """

    label: str
    x: float
    y: float
    catalog_id: int | None
    residual_px: float | None
    match_probability: float | None = None
    double: bool = False


@dataclass(frozen=True, eq=False)
class StarTable:
    """The input points of a solution as arrays: ``labels``, ``xy`` (n, 2, px), the
    ``catalog_id`` of each (-1: none) and its residual length (px, NaN: unmatched); with the
    deep stage (``pipeline.deep``) also ``match_probability`` (NaN: unmatched) and
    ``double`` (bool), None without it."""

    labels: tuple[str, ...]
    xy: np.ndarray
    catalog_id: np.ndarray
    residual_px: np.ndarray
    match_probability: np.ndarray | None = None
    double: np.ndarray | None = None

    @property
    def deep(self) -> bool:
        """Whether the deep stage made this table (it has ``match_probability``)."""
        return self.match_probability is not None

    def records(self) -> tuple[StarMatch, ...]:
        """One ``StarMatch`` per point."""
        n = len(self.labels)
        ids = [None if i < 0 else i for i in self.catalog_id.tolist()]
        res = _none_for_nan(self.residual_px)
        prob = (
            [None] * n if self.match_probability is None else _none_for_nan(self.match_probability)
        )
        double = [False] * n if self.double is None else [bool(d) for d in self.double]
        return tuple(
            StarMatch(label, x, y, i, r, p, d)
            for label, (x, y), i, r, p, d in zip(
                self.labels, self.xy.tolist(), ids, res, prob, double, strict=True
            )
        )


def _none_for_nan(values: np.ndarray) -> list[float | None]:
    return [None if v != v else v for v in np.asarray(values, dtype=float).tolist()]


@dataclass(frozen=True, eq=False)
class Solution:
    """A verified attitude.

    Angles in degrees: boresight ``ra_deg``/``dec_deg`` (ICRS, catalog epoch), ``roll_deg``
    (position angle of image up from North through East), ``fov_deg`` (horizontal).
    ``parity``: +1 the sky as seen, -1 mirrored. ``R_cam_from_icrs``: rows are the camera axes
    in ICRS (determinant = parity). ``rms_px``: residual rms of matched stars;
    ``sigma_*_arcsec``: 1-sigma from the fit (``sigma_focal_px`` 0 unless the focal length
    was fitted); ``camera_model``: the lens model's name, ``k1``..``k4`` its coefficients
    (fitted or given, see ``starnav.camera``; 0 for those it lacks), ``camera`` the fitted
    camera itself; ``rotation_cov_rad2`` (3, 3): the fit's covariance of a small rotation
    about the camera axes (x right, y down, z boresight; radians squared), the matrix the
    1-sigmas come from (None when not known); ``time_ms``: identification and fit, without
    loading the catalog or database; ``star_table``: every input point with its id and
    residual, as arrays (``stars``: the same as ``StarMatch`` records, made on first use);
    ``pixel_aspect``: a pixel's height over its width (an image whose header says its pixels
    are not square, ``detect.header``): the ``star_table`` is in the image's pixels, the
    ``camera`` (and ``focal_px``, ``rms_px``) in square pixels of the pixel's width, whose y is
    the image's times ``pixel_aspect``.
    """

    ra_deg: float
    dec_deg: float
    roll_deg: float
    parity: int
    focal_px: float
    fov_deg: float
    rms_px: float
    sigma_boresight_arcsec: float
    sigma_roll_arcsec: float
    sigma_focal_px: float
    false_match_probability: float
    time_ms: float
    R_cam_from_icrs: np.ndarray
    star_table: StarTable
    n_matched: int
    algorithm: str
    catalog: str
    camera_model: str = "pinhole"
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    camera: CameraModel | None = None
    rotation_cov_rad2: np.ndarray | None = field(default=None, repr=False)
    pixel_aspect: float = 1.0

    def __repr__(self) -> str:
        n = len(self.star_table.labels)
        return (
            f"Solution(RA {self.ra_deg:.5f}° Dec {self.dec_deg:+.5f}° roll {self.roll_deg:.4f}° "
            f"parity {self.parity:+d}, FOV {self.fov_deg:.4f}°, {self.n_matched}/{n} stars "
            f"matched, rms {self.rms_px:.3f} px, 1σ boresight "
            f"{self.sigma_boresight_arcsec:.3g}″, false-match probability "
            f"{self.false_match_probability:.1e}, {self.algorithm})"
        )

    @functools.cached_property
    def stars(self) -> tuple[StarMatch, ...]:
        """Every input point: label, position, catalog id (None: none), residual (px)."""
        return self.star_table.records()

    def to_dict(self) -> dict:
        """JSON-ready dict of every field (the matrix as nested lists)."""
        skip = ("star_table", "R_cam_from_icrs", "camera", "rotation_cov_rad2")
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in skip}
        out["solved"] = True
        out["R_cam_from_icrs"] = self.R_cam_from_icrs.tolist()
        # the deep stage's columns only when it ran: other outputs keep their five keys
        drop = () if self.star_table.deep else ("match_probability", "double")
        out["stars"] = [{k: v for k, v in asdict(s).items() if k not in drop} for s in self.stars]
        return out


@dataclass(frozen=True, eq=False)
class SolveResult:
    """The outcome of one solve: the ``solution`` or None with the ``reason``; ``time_ms``
    in all, the ``hypotheses`` tried, the ``catalog`` identified against and ``stage_ms``
    per stage (``bearings``, ``identify``, ``fit``; the FOV search has ``search`` for its
    identification). Prints as a one-line summary."""

    solution: Solution | None
    reason: str
    time_ms: float
    hypotheses: int
    catalog: Catalog | None
    stage_ms: dict[str, float] = field(default_factory=dict)

    @property
    def solved(self) -> bool:
        """Whether there is a solution."""
        return self.solution is not None

    def __repr__(self) -> str:
        catalog = "no catalog" if self.catalog is None else f"catalog {self.catalog.name!r}"
        if self.solution is None:
            return (
                f"SolveResult(not solved: {self.reason}; {self.hypotheses} hypotheses, "
                f"{self.time_ms:.1f} ms, {catalog})"
            )
        return f"SolveResult({self.solution!r}, {self.time_ms:.1f} ms, {catalog})"

    def to_dict(self, labels: Sequence[str] | None = None, xy: np.ndarray | None = None) -> dict:
        """The JSON of this solve (``solve_dict``); ``labels`` and ``xy`` are the input points,
        listed as the stars when unsolved."""
        return solve_dict(self.solution, self.reason, self.time_ms, labels, xy)


@dataclass(frozen=True, eq=False)
class FrameResult:
    """One frame of a batch: the ``solution`` (None with the ``reason`` when unsolved),
    ``time_ms``, and ``error``, the one-line message when the frame's input was refused (then
    ``reason`` is the same message): a bad frame is reported, it does not stop the batch."""

    solution: Solution | None
    reason: str
    time_ms: float
    error: str | None = None

    @property
    def bad_input(self) -> bool:
        """Whether the frame's input was refused (not merely unsolved)."""
        return self.error is not None


def solve_dict(
    solution: Solution | None,
    reason: str = "",
    time_ms: float = float("nan"),
    labels: Sequence[str] | None = None,
    xy: np.ndarray | None = None,
) -> dict:
    """The JSON of a solve, keys ``SOLVE_KEYS``: from the ``solution`` (its own time; reason
    null) or, without one, ``solved`` false with the ``reason``, ``time_ms`` and every input
    point (``xy`` (n, 2) px, ``labels`` default "1".."n") unidentified."""
    if solution is not None:
        full = solution.to_dict()
        out = {key: full.get(key) for key in SOLVE_KEYS}
        out["reason"] = None
        return out
    out = dict.fromkeys(SOLVE_KEYS)
    points = np.empty((0, 2)) if xy is None else np.asarray(xy, dtype=float)
    names = [str(n + 1) for n in range(len(points))] if labels is None else list(labels)
    out.update(solved=False, reason=reason, time_ms=time_ms, n_matched=0)
    out["stars"] = [
        {"label": lab, "x": float(x), "y": float(y), "catalog_id": None, "residual_px": None}
        for lab, (x, y) in zip(names, points, strict=True)
    ]
    return out
