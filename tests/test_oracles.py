"""Independent oracles for the solver's primitives, through their public functions only.

Each test compares a public function with a separate computation of the same thing: brute
force over the catalog, scipy's assignment, rotation-fit and least-squares
routines, or a formula written out here (the false-match probability's). The primitives are compiled
kernels; these tests pin what the results must be, whatever computes them. Nothing here
imports a private name or relies on the order of an unordered result.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares, linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, maximum_bipartite_matching
from scipy.spatial.transform import Rotation

import starnav
from starnav.api import get_database, solve_stars
from starnav.attitude import refine_attitude
from starnav.attitude.wahba import wahba
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.geometry import (
    angle_between,
    attitude_difference_deg,
    attitude_from_radec_roll,
    chord_from_angle,
    radec_to_unit,
)
from starnav.identify import ALGORITHMS
from starnav.identify.base import MatchSettings
from starnav.identify.kernels.evidence import Q_STAR
from starnav.identify.pyramid import catalog_triangles
from starnav.identify.verify import Verification, match_catalog
from starnav.simulate import FALSE_STAR_ID, simulate_frame

CAMERA = Camera.from_fov(12.0, 512)
MIRROR = np.diag([1.0, -1.0, 1.0])
ARCMIN = np.radians(1.0 / 60.0)
ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0


@pytest.fixture(scope="module")
def catalog():
    return load_catalog(None, mag_limit=6.0)


@pytest.fixture(scope="module")
def database(catalog):
    return get_database(catalog, CAMERA)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _moved(rng, v, angle_rad):
    """Unit vectors ``v`` (n, 3) each moved by ``angle_rad`` (n,) in a random direction."""
    t = rng.normal(size=v.shape)
    t = _unit(t - np.sum(t * v, axis=1, keepdims=True) * v)
    a = np.asarray(angle_rad, dtype=float)[:, None]
    return v * np.cos(a) + t * np.sin(a)


def _in_cap(rng, n, half_angle_rad):
    """``n`` camera-frame unit vectors uniform in the cap of ``half_angle_rad`` about +z."""
    cos_t = rng.uniform(np.cos(half_angle_rad), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    sin_t = np.sqrt(1.0 - cos_t**2)
    return np.column_stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])


def _angle_deg(R_a, R_b):
    """Angle (degrees) of the rotation between two attitudes of the same parity."""
    D = np.asarray(R_a) @ np.asarray(R_b).T
    return float(np.degrees(Rotation.from_matrix(D).magnitude()))


# ----------------------------------------------------------------------------- match_catalog


def _oracle_match(bearings, R, vectors, radius_rad, cov=None):
    """Brute force: every catalog star in the field cone, then the one-to-one pairing of
    within-radius pairs with the most pairs and, among those, the least total squared chord.

    Returns (cone rows, {(obs, cat row): chord}, allowed matrix, squared chords)."""
    field = np.arccos(np.clip(np.min(bearings[:, 2]), -1.0, 1.0)) + radius_rad
    cone = np.flatnonzero(angle_between(vectors, R[2]) <= field)
    cam = vectors[cone] @ R.T
    d2 = np.sum((bearings[:, None, :] - cam[None, :, :]) ** 2, axis=2)
    r2 = np.full(len(cone), chord_from_angle(radius_rad) ** 2)
    if cov is not None:
        r2 = r2 + 9.0 * np.maximum(np.trace(cov) - np.einsum("ni,ij,nj->n", cam, cov, cam), 0.0)
    allowed = d2 <= r2[None, :]
    if not allowed.any():
        return cone, {}, allowed, d2, field
    # every allowed pair is worth more than any sum of squared chords: most pairs first
    big = 1.0 + min(allowed.shape) * d2[allowed].max()
    r, c = linear_sum_assignment(np.where(allowed, d2 - big, 0.0))
    keep = allowed[r, c]
    pairs = {
        (int(o), int(cone[k])): float(np.sqrt(d2[o, k]))
        for o, k in zip(r[keep], c[keep], strict=True)
    }
    # the count, once more, by a maximum-cardinality matching that ignores distances
    n_max = int(np.sum(maximum_bipartite_matching(csr_matrix(allowed), perm_type="column") >= 0))
    assert len(pairs) == n_max
    return cone, pairs, allowed, d2, field


def _largest_group(allowed):
    """Most allowed pairs in one connected group of points and catalog stars."""
    n, m = allowed.shape
    rows, cols = np.nonzero(allowed)
    graph = csr_matrix((np.ones(len(rows)), (rows, n + cols)), shape=(n + m, n + m))
    _, label = connected_components(graph, directed=False)
    return int(np.bincount(label[rows]).max()) if len(rows) else 0


def _frame_bearings(rng, catalog, database, radius_rad, *, aim_double, crowd, spread=1.3):
    """A random attitude (either parity) and camera-frame points: catalog stars of a 7°
    cap (90 % seen, each moved by up to ``spread`` radii, so some fall outside), false points,
    second points near some stars, and ``crowd`` points near one star or, with
    ``aim_double``, between the two stars of a close catalog pair (within the radius of
    both)."""
    vectors = catalog.vectors
    if aim_double:
        a, b = database.pairs_within(0.75 * radius_rad, 0.75 * radius_rad)
        k = rng.integers(len(a))
        centre = _unit(vectors[a[k]] + vectors[b[k]])
        aim = _moved(rng, centre[None], [np.radians(rng.uniform(0.0, 4.0))])[0]
    else:
        aim = _unit(rng.normal(size=3))
    ra, dec = np.degrees(np.arctan2(aim[1], aim[0])), np.degrees(np.arcsin(aim[2]))
    R = attitude_from_radec_roll(ra, dec, rng.uniform(0, 360), int(rng.choice([1, -1])))
    cam = vectors @ R.T
    seen = np.flatnonzero((cam[:, 2] > np.cos(np.radians(7.0))) & (rng.random(len(cam)) < 0.9))
    points = [_moved(rng, cam[seen], rng.uniform(0.0, spread * radius_rad, len(seen)))]
    points.append(_in_cap(rng, 5, np.radians(7.0)))  # false stars
    twice = rng.choice(seen, min(4, len(seen)), replace=False)  # close doubles of points
    points.append(_moved(rng, cam[twice], rng.uniform(0.0, 0.9 * radius_rad, len(twice))))
    if aim_double:
        mid = _unit(cam[a[k]] + cam[b[k]])
        sep = angle_between(cam[a[k]], cam[b[k]])
        spread = rng.uniform(0.0, 0.95 * radius_rad - 0.5 * sep, crowd)
        points.append(_moved(rng, np.repeat(mid[None], crowd, axis=0), spread))
    else:
        star = cam[rng.choice(seen)]
        spread = rng.uniform(0.0, 0.95 * radius_rad, crowd)
        points.append(_moved(rng, np.repeat(star[None], crowd, axis=0), spread))
    bearings = np.vstack(points)
    return bearings[rng.permutation(len(bearings))], R


def _assert_same_match(ver, oracle):
    cone, pairs, _, _, field = oracle
    keys = zip(ver.obs_index.tolist(), ver.cat_index.tolist(), strict=True)
    got = dict(zip(keys, ver.distance_rad, strict=True))
    assert len(got) == len(ver.obs_index)  # no pair twice
    assert len(set(ver.obs_index.tolist())) == len(ver.obs_index)  # one to one
    assert len(set(ver.cat_index.tolist())) == len(ver.cat_index)
    assert set(got) == set(pairs)
    for key, chord in pairs.items():
        assert got[key] == pytest.approx(chord, rel=1e-9, abs=1e-15)
    assert ver.n_cone == len(cone)
    assert ver.field_area == pytest.approx(1.0 - np.cos(field), rel=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_match_catalog_is_the_optimal_one_to_one_pairing(catalog, database, seed):
    """Random frames and frames aimed at close catalog doubles with a crowd of points
    between them: the pairs are those of the brute-force optimal assignment, in groups of
    more than 12 candidate pairs too."""
    rng = np.random.default_rng(seed)
    radius = (3.0 if seed % 2 else 10.0) * ARCMIN
    aim_double = seed >= 2
    crowd = 7 if aim_double else 14
    bearings, R = _frame_bearings(
        rng, catalog, database, radius, aim_double=aim_double, crowd=crowd
    )
    oracle = _oracle_match(bearings, R, catalog.vectors, radius)
    assert _largest_group(oracle[2]) > 12  # the frame holds a contested group
    _assert_same_match(match_catalog(bearings, R, database, radius), oracle)


@pytest.mark.parametrize("seed", range(4))
def test_match_catalog_gate_grows_with_the_rotation_covariance(catalog, database, seed):
    """The radius of each catalog star c grows to radius^2 + 9 (tr C - c^T C c), with an
    anisotropic covariance over a 7° field: one point per star near the edge of its own
    gate (0.8 to 1.2 times its radius), false points and a crowd near one star."""
    rng = np.random.default_rng(100 + seed)
    radius = 3.0 * ARCMIN
    R = Rotation.random(random_state=rng).as_matrix() @ (MIRROR if seed % 2 else np.eye(3))
    # a poorly fixed roll (40' about the boresight, 0.5' across it), axes tilted a little:
    # the gate grows from the centre of the field to its edge
    Q = Rotation.from_rotvec(rng.normal(0.0, 0.05, 3)).as_matrix()
    cov = Q @ np.diag(np.array([0.5, 0.5, 40.0]) ** 2) @ Q.T * ARCMIN**2
    cam = catalog.vectors @ R.T
    cam = cam[cam[:, 2] > np.cos(np.radians(7.0))]
    var = np.trace(cov) - np.einsum("ni,ij,nj->n", cam, cov, cam)
    gate = 2.0 * np.arcsin(0.5 * np.sqrt(chord_from_angle(radius) ** 2 + 9.0 * var))
    crowd = np.repeat(cam[:1], 14, axis=0)
    bearings = np.vstack(
        [
            _moved(rng, cam, gate * rng.uniform(0.8, 1.2, len(cam))),
            _moved(rng, crowd, gate[0] * rng.uniform(0.0, 1.0, len(crowd))),
            _in_cap(rng, 5, np.radians(7.0)),
        ]
    )
    oracle = _oracle_match(bearings, R, catalog.vectors, radius, cov)
    # the comparison tells the gate from a narrower one (2.5 sigma) and from none
    assert oracle[1] != _oracle_match(bearings, R, catalog.vectors, radius, cov / 1.44)[1]
    assert oracle[2].sum() > _oracle_match(bearings, R, catalog.vectors, radius)[2].sum()
    ver = match_catalog(bearings, R, database, radius, rotation_cov_rad2=cov)
    _assert_same_match(ver, oracle)


def test_match_catalog_prefers_more_pairs_to_a_closer_one(catalog, database):
    """Close double a, b: point p1 between them nearer a, p2 beyond a (within the radius
    of a only). The nearest pair p1-a would leave two unpaired; the answer is p2-a, p1-b."""
    a, b = database.pairs_within(2.5 * ARCMIN, 1.5 * ARCMIN)
    a, b = int(a[0]), int(b[0])
    va, vb = catalog.vectors[a], catalog.vectors[b]
    sep = angle_between(va, vb)
    toward = _unit(vb - va - np.dot(vb - va, va) * va)  # tangent at a, towards b
    p1 = np.cos(0.45 * sep) * va + np.sin(0.45 * sep) * toward
    p2 = np.cos(0.7 * sep) * va - np.sin(0.7 * sep) * toward
    ra, dec = np.degrees(np.arctan2(va[1], va[0])), np.degrees(np.arcsin(va[2]))
    R = attitude_from_radec_roll(ra, dec, 30.0)
    bearings = np.vstack([p1, p2]) @ R.T
    ver = match_catalog(bearings, R, database, 0.8 * sep)
    assert set(zip(ver.obs_index.tolist(), ver.cat_index.tolist(), strict=True)) == {
        (0, b),
        (1, a),
    }
    _assert_same_match(ver, _oracle_match(bearings, R, catalog.vectors, 0.8 * sep))


def test_match_catalog_ignores_a_covariance_that_is_not_finite(catalog, database):
    rng = np.random.default_rng(7)
    radius = 3.0 * ARCMIN
    bearings, R = _frame_bearings(rng, catalog, database, radius, aim_double=False, crowd=3)
    oracle = _oracle_match(bearings, R, catalog.vectors, radius)
    cov = np.full((3, 3), np.inf)
    _assert_same_match(match_catalog(bearings, R, database, radius, rotation_cov_rad2=cov), oracle)


def test_match_catalog_on_an_empty_field(catalog, database):
    """A point in a starless spot with a small radius: nothing in the cone, nothing paired."""
    vectors = catalog.vectors
    rng = np.random.default_rng(3)
    for _ in range(1000):
        aim = _unit(rng.normal(size=3))
        if np.min(angle_between(vectors, aim)) > np.radians(1.0):
            break
    ra, dec = np.degrees(np.arctan2(aim[1], aim[0])), np.degrees(np.arcsin(aim[2]))
    R = attitude_from_radec_roll(ra, dec, 0.0)
    ver = match_catalog(np.array([[0.0, 0.0, 1.0]]), R, database, 3.0 * ARCMIN)
    assert ver.n_cone == 0 and len(ver.obs_index) == len(ver.cat_index) == 0
    assert ver.field_area == pytest.approx(1.0 - np.cos(3.0 * ARCMIN), rel=1e-9)


# ------------------------------------------------------------------- false_match_probability

PX = 1.0 / CAMERA.focal_px


def _oracle_p(dist, n_cone, area, n_stars, n_used, hyp, sigmas, radius):
    """len(sigmas) hypotheses / Lambda, Lambda the best over the centroid sigmas of the
    product of the per-point likelihood ratios (star fraction q), written out from
    docs/verification.md."""
    best = -np.inf
    rho = n_cone / area
    q = Q_STAR
    for sigma in sigmas:
        s = 2.0 * np.sin(0.5 * dist) ** 2  # 1 - cos, without its cancellation
        lam = rho * sigma**2
        logs = np.sort(np.log((1 - q) + q * np.exp(rho * s - s / sigma**2) / lam))
        dropped = min(n_used, len(dist))
        kept = logs[: len(dist) - dropped]
        s_r = 2.0 * np.sin(0.5 * radius) ** 2
        miss = np.log((1 - q) + q * np.exp(rho * s_r - s_r / sigma**2))
        n_unmatched = n_stars - len(dist) - (n_used - dropped)
        best = max(best, kept.sum() + n_unmatched * miss)
    return min(1.0, len(sigmas) * max(hyp, 1) * np.exp(-best))


def test_false_match_probability_is_hypotheses_over_the_likelihood_ratio():
    rng = np.random.default_rng(3)
    for _ in range(300):
        n_pairs = int(rng.integers(0, 12))
        n_stars = n_pairs + int(rng.integers(0, 5))
        sigmas = tuple(PX * rng.choice([0.25, 0.5, 1.0], size=int(rng.integers(1, 4))))
        radius = 3.5 * max(sigmas)
        dist = 2 * np.sin(0.5 * rng.uniform(0, radius, n_pairs))  # chords
        n_cone, area = int(rng.integers(1, 60)), float(rng.uniform(1e-3, 3e-2))
        hyp = int(rng.integers(0, 10**5))
        settings = MatchSettings(1e-3, radius, sigmas)
        got = Verification(
            np.arange(n_pairs), np.arange(n_pairs), dist, n_cone, area
        ).false_match_probability(n_stars, 3, hyp, settings)
        angles = 2 * np.arcsin(dist / 2)
        expected = _oracle_p(angles, n_cone, area, n_stars, 3, hyp, sigmas, radius)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-300)
        assert 0.0 <= got <= 1.0


# ------------------------------------------------------------------------------------- cone

CONE_AXES = [
    (0.0, 90.0),
    (0.0, -90.0),
    (123.0, 89.99),
    (0.0, 0.0),
    (360.0, 30.0),
    (359.99, -45.0),
    (0.01, 60.0),
    (83.8, -5.4),
    (201.3, -11.2),
]


@pytest.mark.parametrize(("ra", "dec"), CONE_AXES)
@pytest.mark.parametrize("radius_deg", [0.5, 6.0, 14.0, 40.0])
def test_cone_is_every_catalog_star_within_the_radius(catalog, database, ra, dec, radius_deg):
    axis = radec_to_unit(np.radians(ra), np.radians(dec))
    radius = np.radians(radius_deg)
    angle = angle_between(catalog.vectors, axis)
    got = database.cone(axis, radius)
    assert np.issubdtype(got.dtype, np.integer) and len(np.unique(got)) == len(got)
    got = set(got.tolist())
    assert set(np.flatnonzero(angle <= radius - 1e-9).tolist()) <= got
    assert got <= set(np.flatnonzero(angle <= radius + 1e-9).tolist())
    if radius_deg >= 6.0 and abs(dec) < 80.0 and (ra < 1.0 or ra > 359.0):
        ras = catalog.ra_deg[list(got)]  # the cone spans RA 0/360: both sides found
        assert np.any(ras < 5.0) and np.any(ras > 355.0)


# ------------------------------------------------------------------------ catalog_triangles


@pytest.fixture(scope="module")
def bright():
    return load_catalog(None, mag_limit=4.0)


def _brute_triangles(vectors, sides, tol):
    """Ordered triples (a, b, c) of distinct stars with |ab - ij|, |ac - ik|, |bc - jk| <=
    ``tol`` (radians), by testing every pair of the catalog."""
    A = angle_between(vectors[:, None, :], vectors[None, :, :])
    np.fill_diagonal(A, np.inf)
    ij, ik, jk = (np.abs(A - s) <= tol for s in sides)
    out = set()
    for a in range(len(vectors)):
        bs, cs = np.flatnonzero(ij[a]), np.flatnonzero(ik[a])
        if len(bs) and len(cs):
            hit = jk[np.ix_(bs, cs)]
            for p, q in zip(*np.nonzero(hit), strict=True):
                out.add((a, int(bs[p]), int(cs[q])))
    return out


def _triangle_cases(vectors):
    rng = np.random.default_rng(4)
    cases = []
    while len(cases) < 4:  # sides of real catalog triangles
        a = rng.integers(len(vectors))
        near = np.flatnonzero(angle_between(vectors, vectors[a]) < np.radians(10.0))
        near = near[near != a]
        if len(near) >= 2:
            b, c = rng.choice(near, 2, replace=False)
            sides = (
                angle_between(vectors[a], vectors[b]),
                angle_between(vectors[a], vectors[c]),
                angle_between(vectors[b], vectors[c]),
            )
            cases.append((tuple(float(s) for s in sides), np.radians(0.3)))
    deg = np.radians
    cases.append(((deg(5.0), deg(5.0), deg(3.0)), deg(0.4)))  # isosceles: both orders
    cases.append(((deg(6.0), deg(6.0), deg(6.0)), deg(0.5)))  # equilateral
    cases.append(((deg(4.0), deg(4.1), deg(0.1)), deg(0.3)))  # side jk below the tolerance
    cases.append(((deg(1.0), deg(1.0), deg(5.0)), deg(0.1)))  # no such triangle
    return cases


def test_catalog_triangles_are_every_matching_triple(bright):
    database = get_database(bright, CAMERA)
    vectors = bright.vectors
    found_any = 0
    for sides, tol in _triangle_cases(vectors):
        got = catalog_triangles(database, *sides, tol)
        assert got.ndim == 2 and got.shape[1] == 3 and np.issubdtype(got.dtype, np.integer)
        got_set = {tuple(map(int, t)) for t in got}
        assert len(got_set) == len(got)
        inner = _brute_triangles(vectors, sides, tol - 1e-9)
        outer = _brute_triangles(vectors, sides, tol + 1e-9)
        assert inner <= got_set <= outer, (sides, tol)
        found_any += len(got_set) > 0
    assert found_any >= 6  # most cases have triangles to find


# -------------------------------------------------------------------------------- wahba


@pytest.mark.parametrize("parity", [1, -1])
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("n", [2, 3, 12])
def test_wahba_is_scipys_align_vectors(parity, weighted, n):
    """Noisy pairs: the same rotation as Rotation.align_vectors (for parity -1 on the
    camera vectors with y mirrored, then mirrored back)."""
    rng = np.random.default_rng(n + 10 * weighted + (parity < 0))
    for _ in range(20):
        truth = Rotation.random(random_state=rng).as_matrix()
        if parity < 0:
            truth = MIRROR @ truth
        icrs = _unit(rng.normal(size=(n, 3)))
        cam = _unit(icrs @ truth.T + rng.normal(0.0, 0.02, (n, 3)))
        w = rng.uniform(0.2, 3.0, n) if weighted else None
        R = wahba(cam, icrs, w, parity=parity)
        ref = Rotation.align_vectors(cam @ MIRROR if parity < 0 else cam, icrs, weights=w)[0]
        expected = ref.as_matrix()
        if parity < 0:
            expected = MIRROR @ expected
        np.testing.assert_allclose(R, expected, atol=1e-9)
        assert np.linalg.det(R) == pytest.approx(parity)


def test_wahba_keeps_a_proper_rotation_when_the_data_are_mirrored():
    """Mirrored data asked for parity +1: the best proper rotation, as align_vectors gives
    (the determinant guard), not the reflection that fits better."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        icrs = _unit(rng.normal(size=(8, 3)))
        cam = icrs @ (MIRROR @ Rotation.random(random_state=rng).as_matrix()).T
        R = wahba(cam, icrs, parity=1)
        expected = Rotation.align_vectors(cam, icrs)[0].as_matrix()
        np.testing.assert_allclose(R, expected, atol=1e-9)
        assert np.linalg.det(R) == pytest.approx(1.0)


