import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from starnav.camera import Camera
from starnav.cli import main
from starnav.geometry import (
    angle_between,
    attitude_from_radec_roll,
    radec_to_unit,
    unit_to_radec,
)
from starnav.pointing import (
    MIN_FLATNESS,
    PointingError,
    best_triple,
    boresight_covariance,
    flatness,
    linear_boresight,
    three_star,
)


def _triple(ra, dec, roll, focal, xy, parity=1, width=512):
    """Catalog RA/Dec (degrees) of the sky points seen at pixels ``xy``."""
    cam = Camera(width, width, focal)
    R = attitude_from_radec_roll(ra, dec, roll, parity)
    u = cam.pixels_to_bearings(xy) @ R
    r, d = unit_to_radec(u)
    return np.degrees(r), np.degrees(d), R


def _angle(a, b):
    return float(angle_between(a, b))


@settings(max_examples=60, deadline=None)
@given(
    ra=st.floats(0, 360),
    dec=st.floats(-85, 85),
    roll=st.floats(0, 360),
    focal=st.floats(400, 8000),
    seed=st.integers(0, 2**32 - 1),
)
def test_noiseless_triple_gives_boresight_exactly(ra, dec, roll, focal, seed):
    xy = np.random.default_rng(seed).uniform(10, 502, (3, 2))
    ras, decs, R = _triple(ra, dec, roll, focal, xy)
    if flatness(radec_to_unit(np.radians(ras), np.radians(decs))) < MIN_FLATNESS:
        return  # (nearly) collinear: refused, tested below
    known = three_star(ras, decs, xy=xy, width=512, height=512, focal_px=focal)
    assert _angle(known.boresight, R[2]) < 1e-9
    assert abs(known.consistency) < 1e-9
    assert abs((known.roll_deg - roll + 180) % 360 - 180) < 1e-6
    unknown = three_star(ras, decs, xy=xy, width=512, height=512)
    assert _angle(unknown.boresight, R[2]) < 1e-9
    # where the solver itself says the geometry hardly fixes f (1 px moving it by > 1 %),
    # float rounding alone moves the root by more than 1e-9 of f
    poorly_fixed = "hardly determines the focal length" in unknown.note
    assert unknown.focal_px == pytest.approx(focal, rel=1e-6 if poorly_fixed else 1e-9)


def test_distances_only_give_every_candidate_focal_length():
    """From r_px alone several (f, boresight) can fit exactly: all are returned, the true one
    among them."""
    rng = np.random.default_rng(0)
    several = 0
    for _ in range(10):
        focal = rng.uniform(1000, 5000)
        xy = rng.uniform(20, 490, (3, 2))
        ras, decs, R = _triple(rng.uniform(0, 360), rng.uniform(-80, 80), 0.0, focal, xy)
        result = three_star(ras, decs, r_px=np.hypot(*(xy - 256).T))
        found = [result, *result.alternatives]
        best = min(found, key=lambda p: abs(p.focal_px - focal))
        assert best.focal_px == pytest.approx(focal, rel=1e-9)
        assert _angle(best.boresight, R[2]) < 1e-9
        assert result.roll_deg is None  # no roll from distances alone
        if len(found) > 1:
            several += 1
            assert "focal lengths fit" in result.note
    assert several >= 3


def test_equal_distances_still_determine_the_focal_length():
    """Stars on a circle about the centre: the boresight is their spherical circumcentre and
    f = a / tan(theta) follows; starnav finds it (a finding: this case is not degenerate)."""
    angles = np.radians([10.0, 130.0, 250.0])
    xy = 256 + 200 * np.column_stack([np.cos(angles), np.sin(angles)])
    ras, decs, R = _triple(50.0, 10.0, 0.0, 3000.0, xy)
    result = three_star(ras, decs, r_px=np.full(3, 200.0))
    assert [result.focal_px] + [a.focal_px for a in result.alternatives] == pytest.approx(
        [3000.0], rel=1e-9
    )
    assert _angle(result.boresight, R[2]) < 1e-9


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_analytic_covariance_matches_monte_carlo(seed):
    """1-sigma boresight error of any triple: analytic vs 20 000 noisy trials, within 10 %."""
    rng = np.random.default_rng(seed)
    focal, sigma = 2435.68, 0.5
    xy = rng.uniform(30, 480, (3, 2))
    ras, decs, _ = _triple(200.0, 45.0, 0.0, focal, xy)
    U = radec_to_unit(np.radians(ras), np.radians(decs))
    a = np.hypot(*(xy - 256).T)
    cov = boresight_covariance(U, a, focal, np.full(3, sigma))
    analytic = np.sqrt(np.trace(cov))
    trials = 20000
    noisy = xy[None] + rng.normal(0, sigma, (trials, 3, 2))
    a_noisy = np.hypot(noisy[..., 0] - 256, noisy[..., 1] - 256)
    c = focal / np.sqrt(a_noisy**2 + focal**2)
    d = np.linalg.solve(U, c.T).T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    truth = linear_boresight(U, a, focal)
    truth /= np.linalg.norm(truth)
    err = np.arccos(np.clip(d @ truth, -1, 1))
    assert np.sqrt(np.mean(err**2)) == pytest.approx(analytic, rel=0.1)
    pointing = three_star(ras, decs, xy=xy, width=512, height=512, focal_px=focal, sigma_px=sigma)
    assert pointing.sigma_boresight_arcsec == pytest.approx(np.degrees(analytic) * 3600)


