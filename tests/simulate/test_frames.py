import numpy as np
import pytest

from shared_data import reference_frames
from starnav.camera import Camera
from starnav.errors import StarnavError
from starnav.simulate import (
    FALSE_STAR_ID,
    draw_radec_roll,
    project_catalog,
    simulate_frame,
    write_frame_csv,
)
from starnav.starlist import read_star_csv


@pytest.mark.parametrize(
    "name,noise", [("a_fov12_512_clean.jsonl", 0.1), ("c_fov20_1024.jsonl", 0.2)]
)
def test_projection_agrees_with_independent_generator(hip_1991, name, noise):
    """Our projection of the true attitude lands on the generator's centroids (within noise)."""
    for frame in reference_frames(name)[:20]:
        cam = Camera.from_fov(frame["fov_deg"], frame["width"], frame["height"])
        R = np.array(frame["truth"]["R_cam_from_icrs"])
        rows, xy = project_catalog(hip_1991, R, cam)
        ours = dict(zip(hip_1991.ids[rows].tolist(), xy, strict=True))
        theirs = np.array(frame["centroids"])[:, :2]
        hips = frame["truth"]["hip"]
        assert set(hips) <= set(ours)
        d = np.array([np.linalg.norm(ours[h] - p) for h, p in zip(hips, theirs, strict=True)])
        assert d.max() < 6 * noise
        assert abs(np.sqrt(np.mean(d**2)) / np.sqrt(2) - noise) < 0.5 * noise


def test_frame_errors_are_as_asked(hip_1991):
    cam = Camera.from_fov(12.0, 512)
    clean = simulate_frame(hip_1991, cam, ra_deg=80, dec_deg=-5, roll_deg=10, seed=1)
    noisy = simulate_frame(
        hip_1991,
        cam,
        ra_deg=80,
        dec_deg=-5,
        roll_deg=10,
        seed=1,
        noise_px=1.0,
        false_stars=3,
        missing_frac=0.3,
    )
    assert len(clean.xy) == clean.n_in_view and (clean.true_id > 0).all()
    assert np.all(np.diff(clean.mag) >= 0)  # brightest first
    assert np.sum(noisy.true_id == FALSE_STAR_ID) == 3
    assert np.sum(noisy.true_id > 0) == clean.n_in_view - round(0.3 * clean.n_in_view)
    truth = clean.truth
    assert np.allclose(truth[:3], (80, -5, 10)) and truth[3] == 1


def test_same_seed_same_frame(hip_1991):
    cam = Camera.from_fov(12.0, 512)
    a = simulate_frame(hip_1991, cam, seed=7, noise_px=0.5, false_stars=2)
    b = simulate_frame(hip_1991, cam, seed=7, noise_px=0.5, false_stars=2)
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.R_cam_from_icrs, b.R_cam_from_icrs)


@pytest.mark.parametrize(
    "kwargs", [dict(noise_px=-1), dict(missing_frac=1.0), dict(false_stars=-2), dict(parity=0)]
)
def test_bad_simulation_parameters(hip_1991, kwargs):
    with pytest.raises(StarnavError):
        simulate_frame(hip_1991, Camera.from_fov(12.0, 512), **kwargs)


def test_random_attitude_is_the_draw_of_draw_radec_roll(hip_1991):
    cam = Camera.from_fov(12.0, 512)
    frame = simulate_frame(hip_1991, cam, dec_deg=20.0, parity=-1, seed=5)
    ra, dec, roll = draw_radec_roll(np.random.default_rng(5), None, 20.0, None)
    assert frame.truth == pytest.approx((ra, dec, roll, -1))
    assert draw_radec_roll(np.random.default_rng(0), 1.0, 2.0, 3.0) == (1.0, 2.0, 3.0)


def test_truth_dict_comparison_and_csv(hip_1991, tmp_path):
    cam = Camera.from_fov(12.0, 512)
    frame = simulate_frame(
        hip_1991, cam, ra_deg=80, dec_deg=-5, roll_deg=10, false_stars=2, noise_px=0.2, seed=1
    )
    truth = frame.to_dict()
    assert truth["n_false"] == 2 and truth["n_points"] == len(frame.xy)
    assert truth["ra_deg"] == pytest.approx(80) and truth["parity"] == 1
    assert frame.compare(None) is None
    path = tmp_path / "frame.csv"
    write_frame_csv(path, frame)
    stars = read_star_csv(path)
    assert np.allclose(stars.xy, frame.xy, atol=1e-4) and stars.labels[0] == "1"
    lines = path.read_text().splitlines()
    assert lines[0] == "label,x,y,mag,true_catalog_id"
    assert sum(line.endswith(",") for line in lines[1:]) == 2  # false stars: no id
    with pytest.raises(StarnavError, match="cannot write"):
        write_frame_csv(tmp_path / "no" / "frame.csv", frame)
