"""astrometry.net's nova API in starnav's terms: a request's hints, and the JSON answers.

The shapes are those of astrometry.net's ``net/api.py`` (``upload_common``,
``submission_status``, ``job_status``, ``calibration``, ``job_info``,
``annotations_in_field``); the hints are its submission fields (``scale_units``,
``scale_type`` "ul" (lower/upper) or "ev" (estimate ± error %), ``scale_lower``,
``scale_upper``, ``scale_est``, ``scale_err``, ``center_ra``, ``center_dec``, ``radius``,
``parity`` (0 pos, 1 neg, 2 both), ``downsample_factor``, ``positional_error`` (px),
``crpix_center``), read as ``pipeline.plate.PlateHints``; ``publicly_visible`` is
``service.privacy``'s. Fields nova takes and starnav has no use for (``tweak_order``: the fit
is ours; ``use_sextractor``, ``invert``, licence) are accepted and ignored.
"""

from __future__ import annotations

import math

from starnav.errors import StarnavError
from starnav.pipeline.plate import (
    PlateHints,
    fov_range_from_scale,
    parity_from_nova,
    scale_bounds,
)
from starnav.service.store import Job

DEFAULT_SCALE_UNITS = "degwidth"  # nova's model default
STATUS_BLURB = {"queued": "processing", "solving": "solving", "success": "success",
                "failure": "failure"}  # fmt: skip
USER_ID = 1  # nova reports a user; the service has one


def _number(request: dict, key: str, kind=float):
    value = request.get(key)
    if value is None or value == "":
        return None
    try:
        v = kind(value)
    except (TypeError, ValueError):
        raise StarnavError(f"{key} must be a number, got {value!r}") from None
    if kind is float and not math.isfinite(v):
        raise StarnavError(f"{key} must be finite, got {value!r}")
    return v


def _flag(request: dict, key: str) -> bool:
    value = request.get(key)
    if isinstance(value, str):
        return value.strip().lower() in ("1", "true", "yes", "y", "on")
    return bool(value)


def plate_hints(request: dict, width_px: float, height_px: float | None = None) -> PlateHints:
    """The hints of a nova request (``StarnavError`` naming a bad one) for an image
    ``width_px`` x ``height_px`` (the width for "arcsecperpix"; both for the narrowest field
    searched, ``pipeline.fov.fov_limits_deg``)."""
    units = request.get("scale_units") or DEFAULT_SCALE_UNITS
    stype = request.get("scale_type") or ("ev" if "scale_est" in request else "ul")
    fov_range = None
    if stype == "ev" and request.get("scale_est") is not None:
        lo, hi = scale_bounds(_number(request, "scale_est"), _number(request, "scale_err") or 20)
        fov_range = fov_range_from_scale(units, lo, hi, width_px, height_px)
    elif stype == "ul" and (request.get("scale_lower") is not None
                            or request.get("scale_upper") is not None):  # fmt: skip
        lo = _number(request, "scale_lower")
        hi = _number(request, "scale_upper")
        if lo is None or hi is None:
            raise StarnavError("scale_lower and scale_upper go together")
        fov_range = fov_range_from_scale(units, lo, hi, width_px, height_px)
    elif stype not in ("ul", "ev"):
        raise StarnavError(f"scale_type must be 'ul' or 'ev', got {stype!r}")
    ra, dec = _number(request, "center_ra"), _number(request, "center_dec")
    if (ra is None) != (dec is None):
        raise StarnavError("center_ra and center_dec go together")
    radius = _number(request, "radius")
    downsample = _number(request, "downsample_factor", int)
    if downsample is not None and downsample < 1:
        raise StarnavError(f"downsample_factor must be >= 1, got {downsample}")
    return PlateHints(
        fov_range_deg=fov_range,
        ra_deg=ra,
        dec_deg=dec,
        radius_deg=radius if radius is None or radius > 0 else None,
        parity=parity_from_nova(request.get("parity")),
        downsample=downsample,
        positional_error_px=_number(request, "positional_error"),
        crpix_center=_flag(request, "crpix_center"),
    )


def _when(t: float | None) -> str:
    """nova's timestamps: ``str(datetime)``, "None" when not reached."""
    if t is None:
        return "None"
    import datetime as dt

    return str(dt.datetime.fromtimestamp(t, dt.UTC).replace(tzinfo=None))


def submission_status(job: Job) -> dict:
    """``api/submissions/N``: the job is listed once it has started."""
    out = {
        "user": USER_ID,
        "processing_started": _when(job.started),
        "processing_finished": _when(job.finished),
        "user_images": [job.id],
        "images": [job.id],
        "jobs": [job.id] if job.status != "queued" else [],
        "job_calibrations": [[job.id, job.id]] if job.status == "success" else [],
    }
    if job.status == "failure" and job.reason and job.started is None:
        out["error_message"] = job.reason
    return out


def job_status(job: Job) -> dict:
    """``api/jobs/N``."""
    return {"status": STATUS_BLURB[job.status]}


def calibration(job: Job) -> dict:
    """``api/jobs/N/calibration``."""
    if job.calibration is None:
        return {"error": f"no calibration data available for job {job.id}"}
    return job.calibration


def star_names(job: Job) -> list[str]:
    """The names of the identified stars that have one (brightest first), for nova's
    ``objects_in_field`` and machine tags."""
    stars = (job.result or {}).get("stars") or []
    return [s["name"] for s in stars if s.get("name")]


def starnav_answer(job: Job) -> dict:
    """``api/jobs/N/starnav``: starnav's own record of the job, with its whole solution."""
    return {"id": job.id, "status": job.status, "reason": job.reason,
            "original_filename": job.original_filename, "submitted": job.submitted,
            "started": job.started, "finished": job.finished, "calibration": job.calibration,
            "result": job.result}  # fmt: skip


def job_info(job: Job) -> dict:
    """``api/jobs/N/info``."""
    names = star_names(job)
    out = {
        "objects_in_field": names,
        "machine_tags": names,
        "tags": names,
        "status": STATUS_BLURB[job.status],
        "original_filename": job.original_filename,
    }
    if job.calibration is not None:
        cal = job.calibration
        keys = ("ra", "dec", "radius", "pixscale", "orientation", "parity")
        out["calibration"] = {k: cal[k] for k in keys}
    return out


def annotations(job: Job) -> dict:
    """``api/jobs/N/annotations``: the identified catalog stars, at their FITS pixel (1-based)
    where the solution puts them, as nova's "hip" entries."""
    if job.calibration is None:
        return {"error": f"no calibration data available for job {job.id}"}
    out = []
    for s in (job.result or {}).get("stars") or []:
        if s.get("catalog_id") is None:
            continue
        names = [f"HIP {s['catalog_id']}"] + ([s["name"]] if s.get("name") else [])
        out.append({"type": "hip", "names": names, "pixelx": s["x"] + 0.5,
                    "pixely": s["y"] + 0.5, "radius": 0.0, "hpmag": s.get("mag")})  # fmt: skip
    return {"annotations": out}
