import csv
import json
import pickle
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from starnav.camera import Equidistant, Equisolid, save_camera
from starnav.cli import main
from starnav.errors import StarnavError
from starnav.evaluate import (
    KINDS,
    EvalConfig,
    camera_items,
    grid_boresights,
    run_evaluation,
    runner,
    solve_frame,
    summarize,
    uniform_boresights,
)
from starnav.evaluate.kinds import MIRROR
from starnav.evaluate.report import describe
from starnav.geometry import attitude_difference_deg
from starnav.simulate import FALSE_STAR_ID
from starnav.starlist import check_star_list


def test_published_grid_has_7200_boresights_inside_the_sky():
    b = grid_boresights(3.0)
    assert len(b) == 7200
    assert b.ra_deg.min() == 0.0 and b.ra_deg.max() == 357.0
    assert b.dec_deg.min() == -88.5 and b.dec_deg.max() == 88.5
    assert len({(r, d) for r, d in zip(b.ra_deg, b.dec_deg, strict=True)}) == 7200


def test_uniform_sampling_is_uniform_on_the_sphere_and_reproducible():
    a = uniform_boresights(4000, seed=3)
    b = uniform_boresights(4000, seed=3)
    assert np.array_equal(a.ra_deg, b.ra_deg) and np.array_equal(a.roll_deg, b.roll_deg)
    # uniform on the sphere: sin(dec) uniform, so half the frames within |dec| < 30°
    assert abs(np.mean(np.abs(a.dec_deg) < 30.0) - 0.5) < 0.03


@pytest.mark.parametrize("bad", [0.0, -3.0, float("nan")])
def test_bad_grid_step_is_refused(bad):
    with pytest.raises(StarnavError, match="grid step"):
        grid_boresights(bad)


@pytest.mark.slow
def test_frames_are_the_same_wherever_they_are_solved():
    """Serial and two processes give the same outcome and stars for every frame."""
    config = EvalConfig(noise_px=0.5, false_stars=2, missing_frac=0.1, seed=4)
    b = uniform_boresights(40, seed=4)
    serial = run_evaluation(config, b, workers=1)
    pooled = run_evaluation(config, b, workers=2)
    key = [(r.index, r.outcome, r.n_points, r.n_identified) for r in serial]
    assert key == [(r.index, r.outcome, r.n_points, r.n_identified) for r in pooled]
    s = summarize(serial, db_bytes=1, wall_s=1.0)
    assert s.frames == 40 and s.correct + s.wrong + s.none == 40
    assert s.wrong == 0 and s.correct >= 36


def test_frame_with_too_few_points_is_scored_none_not_raised():
    config = EvalConfig(fov_deg=2.0, noise_px=0.0, false_stars=0, missing_frac=0.0, seed=1)
    b = uniform_boresights(30, seed=1)
    results = [solve_frame(config, b, i) for i in range(30)]
    few = [r for r in results if r.n_points < 3]
    assert few, "a 2° field at Hp 6 is usually nearly empty"
    assert all(r.outcome == "none" and "3 needed" in r.reason for r in few)


def test_scorer_counts_right_and_wrong_attitudes(monkeypatch):
    """A frame solved right is correct; the same solution turned by 0.2° is wrong."""
    config = EvalConfig(noise_px=0.2, false_stars=0, missing_frac=0.0, seed=2)
    b = uniform_boresights(5, seed=2)
    r = solve_frame(config, b, 0)
    assert r.outcome == "correct" and r.boresight_error_arcsec < 60.0
    assert r.n_identified >= 3 and r.n_wrong_ids == 0

    solver = runner.config_solver(config)
    real = solver.solve

    def turned(*args, **kwargs):
        result = real(*args, **kwargs)
        R = (
            Rotation.from_euler("x", 0.2, degrees=True).as_matrix()
            @ result.solution.R_cam_from_icrs
        )
        return replace(result, solution=replace(result.solution, R_cam_from_icrs=R))

    monkeypatch.setattr(solver, "solve", turned)
    wrong = solve_frame(config, b, 0)
    assert wrong.outcome == "wrong" and 0.1 < wrong.boresight_error_arcsec / 3600 < 0.3