# ------------------------------------------------------------------------- refine_attitude


def _project(R, icrs, focal, cx, cy, k1, k2):
    """The pinhole with radial distortion, written out: x = cx + f u d, u = c_x / c_z."""
    c = icrs @ R.T
    u, v = c[:, 0] / c[:, 2], c[:, 1] / c[:, 2]
    r2 = u * u + v * v
    d = 1.0 + k1 * r2 + k2 * r2 * r2
    return np.column_stack([cx + focal * u * d, cy + focal * v * d])


def _oracle_fit(R0, icrs, xy, camera, fit_focal, fit_distortion):
    """scipy least_squares on the pixel residuals: rotation vector about the camera axes
    applied to R0, then the focal length, then k1, k2."""
    start = [camera.focal_px, camera.k1, camera.k2]
    n_extra = 3 if fit_distortion else 1 if fit_focal else 0

    def unpack(p):
        extra = list(p[3:]) + start[n_extra:]
        return Rotation.from_rotvec(p[:3]).as_matrix() @ R0, extra

    def fun(p):
        R, (focal, k1, k2) = unpack(p)
        return (_project(R, icrs, focal, camera.cx, camera.cy, k1, k2) - xy).ravel()

    x0 = np.concatenate([np.zeros(3), start[:n_extra]])
    fit = least_squares(
        fun,
        x0,
        jac="3-point",
        method="lm",
        x_scale="jac",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        max_nfev=5000,
    )
    R, (focal, k1, k2) = unpack(fit.x)
    return R, focal, k1, k2, fun(fit.x).reshape(-1, 2)


