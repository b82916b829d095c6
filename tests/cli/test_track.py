"""``starnav track`` as flight software runs it: a separate process fed JSON lines on a pipe or a
loopback socket, answering each line as it comes, stopped by end of input or a signal (the
stream's logic in one process, quickly: tests/pipeline/test_track.py)."""

from __future__ import annotations

import io
import json
import signal
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cli_helpers import run_cli
from starnav import Camera, load_catalog, simulate_frame
from starnav.cli.track import Signals, Stop, answer_stream
from starnav.geometry import attitude_difference_deg, attitude_from_radec_roll
from starnav.pipeline.options import SolveOptions
from starnav.pipeline.track import Tracker

CAMERA = ["--fov-deg", "12", "--width", "512"]
TRACK = [sys.executable, "-m", "starnav", "track", *CAMERA]
STEP_DEG = 0.05  # the slew per frame (0.5°/s at 10 Hz)


@pytest.fixture(scope="module")
def sequence():
    """Eight frames 0.1 s apart of a slow slew through Orion (0.1 px noise, one false star
    each), with their true attitudes: (JSON lines, true R_cam_from_icrs per line)."""
    catalog = load_catalog(None, mag_limit=6.0)
    camera = Camera.from_fov(12.0, 512)
    R = attitude_from_radec_roll(83.8, -5.4, 30.0)
    step = Rotation.from_rotvec(np.radians(STEP_DEG) * np.array([0.96, 0.2, 0.2])).as_matrix()
    rng = np.random.default_rng(7)
    lines, truth = [], []
    for k in range(8):
        f = simulate_frame(
            catalog, camera, R_cam_from_icrs=R, noise_px=0.1, false_stars=1, seed=rng
        )
        frame = {
            "xy": f.xy.round(3).tolist(),
            "mag": f.mag.round(2).tolist(),
            "t": 0.1 * k,
            "id": f"f{k}",
            "true_id": f.true_id.tolist(),
        }
        lines.append(json.dumps(frame))
        truth.append(R)
        R = step @ R
    return lines, truth


def _check_attitude(answer: dict, R_true: np.ndarray) -> None:
    """The answer's quaternion is its RA/Dec/roll and is the truth to 10″ (boresight)."""
    R = Rotation.from_quat(answer["q_cam_from_icrs_xyzw"]).as_matrix()
    radec = attitude_from_radec_roll(answer["ra_deg"], answer["dec_deg"], answer["roll_deg"])
    assert np.allclose(R, radec, atol=1e-9)
    boresight_deg, roll_deg = attitude_difference_deg(R, R_true)
    assert boresight_deg < 10 / 3600 and roll_deg < 0.05
    cov = np.array(answer["cov_cam_rad2"])
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
    # the 1-sigma of the boresight is the covariance's x and y rotations together
    sigma = np.sqrt(cov[0, 0] + cov[1, 1]) * 180 / np.pi * 3600
    assert sigma == pytest.approx(answer["sigma_boresight_arcsec"], rel=1e-9)


