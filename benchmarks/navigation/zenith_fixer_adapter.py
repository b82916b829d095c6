"""Run zenith-fixer (PyPI ``zenith-fixer``, import ``zenith``) on starnav locate observations.

For comparing ``starnav locate`` with an outside celestial-fix package. It runs inside its own
virtual environment and must not import starnav:

    python -m venv /work/venvs/zenith-fixer
    /work/venvs/zenith-fixer/bin/pip install zenith-fixer
    /work/venvs/zenith-fixer/bin/python benchmarks/navigation/zenith_fixer_adapter.py < obs.json

Input on stdin: one observation object, a JSON list of them, or JSON lines (one per line)::

    {"utc": "2026-03-15T02:00:00Z",
     "gravity_body": [gx, gy, gz],   # unit, pointing down; body x forward, y right, z down
     "pressure_hpa": 0,              # 0: no refraction in the data
     "cameras": [{"fov_deg": 40, "width": 1024, "height": 1024,
                  "azimuth_deg": 0, "elevation_deg": 60,   # or "R_cam_from_body": 3x3
                  "stars": [[x, y], ...]}]}                # px, origin top-left, x right, y down

Optional per camera: ``mag`` or ``brightness`` (one per star) to order the stars brightest
first; without them the list order is taken as brightest first (starnav's simulated frames are
sorted that way). Optional ``focal_px``, ``cx``, ``cy`` override the pinhole derived from
``fov_deg`` (focal ``0.5 * width / tan(fov / 2)``, principal point ``(width / 2, height / 2)``,
starnav's convention: the top-left pixel's centre is (0.5, 0.5)). Other keys (a ``truth``
block, for example) are ignored.

Output: one JSON line per observation with ``lat_deg``, ``lon_deg``, ``azimuth_deg`` (always
null: zenith-fixer reports no heading or attitude), ``time_ms`` (this fix only: building the
inputs and the zenith call, timed here, so interpreter start-up, imports and the one-off catalog
load are excluded), ``error`` (string or null), ``mode``, ``camera_index`` (camera used,
``best`` mode) and ``n_matched``; a fix adds zenith-fixer's ``ellipse_2sigma_m`` ([semi-major,
semi-minor, orientation_deg]), ``residual_rms_arcsec`` and ``match_margin``.

How the conventions are mapped (zenith-fixer 0.22.0; found from its docstrings and by test):

* zenith-fixer solves from one camera (``resolve_from_centroids``: (x, y, flux) centroids,
  pinhole ``focal_px, cx, cy``, optional fisheye k1..k4). Its camera frame is starnav's (x right,
  y down, z boresight) and its pinhole maps direction (0, 0, 1) to the ``(cx, cy)`` passed, so
  starnav pixels go in unchanged. It keeps the ``max_centroids`` brightest (default 12).
* It takes the up direction (unit vector toward the local zenith) in the camera frame:
  ``up_cam = -R_cam_from_body @ gravity_body``.
* UTC goes in as a (year, month, day, hour, minute, second) tuple; there is no UT1-UTC input.
* It has no pressure or temperature input and always removes Bennett's refraction for standard
  air (1010 hPa, 10 C) from every star's altitude. ``--refraction match`` (default) therefore
  moves each star along its vertical circle (altitude from the gravity vector) so that this
  removal gives back the data's own true altitude, with the data's refraction taken as Bennett
  scaled by ``pressure_hpa / 1010`` (none for 0). ``--refraction none`` passes the pixels through
  untouched: on refraction-free data (``pressure_hpa`` 0) the fix is then biased by 20 to 80
  arcsec, depending on the stars' altitudes.
* Its fix is in the mean equator and equinox of date with GMST: nutation is ignored, so even
  perfect data gives errors of several arcsec (a few hundred metres) against a full
  IAU 2006/2000A reduction. That is zenith-fixer's own error; the adapter does not correct it.
* It returns no heading or attitude: ``azimuth_deg`` is always null.
* ``--mode best`` (default): zenith-fixer as designed, one camera. Cameras are tried in order of
  star count (most first) and the first fix returned is kept.
* ``--mode merge``: every camera's stars are turned into body-frame directions and re-projected
  into one virtual equidistant fisheye looking straight up (zenith-fixer's own calibrated-fisheye
  model, focal length equal to the longest camera focal length, field 200 degrees), so the solver
  sees all cameras at once. This is an adapter construction, not a zenith-fixer feature.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from datetime import UTC, datetime

import numpy as np
import zenith

NM_TO_M = 1852.0
RAD_TO_ARCSEC = 180.0 / math.pi * 3600.0
STANDARD_HPA = 1010.0  # Bennett's standard air (10 C), assumed by zenith-fixer
MERGE_FOV_DEG = 200.0  # virtual fisheye field: stars down to 10 degrees below the horizon


def read_observations(text: str) -> list[dict]:
    """One object, a list of objects, or JSON lines."""
    text = text.strip()
    if not text:
        return []
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        return [json.loads(line) for line in text.splitlines() if line.strip()]
    return data if isinstance(data, list) else [data]


def parse_utc(s: str) -> tuple[int, int, int, int, int, float]:
    """ISO-8601 UTC string -> (year, month, day, hour, minute, second) with float seconds."""
    t = datetime.fromisoformat(s.strip().replace("Z", "+00:00").replace("z", "+00:00"))
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    t = t.astimezone(UTC)
    return (t.year, t.month, t.day, t.hour, t.minute, t.second + t.microsecond * 1e-6)


def r_cam_from_body(cam: dict) -> np.ndarray:
    """Rows = camera x (right), y (down), z (boresight) axes in body axes (FRD)."""
    if "R_cam_from_body" in cam:
        r = np.asarray(cam["R_cam_from_body"], dtype=float)
        if r.shape != (3, 3):
            raise ValueError("R_cam_from_body must be 3x3")
        return r
    az = math.radians(float(cam["azimuth_deg"]))
    el = math.radians(float(cam["elevation_deg"]))
    z = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])
    x = np.array([-math.sin(az), math.cos(az), 0.0])
    return np.vstack([x, np.cross(z, x), z])


def intrinsics(cam: dict) -> tuple[float, float, float]:
    """(focal_px, cx, cy) of the pinhole: starnav's from_fov convention unless given."""
    w, h = float(cam["width"]), float(cam["height"])
    f = cam.get("focal_px")
    if f is None:
        f = 0.5 * w / math.tan(0.5 * math.radians(float(cam["fov_deg"])))
    return float(f), float(cam.get("cx", w / 2.0)), float(cam.get("cy", h / 2.0))