def _stars(catalog, camera, seed, noise_px, min_stars):
    rng = np.random.default_rng(seed)
    while True:
        frame = simulate_frame(catalog, camera, noise_px=noise_px, seed=rng)
        if len(frame.xy) >= min_stars:
            return frame, catalog.vectors[catalog.rows(frame.true_id)]


DISTORTED_1024 = Camera(1024, 1024, Camera.from_fov(20.0, 1024).focal_px, k1=-0.06, k2=0.02)
DISTORTED_640 = Camera(640, 480, Camera.from_fov(30.0, 640).focal_px, 322.0, 238.0, -0.08, 0.01)
REFINE_CASES = [
    # (camera, fit_focal, fit_distortion, focal start factor, start offset deg)
    (CAMERA, False, False, 1.0, 0.01),
    (CAMERA, False, False, 1.0, 3.0),
    (CAMERA, True, False, 1.01, 0.01),
    (CAMERA, True, False, 0.99, 3.0),
    (DISTORTED_1024, False, False, 1.0, 2.0),
    (DISTORTED_640, True, True, 1.005, 0.01),
    (DISTORTED_640, True, True, 0.995, 3.0),
]


@pytest.mark.parametrize(
    ("camera", "fit_focal", "fit_distortion", "scale", "off_deg"), REFINE_CASES
)
def test_refine_attitude_is_the_least_squares_solution(
    catalog, camera, fit_focal, fit_distortion, scale, off_deg
):
    frame, icrs = _stars(catalog, camera, 31, 0.3, 15 if fit_distortion else 6)
    rng = np.random.default_rng(5)
    axis = _unit(rng.normal(size=3))
    R0 = Rotation.from_rotvec(np.radians(off_deg) * axis).as_matrix() @ frame.R_cam_from_icrs
    start = Camera(
        camera.width,
        camera.height,
        camera.focal_px * scale,
        camera.cx,
        camera.cy,
        0.0 if fit_distortion else camera.k1,
        0.0 if fit_distortion else camera.k2,
    )
    got = refine_attitude(
        R0, icrs, frame.xy, start, fit_focal=fit_focal, fit_distortion=fit_distortion
    )
    R, focal, k1, k2, residuals = _oracle_fit(R0, icrs, frame.xy, start, fit_focal, fit_distortion)
    assert _angle_deg(got.R_cam_from_icrs, R) * 3600.0 < 1e-4  # arcsec
    assert got.camera.focal_px == pytest.approx(focal, rel=1e-9)
    assert got.camera.k1 == pytest.approx(k1, abs=1e-8)
    assert got.camera.k2 == pytest.approx(k2, abs=1e-7)
    np.testing.assert_allclose(got.residuals_px, residuals, atol=1e-6)
    assert np.sum(got.residuals_px**2) <= np.sum(residuals**2) + 1e-9  # no worse than scipy
    rms = np.sqrt(np.mean(np.sum(residuals**2, axis=1)))
    assert got.rms_px == pytest.approx(rms, rel=1e-6)
    # and the fit found the truth, to the noise
    error = angle_between(got.R_cam_from_icrs[2], frame.R_cam_from_icrs[2]) * ARCSEC_PER_RAD
    assert error < 5.0 * got.sigma_boresight_arcsec


