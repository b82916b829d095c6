"""Why an image was not solved, in words a photographer acts on.

``diagnose`` names one class of ``FAILURES`` from what detection measured and why the solve
ended, first that applies:

* ``FEW_STARS``: fewer than ``FEW_STARS_LIMIT`` stars detected (overcast, twilight, too short
  an exposure, a threshold too high), or the best attitude found is matched by too few of
  them to be sure of it (``_NOT_CONVINCING``);
* ``TRAILED``: the stars are ``TRAILED_ELONGATION`` times longer than wide or more (a long
  exposure on a fixed tripod, a shaking camera): their centres are the trails' middles;
* ``DISTORTED``: an attitude fitted part of the stars and not the rest (a lens beyond the
  model: a fisheye or a wide-angle lens for the pinhole, or its distortion not fitted);
* ``BUDGET``: the time budget ended the search (of the first range searched: the extended
  ranges share what the default range left);
* ``OUTSIDE``: no pattern of the stars matched the catalog anywhere in the range searched: the
  field lies outside it, or the brightest points are not stars (noise, a nebula's knots,
  satellites), or a field too narrow for the catalog.

The advice says what to change (exposure, mount, ``--lens``, ``--fov-range``, the budget).
"""

from __future__ import annotations

from dataclasses import dataclass

from starnav.camera import Camera
from starnav.detect.stars import Detections
from starnav.runtime.budget import SPENT

FEW_STARS = "too few stars"
TRAILED = "stars trailed"
DISTORTED = "lens too distorted for the model"
BUDGET = SPENT
OUTSIDE = "field outside the range"
FAILURES = (FEW_STARS, TRAILED, DISTORTED, BUDGET, OUTSIDE)

FEW_STARS_LIMIT = 8  # fewer detected stars than this rarely identify a field and verify it
TRAILED_ELONGATION = 2.0  # median long / short axis of the stars
# the solve's own words for an attitude that fits some of the stars only
_PART_FITS = "stars agree with the best attitude"
_BUDGET = SPENT
_NOT_CONVINCING = "best hypothesis not convincing"


@dataclass(frozen=True)
class Failure:
    """Why an image was not solved: its ``kind`` (one of ``FAILURES``) and what to change."""

    kind: str
    advice: str

    def explain(self, reason: str) -> str:
        """The reason a user reads: the class, the solve's own reason, the advice."""
        return f"{self.kind}: {reason}; {self.advice}"


def diagnose(
    detections: Detections,
    reason: str,
    *,
    fov_range_deg: tuple[float, float] | None,
    threshold_sigma: float,
    lens: str,
    fit_distortion: bool = False,
) -> Failure:
    """The class of an unsolved image's failure (see the module docstring) from its
    ``detections`` and the solve's ``reason``; ``fov_range_deg``: the horizontal fields
    searched (degrees; None when the field was given), ``threshold_sigma``, ``lens`` and
    ``fit_distortion`` as solved."""
    n = len(detections)
    if n < FEW_STARS_LIMIT:
        used = detections.threshold_sigma or threshold_sigma
        lower = max(1.5, round(0.8 * used * 2.0) / 2.0)
        where = ""
        if detections.sky_fraction < 1.0:
            where = f" inside the sky ({100.0 * detections.sky_fraction:.0f} % of the frame)"
        return Failure(
            FEW_STARS,
            f"only {n} star{'s' if n != 1 else ''} above {used:g} sigma{where}, "
            f"{FEW_STARS_LIMIT} or more are "
            "needed: cloud, daylight, dew or too short an exposure; try a longer exposure, "
            f"a clearer sky or --threshold-sigma {lower:g}",
        )
    if _NOT_CONVINCING in reason.split("; ")[0] and detections.elongation < TRAILED_ELONGATION:
        return Failure(
            FEW_STARS,
            "the best attitude found is matched by too few stars to be sure of it: a longer "
            "exposure or a darker sky shows more of them",
        )
    if detections.elongation >= TRAILED_ELONGATION:
        return Failure(
            TRAILED,
            f"the stars are {detections.elongation:.1f} times longer than wide: a shorter "
            "exposure, a steadier camera or a tracking mount",
        )
    if _PART_FITS in reason:
        models = "a fisheye model (--lens)" if lens == "pinhole" else "another --lens model"
        tries = models if fit_distortion else f"--fit-distortion, {models}"
        return Failure(
            DISTORTED,
            "the best attitude holds part of the frame and not the rest: if the lens "
            f"distorts, try {tries}, or calibrate the camera (starnav calibrate)",
        )
    if _BUDGET in reason.split("; ")[0]:  # the default range's search ran out of time
        return Failure(BUDGET, "a longer --time-budget, or the field of view if it is known")
    where = (
        f"in {fov_range_deg[0]:g}-{fov_range_deg[1]:g}°" if fov_range_deg else "at the field given"
    )
    lo, hi = Camera.fov_limits_deg
    return Failure(
        OUTSIDE,
        f"no pattern of the brightest stars matches the catalog {where}: the field lies "
        f"outside that (give it: --fov-deg, or --fov-range within {lo:g}-{hi:g}° for the "
        f"pinhole lens; narrower than {lo:g}° along the image's longer side is beyond the "
        "embedded catalogs), or the brightest "
        "points are not the brightest stars (a processed or stacked picture, a nebula, noise)",
    )