def flux(cam: dict, n: int) -> np.ndarray:
    """Brightness per star; zenith uses it only to keep the brightest ``max_centroids`` first."""
    if "brightness" in cam:
        return np.asarray(cam["brightness"], dtype=float)
    if "mag" in cam:
        return 10.0 ** (-0.4 * np.asarray(cam["mag"], dtype=float))
    return 1.0 / np.arange(1, n + 1)  # list order = brightest first; merge interleaves cameras


def bennett_arcmin(h_deg: np.ndarray) -> np.ndarray:
    """Bennett (1982) refraction, arcmin, for apparent altitude ``h_deg`` (standard air)."""
    h = np.maximum(h_deg, -1.0)
    return 1.0 / np.tan(np.radians(h + 7.31 / (h + 4.4)))


def match_refraction(v: np.ndarray, up: np.ndarray, pressure_hpa: float) -> np.ndarray:
    """Move body-frame star directions ``v`` (n, 3) along their vertical circles so that
    zenith-fixer's built-in standard-air refraction removal gives back the data's true altitudes.

    The data's refraction is taken as Bennett scaled by ``pressure_hpa / 1010`` (0: none);
    zenith-fixer always removes Bennett at 1010 hPa (see the module docstring)."""
    s = np.clip(v @ up, -1.0, 1.0)
    h_obs = np.degrees(np.arcsin(s))
    h_true = h_obs - pressure_hpa / STANDARD_HPA * bennett_arcmin(h_obs) / 60.0
    h_app = h_true.copy()
    for _ in range(6):  # solve h_app - R(h_app) = h_true
        h_app = h_true + bennett_arcmin(h_app) / 60.0
    horiz = v - s[:, None] * up
    horiz /= np.linalg.norm(horiz, axis=1, keepdims=True)
    ha = np.radians(h_app)[:, None]
    return np.cos(ha) * horiz + np.sin(ha) * up


def body_vectors(cam: dict) -> np.ndarray:
    """Unit star directions (n, 3) in the body frame."""
    xy = np.asarray(cam.get("stars", []), dtype=float).reshape(-1, 2)
    f, cx, cy = intrinsics(cam)
    v = np.column_stack([(xy[:, 0] - cx) / f, (xy[:, 1] - cy) / f, np.ones(len(xy))])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v @ r_cam_from_body(cam)  # rows: R.T @ v_cam


def star_sets(obs: dict, up: np.ndarray, refraction: str) -> list[tuple[dict, np.ndarray]]:
    """Per camera: (camera, body-frame unit vectors after the refraction step)."""
    pressure = float(obs.get("pressure_hpa") or 0.0)
    out = []
    for cam in obs["cameras"]:
        v = body_vectors(cam)
        if refraction == "match" and len(v):
            v = match_refraction(v, up, pressure)
        out.append((cam, v))
    return out