def test_cli_evaluate_json_csv_and_sky_map(tmp_path, capsys):
    csv_path, png = tmp_path / "frames.csv", tmp_path / "sky.png"
    code = main(
        [
            "evaluate",
            "--grid-step-deg",
            "30",
            "--workers",
            "1",
            "--frames-csv",
            str(csv_path),
            "--sky-map",
            str(png),
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("frames", "correct", "wrong", "none", "correct_rate", "wrong_rate"):
        assert key in out
    assert out["frames"] == 72 and out["wrong"] == 0
    assert out["median_ms"] > 0 and out["p95_ms"] >= out["median_ms"] and out["db_bytes"] > 1e6
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 72
    assert sum(r["outcome"] == "correct" for r in rows) == out["correct"]
    assert png.stat().st_size > 10_000


def test_cli_evaluate_markdown(capsys):
    assert main(["evaluate", "--sampling", "uniform", "--frames", "8", "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "| pyramid | 8 |" in out and "uniform on the sphere" in out


@pytest.mark.slow
def test_cli_evaluate_on_a_local_dask_cluster(capsys):
    pytest.importorskip("distributed")
    args = ["evaluate", "--sampling", "uniform", "--frames", "20", "--json", "--seed", "5",
            "--kind", "true,random,mirrored,few"]  # fmt: skip
    assert main([*args, "--dask", "local", "--workers", "2"]) == 0
    dask = json.loads(capsys.readouterr().out)
    assert main([*args, "--workers", "1"]) == 0
    serial = json.loads(capsys.readouterr().out)
    assert (dask["correct"], dask["none"]) == (serial["correct"], serial["none"])
    for kind in ("true", "random", "mirrored", "few"):  # every frame remade from (seed, index)
        assert dask["by_kind"][kind]["frames"] == 5
        assert dask["by_kind"][kind]["correct"] == serial["by_kind"][kind]["correct"]
    assert dask["by_kind"]["random"]["correct"] == 0 and dask["wrong"] == 0


@pytest.mark.parametrize(
    "args,message",
    [
        (["--missing-frac", "1.5"], "missing_frac"),
        (["--noise-px", "-1"], "noise_px"),
        (["--fov-deg", "0"], "fov_deg"),
        (["--mag-limit", "40"], "mag limit"),
        (["--grid-step-deg", "0"], "grid step"),
        (["--sky-map", "/nonexistent/dir/x.png"], "does not exist"),
        (["--kind", "true,nonsense"], "unknown frame kind 'nonsense'"),
        (["--kind", ","], "no frame kind given"),
        (["--max-false-match-probability", "1.5"], "max_false_match_probability"),
    ],
)
def test_cli_evaluate_bad_input_is_one_line_exit_2(args, message, capsys):
    assert main(["evaluate", "--workers", "1", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err


@pytest.mark.parametrize(
    "seed,index,algorithm",
    [
        (0, 4963, "pyramid"),
        (0, 1098, "pyramid"),
        (2026, 6543, "pyramid"),
        (2026, 662, "star-lines"),
    ],
)
def test_first_match_on_one_side_or_with_a_wrong_double_is_repaired(seed, index, algorithm):
    """Regressions from the 3° grid (0.5 px noise, 2 false stars, 10 % missing), each once
    reported with a wrong attitude (0.05-0.07° boresight, 0.3-0.7° roll):
    - 4963, 1098: the first verified stars sat in one part of the image; the poorly fixed
      roll put the far stars outside the match radius (now: gate by the attitude's covariance);
    - 6543: that wider gate let a false star 5.7 px from a real one in, and the fit bent to
      it (now: studentized residuals drop it);
    - 662: the first match took the faint star of a 4 px pair, and the fit bent so that the
      far stars fell outside the radius (now: a wide search from the result, kept when it
      explains more stars and fits the shared ones as well);
    - 6629 (neighbor-sum): a false match of 5 stars (2 of them false stars) accepted at p 6e-5
      because only the 4 feature pairs were counted as hypotheses, not the 3-star hypotheses
      chosen among (now all counted)."""
    config = EvalConfig(
        noise_px=0.5, false_stars=2, missing_frac=0.1, seed=seed, algorithm=algorithm
    )
    r = solve_frame(config, grid_boresights(3.0, seed=seed), index)
    assert r.outcome == "correct" and r.boresight_error_arcsec < 60.0
    assert r.n_identified >= r.n_true - 1 and r.n_wrong_ids == 0


def _allsky_config(**kwargs) -> EvalConfig:
    camera = Equidistant.from_fov(185.0, 1024, 1024).with_circle(185.0)
    defaults = dict(mag_limit=5.0, noise_px=0.3, false_stars=2, missing_frac=0.1, seed=6)
    return EvalConfig(camera=camera_items(camera), **{**defaults, **kwargs})


def test_a_fisheye_configuration_makes_its_camera_everywhere():
    config = _allsky_config()
    camera = config.make_camera()
    assert isinstance(camera, Equidistant) and camera.image_circle_deg == 185.0
    assert camera == Equidistant.from_fov(185.0, 1024, 1024).with_circle(185.0)
    # workers and Dask get the configuration pickled: the camera travels inside it
    assert pickle.loads(pickle.dumps(config)).make_camera() == camera
    assert runner.config_solver(config).camera == camera
    assert "equidistant 185° / 1024x1024 px (image circle 185°)" in describe(config, "x")
    assert EvalConfig().make_camera().model == "pinhole"


def test_all_sky_frames_are_simulated_and_solved_through_the_fisheye():
    config = _allsky_config()
    b = uniform_boresights(3, seed=6)
    results = [solve_frame(config, b, i) for i in range(3)]
    for r in results:
        assert r.n_in_view > 600  # the whole sky above the lens, to Hp 5
        assert r.outcome == "correct" and r.boresight_error_arcsec < 60.0
        assert r.n_identified >= 0.8 * r.n_true and r.n_wrong_ids == 0


def test_cli_evaluate_with_a_camera_file(tmp_path, capsys):
    path = tmp_path / "allsky.json"
    save_camera(path, Equisolid.from_fov(185.0, 1024, 1024).with_circle(185.0))
    args = ["evaluate", "--camera", str(path), "--sampling", "uniform", "--frames", "4"]
    args += ["--mag-limit", "5", "--workers", "1", "--seed", "2"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["config"]["camera"]["model"] == "equisolid"
    assert out["config"]["width"] == 1024 and out["config"]["fov_deg"] == pytest.approx(185.0)
    assert out["frames"] == 4 and out["wrong"] == 0 and out["correct"] >= 3
    assert main(args) == 0
    assert "equisolid 185° / 1024x1024 px (image circle 185°)" in capsys.readouterr().out
    assert main([*args, "--fov-deg", "20"]) == 2
    err = capsys.readouterr().err.strip()
    assert "drop --fov-deg" in err and "\n" not in err


def _kind_frame(kind: str, index: int = 3, seed: int = 7):
    config = EvalConfig(seed=seed, kinds=(kind,))
    return runner.config_frame(config, uniform_boresights(index + 1, seed=seed), index)


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_remakes_the_same_frame_from_seed_and_index(kind):
    (a, fa), (b, fb) = _kind_frame(kind), _kind_frame(kind)
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.mag, b.mag) and fa == fb
    assert np.array_equal(a.true_id, b.true_id)
    assert np.array_equal(a.R_cam_from_icrs, b.R_cam_from_icrs)
    assert len(a.xy) >= 3 and a.camera.contains(a.xy).all()
    other, _ = _kind_frame(kind, index=4)
    assert not np.array_equal(a.xy[:3], other.xy[:3])


def test_each_kind_makes_what_it_says():
    true, _ = _kind_frame("true")
    real = true.true_id != FALSE_STAR_ID
    random, _ = _kind_frame("random")
    assert len(random.xy) == max(len(true.xy), 3) and (random.true_id == FALSE_STAR_ID).all()
    scrambled, _ = _kind_frame("scrambled")
    assert np.array_equal(np.sort(scrambled.xy[:, 0]), np.sort(true.xy[:, 0]))
    assert np.array_equal(scrambled.mag, true.mag)  # every point keeps its brightness
    assert np.sum(scrambled.true_id != FALSE_STAR_ID) < real.sum() / 2
    mirrored, _ = _kind_frame("mirrored")
    assert np.allclose(mirrored.xy[:, 0], true.camera.width - true.xy[:, 0])
    assert np.allclose(mirrored.R_cam_from_icrs, MIRROR @ true.R_cam_from_icrs)
    assert np.linalg.det(mirrored.R_cam_from_icrs) < 0
    off, factor = _kind_frame("fov-off")
    assert 0.02 <= abs(factor - 1.0) <= 0.10
    assert off.camera.focal_px == pytest.approx(true.camera.focal_px * factor)
    crowded, _ = _kind_frame("crowded")
    n_false = np.sum(crowded.true_id == FALSE_STAR_ID)
    assert n_false == len(crowded.xy) - n_false == real.sum()
    few, _ = _kind_frame("few")
    assert 3 <= np.sum(few.true_id != FALSE_STAR_ID) <= 6
    assert np.sum(few.true_id == FALSE_STAR_ID) == 2
    assert set(few.true_id) <= set(true.true_id)


def test_a_solved_random_frame_is_wrong_and_a_mirrored_one_needs_parity_minus_1(monkeypatch):
    config = EvalConfig(kinds=("true", "random", "mirrored"), seed=2)
    b = uniform_boresights(3, seed=2)
    true = solve_frame(config, b, 0)
    assert true.kind == "true" and true.outcome == "correct"
    assert 0.0 <= true.false_match_probability < 1e-4
    mirrored = solve_frame(config, b, 2)
    assert mirrored.kind == "mirrored" and mirrored.outcome == "correct"
    refused = solve_frame(config, b, 1)
    assert refused.kind == "random" and refused.outcome == "none"
    assert np.isnan(refused.false_match_probability)

    solver = runner.config_solver(config)
    real = solver.solve
    answer = real(*_stars_of(config, b, 0))

    monkeypatch.setattr(solver, "solve", lambda *a, **k: answer)
    monkeypatch.setattr(runner, "_wrong_ids", lambda *a: 0)  # the answer is another frame's
    wrong = solve_frame(config, b, 1)  # any answer to a random frame is wrong
    assert wrong.outcome == "wrong"
    assert wrong.false_match_probability == answer.solution.false_match_probability

    def unmirrored(*args, **kwargs):  # the mirrored truth's twin of parity +1
        result = real(*args, **kwargs)
        s = result.solution
        twin = replace(s, R_cam_from_icrs=MIRROR @ s.R_cam_from_icrs, parity=1)
        return replace(result, solution=twin)

    monkeypatch.setattr(solver, "solve", unmirrored)
    assert solve_frame(config, b, 2).outcome == "wrong"


def _stars_of(config, b, index):
    from starnav.starlist import check_star_list

    camera = runner.config_solver(config).camera
    frame, _ = runner.config_frame(config, b, index)
    w, h = camera.width, camera.height
    return (check_star_list(frame.xy, width=w, height=h, brightness=frame.brightness),)


def test_cli_evaluate_kinds_json_breakdown_and_csv(tmp_path, capsys):
    csv_path = tmp_path / "frames.csv"
    args = ["evaluate", "--kind", "random,true", "--frames", "40", "--sampling", "uniform"]
    args += ["--workers", "1", "--seed", "3", "--frames-csv", str(csv_path)]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["config"]["kinds"] == ["random", "true"]
    assert list(out["by_kind"]) == ["true", "random"]
    random, true = out["by_kind"]["random"], out["by_kind"]["true"]
    assert random["frames"] == true["frames"] == 20
    assert random["correct"] == 0 and random["wrong"] == 0 and random["none"] == 20
    assert true["correct"] >= 18 and true["wrong"] == 0
    stars = out["by_true_stars"]
    assert list(stars) == ["true"]
    assert sum(c["frames"] for c in stars["true"].values()) == 20
    assert set(stars["true"]) <= {"0-2", "3", "4", "5", "6", ">=7"}
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r["kind"] for r in rows[:4]] == ["random", "true", "random", "true"]
    solved = [float(r["false_match_probability"]) for r in rows if r["outcome"] == "correct"]
    assert len(solved) == true["correct"] and all(0.0 <= p < 1e-4 for p in solved)
    assert all(r["false_match_probability"] == "nan" for r in rows if r["outcome"] == "none")
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "| random | 20 | 0 | 0 | 20 |" in text and "| true, " in text


ADVERSARIAL = ("random", "scrambled", "mirrored", "fov-off", "crowded", "few")


def test_a_few_star_fit_told_its_sigma_does_not_claim_more_precision():
    """The one answer of the first million adversarial frames scored wrong (seed 1011, frame
    1505: 5 nearly collinear stars, ids right, roll 0.53° off): its residuals (rms 0.34 px
    per axis for a 0.5 px noise) put the fit's a-posteriori sigma low, and the roll error
    was 5.9 of the 1-sigmas it reported. Told the sigma, the solver reports the covariance
    at least at it: 4.0 sigma. Re-noised copies of the frame: roll errors over the reported
    sigma rms 0.92, 0.25 % beyond 2.5 (a normal's tails: 1.2 %); with the a-posteriori
    variance of 2 x 5 - 3 degrees of freedom they had Student's tails: rms 1.10, 2.3 %.
    With its brightness the frame is refused now (its image holds brighter stars than any
    point: the few-star kind dropped them); the fit is checked on its positions alone."""
    config = EvalConfig(seed=1011, kinds=ADVERSARIAL)
    boresights = uniform_boresights(50_000, seed=1011)  # the million's chunk of 50 000
    r = solve_frame(config, boresights, 1505)
    assert r.outcome == "none" and "brighter than any it matched" in r.reason
    frame, _ = runner.config_frame(config, boresights, 1505)
    solver = runner.config_solver(config)
    s = solver.solve(check_star_list(frame.xy, width=512, height=512)).solution
    ids = s.star_table.catalog_id
    assert np.sum(ids != -1) == 5 and set(ids[ids != -1]) <= set(frame.true_id)
    roll = attitude_difference_deg(s.R_cam_from_icrs, frame.R_cam_from_icrs)[1]
    assert roll > 0.5  # beyond the tolerance, within 5 sigma
    real = frame.true_id != FALSE_STAR_ID
    rows = [np.flatnonzero(solver.catalog.ids == i)[0] for i in frame.true_id[real]]
    truth_xy = frame.camera.bearings_to_pixels(
        solver.catalog.vectors[rows] @ frame.R_cam_from_icrs.T
    )
    rng = np.random.default_rng(5)
    z = []
    for _ in range(400):
        xy = frame.xy.copy()
        xy[real] = truth_xy + rng.normal(0.0, config.noise_px, truth_xy.shape)
        s = solver.solve(check_star_list(xy, width=512, height=512))
        if s.solution is None:
            continue
        roll = attitude_difference_deg(s.solution.R_cam_from_icrs, frame.R_cam_from_icrs)[1]
        z.append(roll * 3600.0 / s.solution.sigma_roll_arcsec)
    z = np.array(z)
    assert len(z) > 300
    assert 0.8 < np.sqrt(np.mean(z**2)) < 1.05
    assert np.mean(z > 2.5) < 0.0124  # a normal's two tails


def test_two_equally_good_sets_of_matches_are_refused_not_guessed():
    """The one wrong answer of the final million adversarial frames (seed 6016, frame 20435,
    a few-star frame: 5 true stars, 4 of them in one corner, 2 false stars): a false star far
    out matched a catalog star (p 1.3e-5) and bent the roll 0.52° so that a true star fell
    outside the match radius. The wide search from that fit finds the true star; refitted,
    the false star drops out: as many stars, as well fitted, a different set. The answer is
    then not sure, and says so."""
    config = EvalConfig(seed=6016, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=6016), 20435)
    assert r.outcome == "none" and "two sets of matches" in r.reason


@pytest.mark.parametrize("seed, index", [(7000, 23823), (7019, 10407), (7019, 15135)])
def test_one_far_star_does_not_hold_a_wrong_focal_length(seed, index):
    """Three wrong answers of the third million adversarial frames (fov-off: the focal length
    told 2-5 % off): a cluster (the Hyades, the Pleiades) fits the wrong scale by itself and
    one star across the field, matched to a wrong neighbour where that scale puts one, held
    the joint fit at the focal length told (seed 7000 #23823: 0.5 %, 2.3 sigma). Without that
    one star the others say the focal length is off: refused, naming the one they fit."""
    config = EvalConfig(seed=seed, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=seed), index)
    assert r.kind == "fov-off" and r.outcome == "none"
    assert "the stars fit a focal length of" in r.reason


def test_a_larger_set_that_gives_a_point_another_star_contests_the_answer():
    """A wrong answer of the fourth million (seed 8005 #30896, mirrored): a false star 2 px
    from a true one took its star and bent a five-star fit (0.65° in roll) so that four true
    stars fell outside the radius. The wide search found all nine, the true star on its own
    point, but the four stars they share fit the bent answer better (1.03 against 0.45 px rms,
    a five-star fit follows its noise), so the larger set was not taken; it gives one of the
    answer's stars another point, so the answer is refused as not sure."""
    config = EvalConfig(seed=8005, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=8005), 30896)
    assert r.kind == "mirrored" and r.outcome == "none"
    assert "two sets of matches" in r.reason


def test_a_far_star_between_the_stars_of_a_double_is_contested():
    """The third million's few-star wrong answer (seed 7016 #9209): four stars in one corner
    and one far point between HIP 100027 and HIP 100064 (4.4 px apart, the brighter one
    missing from the frame). The point fixes the roll by itself, so the fit bends to
    whichever it is given: it took the wrong one and the roll was 0.5° off. Judged from the
    other four, the other star fits as well and would move the attitude beyond its error
    bars: refused as not sure."""
    config = EvalConfig(seed=7016, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=7016), 9209)
    assert r.kind == "few" and r.outcome == "none"
    assert "two sets of matches" in r.reason


def test_an_answer_whose_image_holds_more_unseen_bright_stars_than_matches_is_refused():
    """The sixth million's one wrong answer (seed 10009, frame 37207, scrambled: no star
    where it belongs): 5 of its 9 points, all of Hp 4.8-5.8, matched stars of Hp 5.0-6.0 with
    magnitudes that agree (claim 8.6e-5), in a field whose brighter stars (Hp 2.1-4.9) none of
    the points are. Now refused for them."""
    config = EvalConfig(seed=10009, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=10009), 37207)
    assert r.kind == "scrambled" and r.n_true == 0
    assert r.outcome == "none" and "brighter than any it matched" in r.reason


