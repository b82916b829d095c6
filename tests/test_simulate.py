import numpy as np
import pytest

from conftest import reference_frames
from starnav.camera import Camera
from starnav.errors import StarnavError
from starnav.simulate import FALSE_STAR_ID, project_catalog, simulate_frame


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
