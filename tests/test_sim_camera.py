"""The palm camera on rendered frames: accuracy against ground truth, and 'no observation'."""

import mujoco
import numpy as np
import pytest
from vlr.sim.backend import SimHand
from vlr.sim.camera_check import camera_trial

from vlr.perception import observe

OBJECTS = ["apple", "wine_glass", "toy_block", "flat_screwdriver", "gelatin_box"]


@pytest.mark.parametrize("obj", OBJECTS)
def test_detections_match_ground_truth_over_50_actions(obj):
    r = camera_trial(obj, actions=50, seed=0)
    assert r.frames == 51
    assert r.detection_rate >= 0.99
    assert np.median(r.position_mm) < 0.1
    assert np.median(r.orientation_deg) < 0.5


def test_calibration_matches_the_rendered_camera():
    with SimHand("apple") as hand:
        cal = hand.calibration
        assert (cal.width, cal.height) == (640, 480)
        # The camera looks up the palm's +z: OpenCV's optical axis (+z_cam) is palm +z.
        np.testing.assert_allclose(cal.T_palm_cam[:3, 2], [0, 0, 1], atol=1e-12)


def _move_object(hand: SimHand, dx: float) -> None:
    adr = hand.model.joint("object/object_free/").qposadr[0]
    hand.data.qpos[adr] += dx
    mujoco.mj_forward(hand.model, hand.data)


@pytest.mark.parametrize("dx, what", [(0.5, "no tag in view"), (0.047, "half out of view")])
def test_tag_missing_or_partly_visible_is_no_observation(dx, what):
    with SimHand("apple") as hand:
        hand.grasp()
        spec = hand.object_spec
        assert observe(hand.grab_frame().image, hand.calibration, spec.tag_id,
                       spec.tag_size) is not None
        _move_object(hand, dx)
        image = hand.grab_frame().image
        assert observe(image, hand.calibration, spec.tag_id, spec.tag_size) is None, what


def test_blacked_out_frame_is_no_observation():
    with SimHand("apple") as hand:
        hand.grasp()
        image = np.zeros_like(hand.grab_frame().image)
        spec = hand.object_spec
        assert observe(image, hand.calibration, spec.tag_id, spec.tag_size) is None


def test_lower_resolution_calibration_matches_its_frames():
    from vlr.sim.backend import SimOptions

    with SimHand("apple", options=SimOptions(width=320, height=240)) as hand:
        hand.grasp()
        frame = hand.grab_frame()
        assert frame.image.shape[:2] == (240, 320)
        assert (hand.calibration.width, hand.calibration.height) == (320, 240)
        spec = hand.object_spec
        assert observe(frame.image, hand.calibration, spec.tag_id, spec.tag_size) is not None


def test_a_hand_left_open_exits_without_egl_errors():
    """A script that renders and never closes its hand exits quietly: its renderers are freed
    before EGL is torn down, not by the garbage collector after it."""
    import os
    import subprocess
    import sys

    script = ("from vlr.sim.backend import SimHand\nfrom vlr.sim.camera import render_scene\n"
              "h = SimHand(object='apple', seed=0)\nh.grab_frame()\nrender_scene(h)\n")
    env = dict(os.environ, MUJOCO_GL="egl")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "EGL" not in r.stderr and "Exception ignored" not in r.stderr, r.stderr