@pytest.mark.slow  # a process of its own: ~1.5 s to be ready, 2-3 s in all
def test_a_piped_sequence_tracks_after_the_first_frame_and_survives_a_bad_line(sequence):
    lines, truth = sequence
    late = json.loads(lines[7])
    late.update(t=60.0, id="late")  # a minute after the last solved frame: lost in space again
    stream = [
        *lines[:4],
        "this is no JSON {",
        "",
        '{"x": [1, 2], "y": [3, 4]}',
        *lines[4:7],
        json.dumps(late),
    ]
    done = subprocess.run(
        TRACK, input="\n".join(stream) + "\n", capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr
    answers = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(answers) == 10  # one per line, the blank one skipped
    assert [a["frame"] for a in answers] == list(range(10))
    assert [a["mode"] for a in answers] == [
        "lost_in_space",
        *["tracked"] * 3,
        None,
        None,
        *["tracked"] * 3,
        "lost_in_space",
    ]
    garbage, too_few = answers[4], answers[5]
    assert "not JSON" in garbage["error"] and garbage["solved"] is False
    assert "at least 3 stars" in too_few["error"]
    assert answers[6]["prior_frame"] == 3  # tracked on across the bad lines
    assert answers[0]["prior_frame"] is None and answers[9]["prior_frame"] is None
    solved = [a for a in answers if a["solved"]]
    assert [a["id"] for a in solved] == [*(f"f{k}" for k in range(7)), "late"]
    for a, R_true in zip(solved, [*truth[:7], truth[7]], strict=True):
        _check_attitude(a, R_true)
        assert a["error"] is None and a["reason"] is None and 0 < a["time_ms"] < 5000
    true_ids = json.loads(lines[0])["true_id"]
    given = answers[0]["ids"]
    assert len(given) == len(true_ids)
    assert all(g is None or g == t for g, t in zip(given, true_ids, strict=True))
    assert sum(g is not None for g in given) >= len(given) - 2


class Track:
    """A ``starnav track`` process (stdout and stdin piped) whose stderr lines a thread
    collects: ``ready()`` waits for its ready or listening line, the lines before it (a
    notice that the machine code is being compiled, after a change to a kernel) skipped."""

    def __init__(self, *extra: str) -> None:
        self.proc = subprocess.Popen(
            [*TRACK, *extra],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._collect, daemon=True)
        self._reader.start()

    def _collect(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line)
            if "ready" in line or "listening on" in line:
                self._ready.set()

    def ready(self) -> str:
        assert self._ready.wait(timeout=300), f"no ready line: {self.lines}"
        return self.lines[-1]

    def stop(self, signum: int) -> tuple[int, str]:
        """Exit status and all of stderr after ``signum``."""
        self.proc.send_signal(signum)
        code = self.proc.wait(timeout=10)
        self._reader.join(timeout=10)
        return code, "".join(self.lines)

    def __enter__(self) -> Track:
        return self

    def __exit__(self, *_exc) -> None:
        self.proc.kill()
        self.proc.wait()


def test_sigterm_while_waiting_for_frames_stops_cleanly(sequence):
    lines, truth = sequence
    with Track() as track:
        assert "ready" in track.ready()
        track.proc.stdin.write(lines[0] + "\n")
        track.proc.stdin.flush()  # the answer comes without closing the input: flushed per line
        answer = json.loads(track.proc.stdout.readline())
        _check_attitude(answer, truth[0])
        code, err = track.stop(signal.SIGTERM)  # stdin still open: it is waiting for a line
        assert code == 0 and track.proc.stdout.read() == "" and "Traceback" not in err


@pytest.mark.slow  # a process of its own: ~1.5 s to be ready, 2-3 s in all
def test_the_socket_answers_each_client_and_stops_on_sigint(sequence):
    lines, truth = sequence
    with Track("--listen", "127.0.0.1:0", "--json") as track:
        assert "listening on 127.0.0.1:" in track.ready()
        host, port = json.loads(track.proc.stdout.readline())["listen"].rsplit(":", 1)
        for _client in range(2):  # each connection is a stream of its own
            with socket.create_connection((host, int(port)), timeout=30) as conn:
                replies = conn.makefile("r")
                modes = []
                for line in [lines[0], "[1, 2, 3]", lines[1]]:
                    conn.sendall((line + "\n").encode())
                    answer = json.loads(replies.readline())
                    modes.append(answer["mode"])
                _check_attitude(answer, truth[1])
                assert answer["frame"] == 2 and modes == ["lost_in_space", None, "tracked"]
        code, err = track.stop(signal.SIGINT)
        assert code == 0 and "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--width", "512"], "needs the camera"),
        ([*CAMERA, "--listen", "192.0.2.1:9000"], "not a loopback address"),
        ([*CAMERA, "--listen", "9000"], "HOST:PORT"),
        ([*CAMERA, "--max-gap-s", "-1"], "--max-gap-s"),
    ],
)
def test_bad_options_exit_2_with_one_line(capsys, argv, needle):
    code, out, err = run_cli(capsys, "track", *argv)
    assert code == 2 and out == "" and needle in err and len(err.strip().splitlines()) == 1


def test_a_port_in_use_is_one_line(capsys):
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        code, _, err = run_cli(capsys, "track", *CAMERA, "--listen", f"127.0.0.1:{port}")
    assert code == 2 and "cannot listen on 127.0.0.1" in err


def test_the_command_in_this_process_answers_every_line(capsys, monkeypatch, sequence):
    """The quick tier's run of the command: stdin to stdout, end of input ends it (exit 0)."""
    lines, truth = sequence
    data = "\n".join([lines[0], '{"xy": 3}', lines[1]]).encode()  # the last line unended
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    code, out, err = run_cli(capsys, "track", *CAMERA, "--json")
    answers = [json.loads(line) for line in out.splitlines()]
    assert code == 0 and "ready" in err
    assert [a["mode"] for a in answers] == ["lost_in_space", None, "tracked"]
    assert '"xy" must be a list of [x, y] pairs' in answers[1]["error"]
    _check_attitude(answers[2], truth[1])


def test_a_signal_during_a_frame_stops_the_stream_after_its_answer(sequence):
    tracker = Tracker.prepare(SolveOptions(fov_deg=12.0), width=512)
    signals, written = Signals(), []
    pending = [line.encode() + b"\n" for line in sequence[0][:3]]

    def write(text: str) -> None:
        written.append(text)
        signals.handle(signal.SIGTERM, None)  # as if it came while the frame was solved

    answer_stream(lambda: pending.pop(0), write, tracker, signals)
    assert len(written) == 1 and json.loads(written[0])["solved"] and len(pending) == 2
    with pytest.raises(Stop), signals.waiting():  # a stop noted before a wait ends it at once
        pass
