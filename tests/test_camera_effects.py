"""vlr.sim.camera_effects: reproducible degradations, and lens distortion a calibration undoes."""

from __future__ import annotations

import numpy as np
import pytest
from vlr.sim.camera_effects import CameraEffects, apply_effects, distorted_calibration

from tests.tag_images import ideal_calibration, pose_cam_object, render_tag, rotation_error_deg
from vlr.perception import lens, observe

TAG_ID, TAG_SIZE = 3, 0.030


@pytest.fixture(scope="module")
def scene():
    cal = ideal_calibration(640, 480, 60.0)
    T = pose_cam_object(0.05, 15.0, 40.0, 20.0, (0.004, -0.003))
    return cal, T, render_tag(cal, T, TAG_ID, TAG_SIZE)


def test_defaults_change_nothing(scene) -> None:
    cal, _, image = scene
    out = apply_effects(image, CameraEffects(), np.random.default_rng(0), cal)
    np.testing.assert_array_equal(out, image)
    assert out is not image


def test_same_seed_same_frames(scene) -> None:
    cal, _, image = scene
    fx = CameraEffects(noise_std=3.0, blur_sigma_px=0.7, exposure_gain=0.8, drop_rate=0.3)
    runs = []
    for _ in range(2):
        rng = np.random.default_rng(42)
        runs.append([apply_effects(image, fx, rng, cal) for _ in range(10)])
    for a, b in zip(*runs, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a, b)
    dropped = sum(a is None for a in runs[0])
    assert 0 < dropped < 10


def test_noise_gain_and_drops_have_their_size(scene) -> None:
    cal, _, _ = scene
    flat = np.full((480, 640), 100, np.uint8)
    rng = np.random.default_rng(1)
    out = apply_effects(flat, CameraEffects(noise_std=4.0, exposure_gain=1.5), rng, cal)
    assert abs(out.mean() - 150) < 0.1 and abs(out.std() - 4.0) < 0.1
    rgb = np.dstack([flat] * 3)
    assert apply_effects(rgb, CameraEffects(noise_std=1.0), rng, cal).shape == rgb.shape
    drops = [apply_effects(flat, CameraEffects(drop_rate=0.25), rng, cal) is None
             for _ in range(2000)]
    assert abs(np.mean(drops) - 0.25) < 0.03
    assert apply_effects(flat, CameraEffects(drop_rate=1.0), rng, cal) is None


def test_degraded_frames_still_give_accurate_poses(scene) -> None:
    cal, T, image = scene
    fx = CameraEffects(noise_std=3.0, blur_sigma_px=1.0, exposure_gain=0.7)
    rng = np.random.default_rng(3)
    for _ in range(3):
        obs = observe(apply_effects(image, fx, rng, cal), cal, TAG_ID, TAG_SIZE)
        assert obs is not None
        assert np.linalg.norm(obs.position - T[:3, 3]) < 2e-5
        assert rotation_error_deg(obs.rotation, T[:3, :3]) < 0.1


def test_distortion_is_undone_by_its_calibration(scene) -> None:
    cal, T, image = scene
    fx = CameraEffects(distortion=(-0.25, 0.08, 0.001, -0.0015, -0.01))
    distorted = apply_effects(image, fx, np.random.default_rng(0), cal)
    cal_d = distorted_calibration(cal, fx)
    np.testing.assert_array_equal(cal_d.dist, fx.distortion)
    obs = observe(distorted, cal_d, TAG_ID, TAG_SIZE)
    assert obs is not None and obs.refined
    assert np.linalg.norm(obs.position - T[:3, 3]) < 2e-5
    assert rotation_error_deg(obs.rotation, T[:3, :3]) < 0.05
    # the reported corners are where the tag's corners are in the DISTORTED image
    ideal = observe(image, cal, TAG_ID, TAG_SIZE)
    np.testing.assert_allclose(obs.corners, lens.to_image(ideal.corners, cal.K, cal_d.dist),
                               atol=0.05)
    # ignoring the distortion costs accuracy: the effect is real
    naive = observe(distorted, cal, TAG_ID, TAG_SIZE, max_reprojection_px=100.0)
    assert naive is None or np.linalg.norm(naive.position - T[:3, 3]) > 1e-4


@pytest.mark.parametrize("kwargs", [
    dict(noise_std=-1.0), dict(blur_sigma_px=float("nan")), dict(exposure_gain=0.0),
    dict(drop_rate=1.5), dict(distortion=(0.1, 0.2)),
])
def test_bad_effects_raise(kwargs) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        CameraEffects(**kwargs)