@pytest.mark.parametrize("fit_focal", [False, True])
def test_refine_attitude_sigma_is_calibrated(catalog, fit_focal):
    """200 noisy copies of one frame: the rms of the boresight error over the mean reported
    1-sigma is near 1 (the reported sigma combines both cross-axes)."""
    frame, icrs = _stars(catalog, CAMERA, 8, 0.0, 10)
    rng = np.random.default_rng(11)
    errors, sigmas = [], []
    for _ in range(200):
        xy = frame.xy + rng.normal(0.0, 0.5, frame.xy.shape)
        got = refine_attitude(frame.R_cam_from_icrs, icrs, xy, CAMERA, fit_focal=fit_focal)
        errors.append(angle_between(got.R_cam_from_icrs[2], frame.R_cam_from_icrs[2]))
        sigmas.append(got.sigma_boresight_arcsec)
    ratio = np.sqrt(np.mean(np.square(errors))) * ARCSEC_PER_RAD / np.mean(sigmas)
    assert 0.8 <= ratio <= 1.25, ratio


# --------------------------------------------------------------------------------- camera


@pytest.mark.parametrize("camera", [CAMERA, DISTORTED_640, DISTORTED_1024])
def test_camera_projection_formula_and_round_trip(camera):
    """bearings_to_pixels is the formula written out; pixels_to_bearings inverts it over the
    whole image (corners included) to 1e-6 px."""
    gx, gy = np.meshgrid(np.linspace(0, camera.width, 33), np.linspace(0, camera.height, 25))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    b = camera.pixels_to_bearings(xy)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    assert np.all(b[:, 2] > 0)
    formula = _project(np.eye(3), b, camera.focal_px, camera.cx, camera.cy, camera.k1, camera.k2)
    np.testing.assert_allclose(formula, xy, atol=1e-6)
    np.testing.assert_allclose(camera.bearings_to_pixels(b), xy, atol=1e-6)
    rng = np.random.default_rng(1)
    c = _in_cap(rng, 500, camera.half_diagonal_rad)
    expected = _project(np.eye(3), c, camera.focal_px, camera.cx, camera.cy, camera.k1, camera.k2)
    np.testing.assert_allclose(camera.bearings_to_pixels(c * 3.0), expected, atol=1e-9)
    back = camera.pixels_to_bearings(expected)
    assert np.max(angle_between(back, c)) * camera.focal_px < 1e-6