def solve_best(obs, utc, up, catalog, opts, refraction):
    """zenith-fixer as designed: one camera; the one with most stars that gives a fix."""
    sets = star_sets(obs, up, refraction)
    order = sorted(range(len(sets)), key=lambda i: -len(sets[i][1]))
    errors = []
    for i in order:
        cam, v = sets[i]
        f, cx, cy = intrinsics(cam)
        r = r_cam_from_body(cam)
        c = v @ r.T
        cents = np.column_stack([cx + f * c[:, 0] / c[:, 2], cy + f * c[:, 1] / c[:, 2]])
        if refraction == "none":
            cents = np.asarray(cam.get("stars", []), dtype=float).reshape(-1, 2)
        triples = [(x, y, b) for (x, y), b in zip(cents.tolist(), flux(cam, len(v)), strict=True)]
        up_cam = tuple(float(a) for a in r @ up)
        try:
            fix = zenith.resolve_from_centroids(triples, f, cx, cy, up_cam, utc, catalog, **opts)
        except Exception as exc:  # zenith.ZenithError and bad-input ValueErrors alike
            errors.append(f"camera {i}: {exc}")
            continue
        return fix, i
    raise RuntimeError("; ".join(errors) or "no cameras")


def solve_merge(obs, utc, up, catalog, opts, refraction):
    """All cameras' stars re-projected into one virtual up-looking equidistant fisheye."""
    # virtual camera: z = up, x = body x made horizontal (or body y if x is vertical)
    x = np.array([1.0, 0.0, 0.0]) - up[0] * up
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - up[1] * up
    x /= np.linalg.norm(x)
    r_virt = np.vstack([x, np.cross(up, x), up])
    focal = max(intrinsics(c)[0] for c in obs["cameras"])
    c0 = focal * math.radians(MERGE_FOV_DEG) / 2.0 + 10.0
    # any non-zero k makes it the calibrated fisheye, whose focal_px is the true radial scale
    lens = {"fisheye_fov_deg": MERGE_FOV_DEG, "k1": 1e-12}
    virt = zenith.Camera(focal, c0, c0, **lens)
    pts = []
    for cam, v in star_sets(obs, up, refraction):
        if not len(v):
            continue
        p = np.atleast_2d(virt.vec_to_pixel(v @ r_virt.T))  # NaN rows: outside the field
        b = flux(cam, len(v))
        pts += [
            (px, py, fl) for (px, py), fl in zip(p.tolist(), b, strict=True) if math.isfinite(px)
        ]
    pts.sort(key=lambda t: -t[2])
    fix = zenith.resolve_from_centroids(
        pts, focal, c0, c0, (0.0, 0.0, 1.0), utc, catalog, **lens, **opts
    )
    return fix, None


def locate(obs: dict, catalog, mode: str, refraction: str, opts: dict) -> dict:
    out = {"lat_deg": None, "lon_deg": None, "azimuth_deg": None, "time_ms": None}
    out.update({"error": None, "mode": mode, "camera_index": None, "n_matched": None})
    t0 = time.perf_counter()
    try:
        utc = parse_utc(obs["utc"])
        g = np.asarray(obs["gravity_body"], dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) == 0:
            raise ValueError("gravity_body must be a non-zero 3-vector")
        up = -g / np.linalg.norm(g)
        solve = solve_merge if mode == "merge" else solve_best
        fix, cam = solve(obs, utc, up, catalog, opts, refraction)
        out["time_ms"] = (time.perf_counter() - t0) * 1e3
        a, b, ang = fix.ellipse_2sigma_nm
        out.update(
            lat_deg=fix.latitude_deg,
            lon_deg=((fix.longitude_deg + 180.0) % 360.0) - 180.0,
            camera_index=cam,
            n_matched=len(fix.matched_hr_ids),
            ellipse_2sigma_m=[a * NM_TO_M, b * NM_TO_M, ang],
            residual_rms_arcsec=fix.residual_rms_rad * RAD_TO_ARCSEC,
            match_margin=fix.match_margin,
        )
    except Exception as exc:
        out["time_ms"] = (time.perf_counter() - t0) * 1e3
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mode", choices=("best", "merge"), default="best")
    ap.add_argument(
        "--refraction",
        choices=("match", "none"),
        default="match",
        help="match: move stars so zenith's fixed refraction removal fits pressure_hpa; "
        "none: pass the pixels through untouched",
    )
    ap.add_argument("--sigma-arcmin", type=float, default=None, help="zenith sigma_arcmin")
    ap.add_argument("--max-centroids", type=int, default=None)
    ap.add_argument("--min-matched-stars", type=int, default=None)
    args = ap.parse_args()
    opts = {
        k: v
        for k, v in (
            ("sigma_arcmin", args.sigma_arcmin),
            ("max_centroids", args.max_centroids),
            ("min_matched_stars", args.min_matched_stars),
        )
        if v is not None
    }
    catalog = zenith.bundled_catalog()  # one-off load, outside the per-fix timing
    for obs in read_observations(sys.stdin.read()):
        print(json.dumps(locate(obs, catalog, args.mode, args.refraction, opts)), flush=True)


if __name__ == "__main__":
    main()
