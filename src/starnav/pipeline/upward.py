"""An all-sky camera looking up, at a known site and time: its attitude guessed from the zenith.

A fixed all-sky camera points its axis at the zenith within a few degrees, so with the site
and UTC known its attitude lacks only the roll about the axis (and the mirror: some cameras
see the sky through a mirror, or are read out flipped). Seen from the axis, a star ``z`` from
the zenith at azimuth ``A`` (from North through East) lies ``z`` from the axis, at the angle
``phi`` in the image plane (camera x right, y down) with ``phi + A`` (``phi - A`` mirrored)
the same for every star: the roll. ``zenith_guesses`` lets each of the brightest points vote,
with each of the brightest stars above the horizon whose zenith angle agrees with the point's
angle from the axis (within ``GATE_DEG``: the tilt, the principal point's and the focal
length's errors), for that sum (``ROLL_BIN_DEG`` bins); the focal length is stepped coarsely
(``FOCAL_STEP``: a star 60° out moves 2.4° for 4 %) and the principal point over a grid
(``CENTRE_STEPS``) about the start's: the true one gathers the sharpest peak. The votes of a
winning roll are pairs of a point and a star; the camera's attitude and focal length are
fitted to them by robust least squares (scipy), then, principal point included, to every
bright point paired with the nearest bright star that fit predicts (``_refined``). That guess,
good to a few tenths of a degree, is then tracked on the whole list and verified as any other
solve (``pipeline.fov``): a guess that is wrong is refused there, and the focal scan goes on
as without a site.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import numpy as np

from starnav.attitude.wahba import wahba
from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.catalog.sky import Site, enu_vectors

VOTE_POINTS = 40  # the brightest points vote,
VOTE_STARS = 80  # each with the brightest stars (and planets) above
VOTE_MIN_ALTITUDE_DEG = 10.0  # this altitude (lower ones: extinction, trees, the horizon)
GATE_DEG = 6.0  # a point and a star vote when their angles from the axis and zenith agree so
ROLL_BIN_DEG = 2.0  # the roll's bins, counted three at a time (a 6° window)
FOCAL_STEP = 0.04  # log step of the focal lengths tried
MIN_VOTES = 8  # a roll is tried with at least this many votes in its window,
GUESSES = 3  # the most voted rolls tried (each verified by tracking: chance peaks are common)
FIT_RESIDUAL_PX = 3.0  # the fit's soft-L1 scale; pairs beyond 4x it after the fit are dropped
MIN_PAIRS = 6  # a guess needs this many pairs fitted
PAIR_DEG = 4.0  # then each point is paired with the nearest star it predicts within this
PAIR_POINTS = 60  # (the brightest this many points and
PAIR_STARS = 200  # stars above VOTE_MIN_ALTITUDE_DEG: sparse enough for chance pairs to be rare)
# the principal point is voted for too, at these offsets (times the focal length, px) from
# the start's: an image circle's centre lies up to ~6° from the optical axis
CENTRE_STEPS = (-0.1, -0.05, 0.0, 0.05, 0.1)


def enu_from_icrs(catalog: Catalog, site: Site, utc) -> np.ndarray:
    """``R_enu_from_icrs`` (3, 3) at ``site`` and ``utc``: the rotation that best takes the
    catalog's first 50 stars' ICRS directions to their (East, North, Up) directions (astropy;
    aberration and nutation make the true map a rotation to about 20″)."""
    n = min(50, len(catalog))
    few = Catalog(catalog.ids[:n], catalog.ra_deg[:n], catalog.dec_deg[:n], catalog.mag[:n], "")
    return wahba(enu_vectors(few, site, utc), few.vectors)


def zenith_guesses(
    xy: np.ndarray,
    order: np.ndarray,
    base: CameraModel,
    focal_range_px: tuple[float, float],
    sky: Catalog,
    R_enu_from_icrs: np.ndarray,
) -> Iterator[tuple[CameraModel, np.ndarray]]:
    """Cameras (``base``'s model, fitted focal length and principal point) and
    ``R_cam_from_icrs`` of an upward camera whose points ``xy`` (n, 2, px; ``order``:
    brightest first) show ``sky`` (the stars above the horizon: ``catalog.sky.sky_at``), the
    most voted first: at most ``GUESSES`` rolls (and mirrors) with ``MIN_VOTES`` or more over
    the focal lengths of ``focal_range_px``, each fitted to its votes."""
    enu = sky.vectors @ R_enu_from_icrs.T
    high = np.flatnonzero(enu[:, 2] >= math.sin(math.radians(VOTE_MIN_ALTITUDE_DEG)))
    high = high[np.argsort(sky.mag[high], kind="stable")]  # brightest first
    rows = high[:VOTE_STARS]
    zenith = np.arccos(np.clip(enu[rows, 2], -1.0, 1.0))
    azimuth = np.arctan2(enu[rows, 0], enu[rows, 1])
    order = np.asarray(order)
    points = order[:VOTE_POINTS]
    peaks = []
    for focal, dx, dy in itertools.product(_focals(focal_range_px), *2 * [CENTRE_STEPS]):
        camera = base.with_focal(focal)
        camera = camera.with_centre(base.cx + dx * focal, base.cy + dy * focal)
        b = camera.pixels_to_bearings(xy[points])
        theta = np.arccos(np.clip(b[:, 2], -1.0, 1.0))
        phi = np.arctan2(b[:, 1], b[:, 0])
        i, j = np.nonzero(np.abs(theta[:, None] - zenith[None, :]) < math.radians(GATE_DEG))
        for parity in (1, -1):
            sums = np.mod(phi[i] + parity * azimuth[j], 2.0 * math.pi)
            votes, roll = _peak(sums)
            if votes >= MIN_VOTES:
                peaks.append((votes, camera, parity, roll, i, j, sums))
    taken: list[tuple[int, float]] = []
    for _, camera, parity, roll, i, j, sums in sorted(peaks, key=lambda p: -p[0]):
        if any(p == parity and _apart(r, roll) <= 3.0 * ROLL_BIN_DEG for p, r in taken):
            continue  # the same roll at another focal length
        taken.append((parity, roll))
        near = _apart(sums, roll) <= 1.5 * ROLL_BIN_DEG
        R0 = _attitude(roll, parity) @ R_enu_from_icrs
        guess = _fitted(camera, R0, xy[points[i[near]]], sky.vectors[rows[j[near]]])
        if guess is not None:
            yield _refined(guess, xy[order[:PAIR_POINTS]], sky.vectors[high[:PAIR_STARS]])
        if len(taken) == GUESSES:
            return


def _apart(a, b: float):
    """The angle (degrees) between angles ``a`` and ``b`` (rad), 0-180."""
    return np.degrees(np.abs(np.angle(np.exp(1j * (np.asarray(a) - b)))))


def _focals(focal_range_px: tuple[float, float]) -> list[float]:
    """Focal lengths (px) ``FOCAL_STEP`` apart in log over the range, its middle first."""
    lo, hi = sorted(focal_range_px)
    mid = math.sqrt(lo * hi)
    n = math.ceil(math.log(hi / lo) / FOCAL_STEP / 2.0)
    return [mid * math.exp(FOCAL_STEP * k) for k in sorted(range(-n, n + 1), key=abs)]


def _peak(sums: np.ndarray) -> tuple[int, float]:
    """The most votes in a window of three ``ROLL_BIN_DEG`` bins (circular) and the window's
    centre (rad)."""
    n_bins = round(360.0 / ROLL_BIN_DEG)
    if len(sums) == 0:
        return 0, 0.0
    counts = np.bincount((sums / (2.0 * math.pi) * n_bins).astype(int) % n_bins, minlength=n_bins)
    window = counts + np.roll(counts, 1) + np.roll(counts, -1)
    k = int(np.argmax(window))
    return int(window[k]), (k + 0.5) * 2.0 * math.pi / n_bins


def _attitude(roll: float, parity: int) -> np.ndarray:
    """``R_cam_from_enu`` of a camera looking straight up whose image-plane angle ``phi`` of
    a star at azimuth ``A`` has ``phi + parity A = roll`` (rad): camera z up, x at azimuth
    ``parity roll``, y = parity z × x (then ``phi = parity (az_x - A)``)."""
    az_x = parity * roll
    z = np.array([0.0, 0.0, 1.0])
    x = np.array([math.sin(az_x), math.cos(az_x), 0.0])
    return np.vstack([x, parity * np.cross(z, x), z])


def _fitted(
    camera: CameraModel,
    R0: np.ndarray,
    xy: np.ndarray,
    stars_icrs: np.ndarray,
    *,
    centre: bool = False,
):
    """``camera`` and ``R0`` with the attitude and focal length (and with ``centre`` the
    principal point) fitted by least squares (soft-L1, so that the chance pairs weigh little)
    to the pairs of points ``xy`` and stars; None when fewer than ``MIN_PAIRS`` pairs lie
    within 4 ``FIT_RESIDUAL_PX`` of the fit."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    if len(xy) < MIN_PAIRS:
        return None
    n = 6 if centre else 4

    def model(p):
        lens = camera.with_focal(camera.focal_px * math.exp(p[3]))
        return lens.with_centre(camera.cx + p[4], camera.cy + p[5]) if centre else lens

    def attitude(p):
        return Rotation.from_rotvec(p[:3]).as_matrix() @ R0

    def residuals(p):
        return (model(p).bearings_to_pixels(stars_icrs @ attitude(p).T) - xy).ravel()

    bound = np.array([0.5, 0.5, 0.5, 0.3, np.inf, np.inf])[:n]
    fit = least_squares(
        residuals, np.zeros(n), bounds=(-bound, bound), loss="soft_l1", f_scale=FIT_RESIDUAL_PX
    )
    misses = np.hypot(*fit.fun.reshape(-1, 2).T)
    if not fit.success or np.sum(misses < 4.0 * FIT_RESIDUAL_PX) < MIN_PAIRS:
        return None
    return model(fit.x), attitude(fit.x)


def _refined(guess, xy: np.ndarray, stars_icrs: np.ndarray):
    """A guess (camera, ``R_cam_from_icrs``) fitted again, principal point included, to the
    points ``xy`` paired each with the nearest star of ``stars_icrs`` it predicts within
    ``PAIR_DEG``, then half and a quarter of it (the votes' pairs leave the principal point
    several degrees off, which the fit with every point can tell from a tilt); the last guess
    that fits."""
    from scipy.spatial import cKDTree

    for reach_deg in (PAIR_DEG, PAIR_DEG / 2.0, PAIR_DEG / 4.0):
        camera, R = guess
        ahead = stars_icrs @ R[2] > 0.0
        predicted = camera.bearings_to_pixels(stars_icrs[ahead] @ R.T)
        ok = np.all(np.isfinite(predicted), axis=1)
        tree = cKDTree(predicted[ok])
        reach_px = math.radians(reach_deg) * camera.scale_px_per_rad
        distance, nearest = tree.query(xy, distance_upper_bound=reach_px)
        paired = np.isfinite(distance)
        stars = stars_icrs[ahead][ok][nearest[paired]]
        better = _fitted(camera, R, xy[paired], stars, centre=True)
        if better is None:
            break
        guess = better
    return guess