def test_best_triple_beats_a_bad_one():
    xy = np.array([[20.0, 20.0], [490.0, 30.0], [250.0, 480.0], [250, 250], [262, 255], [245, 262]])
    ras, decs, _ = _triple(10.0, 0.0, 0.0, 2435.68, xy)
    triple = best_triple(ras, decs, xy, focal_px=2435.68, width=512, height=512)
    assert sorted(triple) == [0, 1, 2]


@pytest.mark.parametrize(
    "ra,dec,kwargs,needle",
    [
        ([1, 2], [3, 4], {"r_px": [1, 2]}, "exactly 3 stars"),
        ([1, 1, 2], [3, 3, 4], {"r_px": [1, 2, 3]}, "same star"),
        ([10, 11, 12], [0, 0, 0], {"r_px": [1, 2, 3]}, "collinear"),
        ([10, 11, 12], [0, 1, 0], {"r_px": [1, 2, 900], "width": 512, "height": 512}, "beyond the"),
        ([10, 11, 12], [0, 1, 0], {}, "either xy"),
        ([10, 11, 12], [0, 1, 0], {"r_px": [10, 20, 30], "focal_px": 100.0}, "do not fit"),
        ([10, 11, 12], [0, 1, 0], {"xy": [[1, 2], [3, 4], [5, 6]]}, "give the image width"),
        ([10, 11, 12], [0, 1, 0], {"r_px": [1, 2, 3], "focal_px": 1e300}, "focal_px must be"),
        (
            [10, 11, 12],
            [0, 1, 0],
            {"xy": [[1, 1], [1, 1], [7, 7]], "width": 512, "focal_px": 2435.68},
            "do not match the star separations",
        ),
    ],
)
def test_bad_input(ra, dec, kwargs, needle):
    with pytest.raises(PointingError, match=needle):
        three_star(ra, dec, **kwargs)


