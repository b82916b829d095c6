"""The frame stream's logic in one process: reading a frame, when it is tracked and when lost in
space, what an answer line holds (the ``starnav track`` process: tests/cli/test_track.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from starnav import Camera, load_catalog, simulate_frame, solve_stars
from starnav.errors import StarListError
from starnav.geometry import ARCSEC_PER_RAD, attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.track import (
    LOST_IN_SPACE,
    TRACK_KEYS,
    TRACKED,
    Tracker,
    parse_frame,
    quaternion_xyzw,
)

CAMERA = Camera.from_fov(12.0, 512)


@pytest.fixture(scope="module")
def catalog():
    return load_catalog(None, mag_limit=6.0)


def _frame(catalog, R, **keys) -> str:
    f = simulate_frame(catalog, CAMERA, R_cam_from_icrs=R, noise_px=0.1, seed=3)
    return json.dumps(
        {
            "x": f.xy[:, 0].tolist(),
            "y": f.xy[:, 1].tolist(),
            "brightness": f.brightness.tolist(),
            **keys,
        }
    )


class Clock:
    """A clock the test sets (s)."""

    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture(scope="module")
def tracker():
    t = Tracker.prepare(SolveOptions(fov_deg=12.0, sigma_px=0.1), width=512, max_gap_s=1.0)
    t.clock = Clock()
    return t


def test_frames_are_tracked_while_the_last_attitude_is_recent(catalog, tracker):
    tracker.reset()
    R0 = attitude_from_radec_roll(83.8, -5.4, 30.0)
    R1 = Rotation.from_rotvec(np.radians([0.05, 0.01, 0.01])).as_matrix() @ R0
    clock = tracker.clock
    first = tracker.answer(_frame(catalog, R0, id=5))  # no prior yet
    clock.now_s += 0.1
    bad = tracker.answer(b"\xff\xfe not text")  # changes nothing
    clock.now_s += 0.1
    second = tracker.answer(_frame(catalog, R1).encode())
    clock.now_s += 1.5  # longer than max_gap_s after the last solved frame
    third = tracker.answer(_frame(catalog, R1))
    timed = tracker.answer(_frame(catalog, R1, t=3.0))  # the frame's clock, not the receiver's
    again = tracker.answer(_frame(catalog, R0, t=3.9))
    backwards = tracker.answer(_frame(catalog, R0, t=2.0))  # time ran back: lost in space
    got = [
        (a.frame, a.mode, a.prior_frame)
        for a in (first, bad, second, third, timed, again, backwards)
    ]
    assert got == [
        (0, LOST_IN_SPACE, None),
        (1, None, None),
        (2, TRACKED, 0),
        (3, LOST_IN_SPACE, None),
        (4, LOST_IN_SPACE, None),
        (5, TRACKED, 4),
        (6, LOST_IN_SPACE, None),
    ]
    assert bad.error == "the line is not UTF-8 text" and bad.solution is None
    assert first.id == 5 and timed.t_s == 3.0 and again.to_dict()["t"] == 3.9
    for answer, R in ((first, R0), (second, R1), (timed, R1), (again, R0)):
        boresight_deg, roll_deg = attitude_difference_deg(answer.solution.R_cam_from_icrs, R)
        assert boresight_deg < 0.005 and roll_deg < 0.05
    tracker.reset()  # a new stream: numbered from 0, lost in space
    assert (tracker.answer(_frame(catalog, R0)).frame, tracker.frames) == (0, 1)


def test_a_fault_while_solving_is_the_frame_s_error_and_the_stream_goes_on(
    catalog, tracker, monkeypatch, caplog
):
    tracker.reset()
    line = _frame(catalog, attitude_from_radec_roll(83.8, -5.4, 30.0))
    assert tracker.answer(line).mode == LOST_IN_SPACE

    def fault(stars, prior):
        raise RuntimeError("a bug")

    monkeypatch.setattr(tracker, "_solve", fault)
    failed = tracker.answer(line)
    assert failed.error == "internal error (RuntimeError: a bug): please report it"
    assert "frame 1" in caplog.text and "RuntimeError" in caplog.text  # with its traceback
    monkeypatch.undo()
    after = tracker.answer(line)
    assert (after.frame, after.mode, after.prior_frame) == (2, LOST_IN_SPACE, None)


def test_an_answer_line(catalog, tracker):
    tracker.reset()
    R = attitude_from_radec_roll(200.0, 40.0, 123.0)
    line = tracker.answer(_frame(catalog, R, id="a")).to_dict()
    assert tuple(line) == TRACK_KEYS and line["solved"] and line["id"] == "a"
    q = np.array(line["q_cam_from_icrs_xyzw"])
    assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
    boresight_deg, roll_deg = attitude_difference_deg(Rotation.from_quat(q).as_matrix(), R)
    assert boresight_deg < 0.005 and roll_deg < 0.05
    cov = np.array(line["cov_cam_rad2"])
    assert np.sqrt(cov[2, 2]) * ARCSEC_PER_RAD == pytest.approx(line["sigma_roll_arcsec"])
    assert len(line["ids"]) == len(json.loads(_frame(catalog, R))["x"])
    unsolved = tracker.answer('{"x": [10, 200, 300], "y": [40, 50, 400]}').to_dict()
    assert tuple(unsolved) == TRACK_KEYS and not unsolved["solved"] and unsolved["reason"]
    assert unsolved["error"] is None and unsolved["ids"] is None and unsolved["mode"] is None


def test_the_covariance_is_the_one_the_sigmas_come_from(catalog):
    frame = simulate_frame(
        catalog, CAMERA, ra_deg=83.8, dec_deg=-5.4, roll_deg=30.0, noise_px=0.3, seed=2
    )
    for sigma_px in (None, 0.3, 2.0):  # a told sigma sets the least the covariance is at
        s = solve_stars(
            frame.xy,
            width=512,
            fov_deg=12.0,
            sigma_px=sigma_px,
            catalog=catalog,
            brightness=frame.brightness,
        ).solution
        cov = s.rotation_cov_rad2
        assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
        boresight = np.sqrt(cov[0, 0] + cov[1, 1]) * ARCSEC_PER_RAD
        assert boresight == pytest.approx(s.sigma_boresight_arcsec, rel=1e-9)
        assert np.sqrt(cov[2, 2]) * ARCSEC_PER_RAD == pytest.approx(s.sigma_roll_arcsec, rel=1e-9)
    assert "rotation_cov_rad2" not in s.to_dict()


def test_the_quaternion_turns_icrs_into_camera_coordinates():
    rng = np.random.default_rng(0)
    for R in Rotation.random(20, random_state=1).as_matrix():
        q = quaternion_xyzw(R)
        v = rng.normal(size=3)
        assert np.allclose(Rotation.from_quat(q).apply(v), R @ v) and q[3] >= 0
    mirrored = attitude_from_radec_roll(10.0, 20.0, 30.0, parity=-1)
    assert quaternion_xyzw(mirrored) is None


def test_a_frame_in_either_form():
    as_lists = parse_frame(
        '{"x": [1, 20.5, 300], "y": [4, 50, 60], "mag": [3, 1, 2], "t": 1.5, '
        '"id": "cam1-7", "true_ids": [1, 2, 3]}',
        width=512,
        height=512,
    )
    as_pairs = parse_frame(
        b'{"xy": [[1, 4], [20.5, 50], [300, 60]], "brightness": [1, 9, 4]}', width=512, height=512
    )
    assert np.array_equal(as_lists.stars.xy, as_pairs.stars.xy)
    assert list(as_lists.stars.order) == list(as_pairs.stars.order) == [1, 2, 0]
    assert (as_lists.t_s, as_lists.id, as_pairs.t_s, as_pairs.id) == (1.5, "cam1-7", None, None)


XY = '"x": [1, 20, 300], "y": [4, 50, 60]'


@pytest.mark.parametrize(
    ("line", "needle"),
    [
        ("{", "not JSON"),
        ("[1, 2]", "got a JSON list"),
        ('{"x": [1, 2, 3]}', "give the positions once"),
        (f'{{{XY}, "xy": [[1, 2]]}}', "give the positions once"),
        ('{"x": [1, 2, 3], "y": [4, 5]}', '"x" has 3 numbers, "y" 2'),
        ('{"x": [1, "2", 3], "y": [4, 5, 6]}', '"x" must be a list of numbers'),
        ('{"xy": [[1, 2], [3]]}', "[x, y] pairs"),
        ('{"x": [1, NaN, 3], "y": [4, 5, 6]}', "NaN"),
        ('{"x": [1, 2], "y": [4, 5]}', "at least 3 stars"),
        ('{"x": [1, 2, 3000], "y": [4, 5, 6]}', "far outside"),
        (f'{{{XY}, "mag": [1, 2, 3], "brightness": [1, 2, 3]}}', "not both"),
        (f'{{{XY}, "mag": [1, 2]}}', "2 brightness values for 3 stars"),
        (f'{{{XY}, "t": "noon"}}', '"t" must be a finite number'),
        (f'{{{XY}, "t": Infinity}}', '"t" must be a finite number'),
        (f'{{{XY}, "id": [1]}}', '"id" must be a string or a whole number'),
        (f'{{{XY}, "flux": [1, 2, 3]}}', "unknown key flux"),
        (f'{{{XY}, "t": 1{"0" * 400}}}', '"t" must be a finite number'),
        (f'{{"x": [1, 2, 1{"0" * 400}], "y": [4, 5, 6]}}', "within ±1.8e308"),
    ],
)
def test_a_bad_frame_is_one_line_naming_the_problem(line, needle):
    with pytest.raises(StarListError, match=None) as err:
        parse_frame(line, width=512, height=512)
    assert needle in str(err.value) and "\n" not in str(err.value)
