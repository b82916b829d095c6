"""From an identification to the reported solution or the refusal, with its reason.

The policy (fit, outliers, rematch, wide search, final false-match probability, refusals) is
the kernel ``pipeline.kernels.conclude``; this module gives its answer a form: the
``Solution`` of the matched stars, or the sentence that says why there is none.
"""

from __future__ import annotations

import time

import numpy as np

from starnav.attitude.refine import refinement
from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.geometry import radec_roll_from_attitude
from starnav.identify.base import Identification, MatchSettings
from starnav.identify.database import PairDatabase
from starnav.identify.verify import catalog_mags, kernel_point_mags
from starnav.results import Solution, StarTable
from starnav.starlist import StarList


def kernels():
    """The fit-policy kernels (imported on first use: numba takes ~0.2 s to load)."""
    from starnav.pipeline import kernels

    return kernels


BRIGHT_UNSEEN = (
    "the best attitude puts in the image as many catalog stars brighter than any it matched "
    "as it matched, none of them among the points: not sure it is right"
)
CONTESTED = (
    "two sets of matches explain the stars about as well (a point or a star has another "
    "partner in each): not sure which is right"
)


def conclude(
    found: Identification,
    stars: StarList,
    camera: CameraModel,
    database: PairDatabase,
    settings: MatchSettings,
    *,
    sigma_px: float,
    known_sigma_px: float | None = None,
    fit_focal: bool,
    min_matched_fraction: float,
    fit_distortion: bool = False,
    algorithm: str = "",
    t0: float | None = None,
) -> tuple[Solution | None, str]:
    """The fitted solution of an identification, or None and the reason it is refused.
    ``database``: what it was identified on (its catalog's rows); ``camera``: the model the
    identification used; ``settings``: its tolerances; ``sigma_px``: the centroid sigma the
    outlier and rematch rules use; ``known_sigma_px``: the one told (None: not known), the
    least the reported 1-sigmas are at (``attitude.kernels.at_least_sigma``); ``algorithm``:
    the identifier's name, and ``t0`` when the solve began (``time.perf_counter()``; None:
    ``time_ms`` 0), for the solution's own fields."""
    k = kernels()
    xy = np.ascontiguousarray(stars.xy, dtype=np.float64)
    rank = stars.rank
    done = k.conclude(
        np.ascontiguousarray(found.obs_index, dtype=np.int64),
        np.ascontiguousarray(found.cat_index, dtype=np.int64),
        np.ascontiguousarray(found.R_cam_from_icrs, dtype=np.float64),
        xy,
        database.sky,
        database.everything,
        camera.model_code,
        camera.params,
        float(camera.width),
        float(camera.height),
        bool(fit_focal),
        bool(fit_distortion),
        *settings.kernel_args(),
        float(found.log_sides),
        rank,
        kernel_point_mags(stars.magnitudes, len(xy)),
        catalog_mags(database, stars.brightness is not None),
        database.mags,
        int(found.bright_drop),
        float(sigma_px),
        0.0 if known_sigma_px is None else float(known_sigma_px),
        int(found.hypotheses),
        settings.max_false_match_probability,
        float(min_matched_fraction),
    )
    if done.refusal == k.WRONG_SCALE:
        return None, wrong_scale(done.scale_focal_px, camera)
    if done.refusal == k.UNCONVINCING:
        return None, unconvincing(done.false_match_probability)
    if done.refusal == k.CONTESTED:
        return None, CONTESTED
    if done.refusal == k.BRIGHT_UNSEEN:
        return None, BRIGHT_UNSEEN
    if done.refusal == k.MISFIT:
        return None, misfit(done.fit.rms_px, float(known_sigma_px))
    if done.refusal == k.TOO_FEW:
        return None, too_few(len(done.obs), done.expected, min_matched_fraction)
    fit = refinement(done.fit, camera)
    solution = solution_of(
        stars,
        done.obs,
        done.cat,
        database.catalog,
        fit,
        done.false_match_probability,
        algorithm=algorithm,
        t0=t0,
    )
    return solution, ""


def solution_of(
    stars: StarList,
    obs: np.ndarray,
    cat_rows: np.ndarray,
    cat: Catalog,
    fit,
    p_false: float,
    *,
    algorithm: str = "",
    t0: float | None = None,
) -> Solution:
    """The ``Solution`` of matched ``obs`` rows of ``stars`` and ``cat_rows`` of ``cat`` with
    the ``Refinement`` ``fit`` (its camera, attitude and residuals), found by ``algorithm``;
    ``time_ms`` from ``t0`` (``time.perf_counter()``) to now, 0 when None."""
    catalog_id = np.full(len(stars.xy), -1, dtype=np.int64)
    residual_px = np.full(len(stars.xy), np.nan)
    catalog_id[obs] = cat.ids[cat_rows]
    residual_px[obs] = np.hypot(fit.residuals_px[:, 0], fit.residuals_px[:, 1])
    table = StarTable(stars.labels, stars.xy, catalog_id, residual_px)
    R = fit.R_cam_from_icrs
    ra, dec, roll, par = radec_roll_from_attitude(R)
    camera = fit.camera
    return Solution(
        ra_deg=ra,
        dec_deg=dec,
        roll_deg=roll,
        parity=par,
        focal_px=camera.focal_px,
        fov_deg=camera.fov_deg,
        rms_px=fit.rms_px,
        sigma_boresight_arcsec=fit.sigma_boresight_arcsec,
        sigma_roll_arcsec=fit.sigma_roll_arcsec,
        sigma_focal_px=fit.sigma_focal_px,
        false_match_probability=float(p_false),
        time_ms=0.0 if t0 is None else elapsed_ms(t0),
        R_cam_from_icrs=R,
        star_table=table,
        n_matched=len(obs),
        algorithm=algorithm,
        catalog=cat.name,
        camera_model=camera.model,
        camera=camera,
        rotation_cov_rad2=fit.rotation_cov_rad2,
        **{name: getattr(camera, name) for name in camera.coefficients},
    )


def wrong_scale(focal: float, camera: CameraModel) -> str:
    """The refusal of a fit whose stars want another focal length than the one given."""
    return (
        f"the stars fit a focal length of {focal:.1f} px (FOV "
        f"{camera.with_focal(focal).fov_deg:.3f}°), not the {camera.focal_px:.1f} px "
        f"given: correct the field of view or fit the focal length"
    )


def unconvincing(p_false: float) -> str:
    """The refusal of a fit whose false-match probability is too high."""
    return f"false-match probability {p_false:.2g} after the fit"


def misfit(rms_px: float, sigma_px: float) -> str:
    """The refusal of a fit whose residuals are beyond what the centroid sigma allows."""
    return (
        f"the matched stars fit the camera worse than their centroid sigma allows (rms "
        f"{rms_px:.2f} px, sigma {sigma_px:.2f} px): are the field of view, the lens model "
        f"and the sigma right?"
    )


def too_few(n_matched: int, expected: int, min_matched_fraction: float) -> str:
    """The refusal of a fit that explains too few of the stars it predicts."""
    return (
        f"only {n_matched} of {expected} stars agree with the best attitude (need "
        f"{min_matched_fraction:.0%}): is the field of view right?"
    )


def elapsed_ms(t0: float) -> float:
    """Milliseconds since ``time.perf_counter()`` was ``t0``."""
    return (time.perf_counter() - t0) * 1e3