def _csv(tmp_path, xy, ras, decs, extra=""):
    path = tmp_path / "stars.csv"
    lines = ["label,ra_deg,dec_deg,x,y"] + [
        f"s{k},{r},{d},{x},{y}" for k, (r, d, (x, y)) in enumerate(zip(ras, decs, xy, strict=True))
    ]
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def test_cli_pointing_json_and_select_best(capsys, tmp_path):
    xy = np.array([[20.0, 20.0], [490.0, 30.0], [250.0, 480.0], [250, 250], [262, 255]])
    ras, decs, _ = _triple(10.0, 20.0, 33.0, 2435.68, xy)
    path = _csv(tmp_path, xy, ras, decs)
    code = main(
        [
            "pointing",
            str(path),
            "--focal-px",
            "2435.68",
            "--width",
            "512",
            "--sigma-px",
            "0.5",
            "--select-best",
            "--json",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and sorted(out["stars_used"]) == ["s0", "s1", "s2"]
    assert {
        "ra_deg",
        "dec_deg",
        "roll_deg",
        "focal_px",
        "consistency",
        "sigma_boresight_arcsec",
        "alternatives",
    } <= set(out)
    assert out["roll_deg"] == pytest.approx(33.0, abs=1e-6)
    assert out["sigma_boresight_arcsec"] > 0
    code = main(["pointing", str(path), "--width", "512"])  # 5 stars without --select-best
    assert code == 2 and "exactly 3 stars" in capsys.readouterr().err


def test_cli_pointing_unknown_focal_table(capsys, tmp_path):
    xy = np.array([[60.0, 80.0], [430.0, 150.0], [200.0, 470.0]])
    ras, decs, _ = _triple(300.0, -60.0, 0.0, 1800.0, xy)
    code = main(["pointing", str(_csv(tmp_path, xy, ras, decs)), "--width", "512"])
    out = capsys.readouterr().out
    assert code == 0 and "focal 1800.000 px" in out


@pytest.mark.parametrize(
    "text,needle",
    [
        ("ra_deg,dec_deg\n1,2\n3,4\n5,6\n", "either x,y or r_px"),
        ("ra_deg,dec_deg,r_px\n1,2,3\n1,2,4\n5,6,7\n", "same star"),
        ("ra_deg,dec_deg,r_px\n1,2,x\n1,3,4\n5,6,7\n", "not a number"),
    ],
)
def test_cli_pointing_bad_files(capsys, tmp_path, text, needle):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    code = main(["pointing", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1


def test_best_three_star_from_a_solution(contest_catalog):
    """Best triple of contest map 1's identified stars: boresight within 1 arcmin of the full
    least-squares attitude (the map is exact)."""
    import starnav
    from shared_data import CONTEST
    from starnav.starlist import read_star_csv

    stars = read_star_csv(CONTEST / "images" / "xingtu01.csv")
    s = starnav.solve(
        stars.xy, width=512, fov_deg=12.0, labels=stars.labels, catalog=contest_catalog
    )
    pointing, used = starnav.best_three_star(s, width=512, catalog=contest_catalog)
    assert len(used) == 3 and set(used) <= set(stars.labels)
    assert _angle(pointing.boresight, s.R_cam_from_icrs[2]) < np.radians(1 / 60)
    assert pointing.roll_deg == pytest.approx(s.roll_deg, abs=0.05)


@pytest.mark.slow
def test_cli_pointing_study(capsys, tmp_path):
    code = main(["pointing-study", "--trials", "500", "--out-dir", str(tmp_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["best"].startswith("equilateral")
    assert out["worst"].startswith("nearly collinear") and out["worst_over_best"] > 10
    assert all(
        (tmp_path / name).exists()
        for name in (
            "pointing_arrangements.png",
            "pointing_placement_map.png",
            "pointing_volume.png",
        )
    )


@pytest.mark.slow
def test_unknown_focal_error_propagation_matches_monte_carlo():
    """With f solved from the same distances, the analytic 1σ of f and of the boresight
    (which then includes f's error) agree with a Monte Carlo within 10 %."""
    xy = np.array([[60.0, 80.0], [430.0, 150.0], [200.0, 470.0]])
    ras, decs, R = _triple(120.0, -30.0, 40.0, 2435.68, xy)
    a = np.hypot(*(xy - 256).T)
    sigma = 0.5
    ref = three_star(ras, decs, r_px=a, sigma_px=sigma)
    assert not ref.alternatives  # one solution: no root switching in the draws
    rng = np.random.default_rng(4)
    focal, err = [], []
    for _ in range(2000):
        p = three_star(ras, decs, r_px=a + rng.normal(0, sigma, 3))
        best = min([p, *p.alternatives], key=lambda q: abs(q.focal_px - ref.focal_px))
        focal.append(best.focal_px)
        err.append(_angle(best.boresight, R[2]))
    assert np.std(focal) == pytest.approx(ref.sigma_focal_px, rel=0.1)
    mc = np.degrees(np.sqrt(np.mean(np.square(err)))) * 3600
    assert mc == pytest.approx(ref.sigma_boresight_arcsec, rel=0.1)


def test_thin_triangle_roots_are_not_missed():
    """Two roots within 0.4 % of each other (a thin triangle, exact data): both found
    (a coarse sign-change search found neither and refused the data)."""
    ras = [353.40592511423176, 3.1660248221705554, 14.973247776808579]
    decs = [-77.02625840873065, -80.14394609493496, -81.11053022852899]
    xy = [
        [324.9118089621124, 130.07395242567063],
        [214.76459234987664, 303.5688736217278],
        [117.8771464182538, 375.67404960463057],
    ]
    result = three_star(ras, decs, xy=xy, width=512)
    assert len(result.alternatives) == 1 and result.fit_rms_px < 1e-6
    assert "hardly determines the focal length" in result.note


def test_mirrored_image_roll_and_parity_found():
    xy = np.array([[60.0, 80.0], [430.0, 150.0], [200.0, 470.0]])
    ras, decs, _ = _triple(300.0, -60.0, 25.0, 1800.0, xy, parity=-1)
    result = three_star(ras, decs, xy=xy, width=512)
    assert result.parity == -1 and result.roll_deg == pytest.approx(25.0, abs=1e-6)
    assert result.focal_px == pytest.approx(1800.0, rel=1e-9)
    forced = three_star(ras, decs, xy=xy, width=512, parity=1)  # the wrong parity, forced
    assert forced.parity == 1 and abs((forced.roll_deg - 25.0 + 180) % 360 - 180) > 1.0


def test_select_best_among_many_stars_is_bounded():
    rng = np.random.default_rng(9)
    xy = rng.uniform(10, 500, (200, 2))
    ras, decs, _ = _triple(10.0, 20.0, 33.0, 2435.68, xy)
    triple = best_triple(ras, decs, xy, focal_px=2435.68, width=512)
    assert max(triple) < 40  # only the first 40 (brightest) are considered


def test_root_on_a_grid_point_is_found():
    """f = 1000 px lies exactly on the search grid; rounding put g(f) = ±1e-16 there and the
    root slipped between two brackets (found by hypothesis)."""
    xy = np.random.default_rng(41135).uniform(10, 502, (3, 2))
    ras, decs, R = _triple(0.0, 0.0, 1.0, 1000.0, xy)
    result = three_star(ras, decs, xy=xy, width=512)
    assert result.focal_px == pytest.approx(1000.0, rel=1e-9)
    assert _angle(result.boresight, R[2]) < 1e-9