def test_residuals_the_told_centroid_sigma_cannot_explain_are_refused():
    """Told half the true centroid sigma (0.25 px for 0.5), most true frames' residuals are
    beyond its chi-square limit: refused, the message naming the sigma, never answered wrong;
    told the true one, none is. (The seventh million's wrong answer this rule was made for, a
    cluster holding a focal length 3.7 % off, is now refused by the scale test first.)"""
    boresights = uniform_boresights(20, seed=3)
    told_small = [solve_frame(EvalConfig(seed=3, sigma_px=0.25), boresights, i) for i in range(20)]
    told_right = [solve_frame(EvalConfig(seed=3), boresights, i) for i in range(20)]
    misfit = "worse than their centroid sigma allows"
    refused = [r for r in told_small if misfit in r.reason]
    assert len(refused) >= 8 and "sigma 0.25 px" in refused[0].reason
    assert all(r.outcome != "wrong" for r in told_small)
    assert not any(misfit in r.reason for r in told_right)


@pytest.mark.parametrize("seed, index", [(20005, 33603), (30011, 6027), (40010, 34263)])
def test_the_scale_is_tested_on_the_stars_a_free_focal_length_finds(seed, index):
    """The fov-off wrong answers of the seventh, eighth and ninth millions (the focal length
    told 3.7 %, 2.2 % and 2.3 % off): the Pleiades fit the told scale by themselves, one or two
    stars across the field held the joint fit there (the eighth's scale test on its pairs: 4.7
    sigma, under the 5), and the field's other true stars, 4-7 px from where the told scale
    puts them, stayed unmatched. A fit with the focal length free, from that answer, matches
    them: on those pairs the scale is plainly off, and the refusal names the focal length they
    fit, the true one to 0.1 %."""
    config = EvalConfig(seed=seed, kinds=ADVERSARIAL)
    r = solve_frame(config, uniform_boresights(50_000, seed=seed), index)
    assert r.kind == "fov-off" and r.outcome == "none"
    fitted_px = float(re.search(r"focal length of ([0-9.]+) px", r.reason).group(1))
    true_px = config.make_camera().focal_px * r.focal_factor
    assert abs(fitted_px / true_px - 1.0) < 1e-3


def test_the_misfit_limit_is_the_chi_square_quantile():
    """The misfit rule's chi-square limit (Wilson-Hilferty) against scipy's exact quantile at
    MISFIT_ALPHA: within 4 % from 3 degrees of freedom on, and never below it (the rule errs
    towards answering)."""
    from scipy.stats import chi2

    from starnav.pipeline import kernels

    for dof in (1, 2, 3, 5, 10, 19, 40, 100, 400):
        exact = chi2.isf(1e-4, dof)
        limit = kernels.misfit_limit(dof)
        assert limit >= exact
        if dof >= 3:
            assert limit <= 1.04 * exact
