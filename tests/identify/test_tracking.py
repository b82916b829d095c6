"""Tracking mode: identification near a previous attitude, and the fall-back to lost in space."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import starnav
from shared_data import CONTEST
from starnav.camera import Camera
from starnav.cli import main
from starnav.errors import StarnavError
from starnav.geometry import attitude_difference_deg
from starnav.simulate import simulate_frame

CAMERA = Camera.from_fov(12.0, 512)


def _turned(R, angle_deg, rng):
    axis = rng.normal(size=3)
    axis *= np.radians(angle_deg) / np.linalg.norm(axis)
    return Rotation.from_rotvec(axis).as_matrix() @ R


def _solve(frame, catalog, **kwargs):
    return starnav.solve_stars(
        frame.xy,
        width=512,
        fov_deg=12.0,
        brightness=frame.brightness,
        catalog=catalog,
        sigma_px=0.3,
        **kwargs,
    )


def test_prior_within_a_degree_is_tracked_and_right(hip_1991):
    rng = np.random.default_rng(7)
    tracked = 0
    for _ in range(20):
        f = simulate_frame(hip_1991, CAMERA, noise_px=0.3, false_stars=1, seed=rng)
        if len(f.xy) < 6:
            continue
        r = _solve(f, hip_1991, prior=_turned(f.R_cam_from_icrs, 1.0, rng), prior_sigma_deg=1.0)
        assert r.solution is not None
        boresight, roll = attitude_difference_deg(r.solution.R_cam_from_icrs, f.R_cam_from_icrs)
        assert boresight < 0.05 and roll < 0.5
        tracked += r.solution.algorithm == "tracking"
    assert tracked >= 15


def test_wrong_prior_falls_back_to_lost_in_space(hip_1991):
    rng = np.random.default_rng(8)
    f = simulate_frame(hip_1991, CAMERA, ra_deg=83.8, dec_deg=-5.4, roll_deg=30, noise_px=0.3)
    r = _solve(f, hip_1991, prior=_turned(f.R_cam_from_icrs, 40.0, rng), prior_sigma_deg=1.0)
    assert r.solution is not None and r.solution.algorithm == "pyramid"
    boresight, _ = attitude_difference_deg(r.solution.R_cam_from_icrs, f.R_cam_from_icrs)
    assert boresight < 0.05


def test_prior_helps_few_star_frames(hip_1991):
    """Frames with 4-5 real stars: the prior cuts the hypotheses, so more are confirmed
    (never wrongly)."""
    rng = np.random.default_rng(9)
    lost = tracked = tried = 0
    while tried < 25:
        f = simulate_frame(hip_1991, CAMERA, noise_px=0.3, seed=rng)
        if not 4 <= len(f.xy) <= 5:
            continue
        tried += 1
        lost += _solve(f, hip_1991).solution is not None
        r = _solve(f, hip_1991, prior=_turned(f.R_cam_from_icrs, 0.5, rng), prior_sigma_deg=0.5)
        if r.solution is not None:
            tracked += 1
            boresight, roll = attitude_difference_deg(r.solution.R_cam_from_icrs, f.R_cam_from_icrs)
            assert boresight < 0.05 and roll < 0.5
    assert tracked > lost


@pytest.mark.parametrize(
    "prior,sigma,needle",
    [
        (np.eye(2), 1.0, "3x3 rotation"),
        (np.eye(3) * 2, 1.0, "3x3 rotation"),
        (np.eye(3), 0.0, "prior_sigma_deg"),
        (np.eye(3), 90.0, "prior_sigma_deg"),
    ],
)
def test_bad_prior_is_refused(hip_1991, prior, sigma, needle):
    f = simulate_frame(hip_1991, CAMERA, ra_deg=10.0, dec_deg=10.0, roll_deg=0.0)
    with pytest.raises(StarnavError, match=needle):
        _solve(f, hip_1991, prior=prior, prior_sigma_deg=sigma)


def test_cli_tracking_on_contest_map_1(capsys):
    base = [
        "identify",
        str(CONTEST / "images" / "xingtu01.csv"),
        "--fov-deg",
        "12",
        "--width",
        "512",
        "--catalog",
        str(CONTEST / "catalog.csv"),
        "--json",
    ]
    prior = [
        "--prior-ra-deg",
        "109.9",
        "--prior-dec-deg",
        "34.2",
        "--prior-roll-deg",
        "270.5",
        "--parity",
        "-1",
    ]
    assert main([*base, *prior]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["algorithm"] == "tracking" and out["n_matched"] == 15
    assert main([*base, "--prior-ra-deg", "10"]) == 2
    assert "needs all of" in capsys.readouterr().err


def test_solve_batch_on_processes_matches_one_by_one(hip_1991):
    rng = np.random.default_rng(11)
    frames = [simulate_frame(hip_1991, CAMERA, noise_px=0.3, seed=rng) for _ in range(8)]
    frames = [f for f in frames if len(f.xy) >= 3]
    options = dict(width=512, fov_deg=12.0, catalog=hip_1991, sigma_px=0.3)
    pooled = starnav.solve_stars_batch(
        [f.xy for f in frames], brightness=[f.brightness for f in frames], workers=2, **options
    )
    assert len(pooled) == len(frames)
    for f, r in zip(frames, pooled, strict=True):
        solution, reason, ms = r.solution, r.reason, r.time_ms
        one = starnav.solve_stars(f.xy, brightness=f.brightness, **options).solution
        assert (solution is None) == (one is None)
        if solution is not None:
            assert np.allclose(solution.R_cam_from_icrs, one.R_cam_from_icrs, atol=1e-9)
            assert ms > 0 and reason == ""


def test_batch_keeps_going_past_a_bad_frame(hip_1991):
    results = starnav.solve_stars_batch(
        [np.array([[1.0, 2.0]]), np.array([[10.0, 10.0], [50.0, 60.0], [200.0, 300.0]])],
        workers=1,
        width=512,
        fov_deg=12.0,
        catalog=hip_1991,
    )
    assert results[0].solution is None and results[0].bad_input
    assert "at least 3 stars" in results[0].error and results[0].reason == results[0].error
    assert results[1].solution is None and not results[1].bad_input and results[1].reason


def test_cli_identify_a_directory(tmp_path, capsys):
    for seed in range(4):
        assert (
            main(
                [
                    "simulate",
                    "--fov-deg",
                    "12",
                    "--width",
                    "512",
                    "--noise-px",
                    "0.3",
                    "--seed",
                    str(seed),
                    "-o",
                    str(tmp_path / f"f{seed}.csv"),
                ]
            )
            == 0
        )
    capsys.readouterr()
    assert (
        main(
            [
                "identify",
                str(tmp_path),
                "--fov-deg",
                "12",
                "--width",
                "512",
                "--json",
                "--workers",
                "2",
            ]
        )
        == 0
    )
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["file"].rsplit("/", 1)[1] for line in lines] == [f"f{k}.csv" for k in range(4)]
    assert all(line["solved"] for line in lines)
    (tmp_path / "bad.csv").write_text("x,y\n")
    assert main(["identify", str(tmp_path), "--fov-deg", "12", "--width", "512"]) == 2
    assert "bad.csv: not solved: error:" in capsys.readouterr().out
    assert (
        main(["identify", str(tmp_path), "--fov-deg", "12", "--width", "512", "--plot", "x.png"])
        == 2
    )