# ---------------------------------------------------------------------- solve: the contract

PINHOLE_20 = Camera.from_fov(20.0, 1024)
CONTRACT_CAMERAS = {"12deg-512px": CAMERA, "20deg-1024px": PINHOLE_20}
METHODS = [*ALGORITHMS, "tracking"]


def _solve(method, camera, xy, brightness, catalog, prior):
    if method == "fov-search":
        return solve_stars(
            xy,
            fov_exact=False,
            width=camera.width,
            height=camera.height,
            brightness=brightness,
            camera=camera,
            sigma_px=0.3,
        )
    options = {"prior": prior} if method == "tracking" else {"algorithm": method}
    return starnav.solve_stars(
        xy,
        width=camera.width,
        height=camera.height,
        fov_deg=camera.fov_deg,
        brightness=brightness,
        catalog=catalog,
        sigma_px=0.3,
        **options,
    )


def _assert_right(solution, frame, catalog, camera, min_named):
    """Boresight within 0.05° of the truth and roll within 0.2° (about 6 sigma with 8 stars
    in the 12° field), every named point its true star (or the partner of a double closer
    than 2 px, which the noise cannot tell apart), at least ``min_named`` of the real stars
    named."""
    assert solution.parity == frame.truth[3]
    boresight_deg, roll_deg = attitude_difference_deg(
        solution.R_cam_from_icrs, frame.R_cam_from_icrs
    )
    assert boresight_deg < 0.05 and roll_deg < 0.2, (boresight_deg, roll_deg)
    named = 0
    for star, truth in zip(solution.stars, frame.true_id, strict=True):
        if star.catalog_id is None:
            continue
        named += 1
        if star.catalog_id != truth:
            assert truth != FALSE_STAR_ID, "a false star was named"
            pair = catalog.vectors[catalog.rows([star.catalog_id, truth])]
            assert angle_between(*pair) * camera.focal_px < 2.0, "a wrong star"
    assert named == solution.n_matched
    real = int(np.sum(frame.true_id != FALSE_STAR_ID))
    assert named >= min_named * real


def _contract(method, camera, catalog, seed):
    rng = np.random.default_rng(seed)
    fov = method == "fov-search"
    frames, solved = 0, 0
    for k in range(6):
        frame = simulate_frame(
            catalog,
            camera,
            parity=-1 if k == 0 else 1,
            noise_px=0.3,
            false_stars=1,
            missing_frac=0.1,
            seed=rng,
        )
        if np.sum(frame.true_id != FALSE_STAR_ID) < 8:
            continue
        frames += 1
        res = _solve(method, camera, frame.xy, frame.brightness, catalog, frame.R_cam_from_icrs)
        if res.solution is not None:
            solved += 1
            # solve_fov's catalog of a band is shallower than the frame's (mag 6)
            _assert_right(res.solution, frame, catalog, camera, 0.3 if fov else 0.7)
            if method == "tracking":
                assert res.solution.algorithm == "tracking"
    assert frames >= 4 and solved >= frames - 1, (frames, solved)
    prior = attitude_from_radec_roll(rng.uniform(0, 360), rng.uniform(-60, 60), 0.0)
    for _ in range(4):  # points at random: any answer would be wrong
        n = int(rng.integers(8, 20))
        xy = rng.uniform([0, 0], [camera.width, camera.height], (n, 2))
        res = _solve(method, camera, xy, rng.uniform(0.1, 1.0, n), catalog, prior)
        assert res.solution is None and res.reason


@pytest.mark.parametrize("camera_name", list(CONTRACT_CAMERAS))
@pytest.mark.parametrize("method", METHODS)
def test_solve_contract(catalog, method, camera_name):
    """Every algorithm (and tracking from the true attitude): simulated frames solved with
    the right stars and attitude, random points refused."""
    _contract(method, CONTRACT_CAMERAS[camera_name], catalog, seed=len(method) + 7)


def test_solve_contract_distorted_camera_through_solve_fov(catalog):
    """A 640 x 480 camera with off-centre principal point and radial distortion, given to
    solve_fov: the same contract."""
    _contract("fov-search", DISTORTED_640, catalog, seed=5)
