"""The MJCF Model O: compiles, springs, underactuated closing, scenes step cleanly."""

import mujoco
import numpy as np
import pytest
from vlr.sim.model import build_hand, compile_scene, load_scene

from vlr import models
from vlr.spec import available_fingers, available_hands, available_objects, load_finger, load_hand

HANDS = ["modelo", "nh1", "nh2", "nh3"]


def test_model_folder_has_its_files():
    for name in ["README.md", "make_tags.py", "make_fingers.py", "__init__.py"]:
        assert (models.ROOT / name).is_file(), name
    assert set(HANDS) <= set(available_hands())
    assert {"modelo", "nf1", "nf2", "nf3"} <= set(available_fingers())
    assert {"apple", "wine_glass", "toy_block", "flat_screwdriver", "gelatin_box",
            "cup1", "cup2", "cup3", "cup4", "cup5"} <= set(available_objects())
    for f in available_fingers():
        spec = load_finger(f)
        for mesh in spec.visual_meshes:
            assert mesh is None or mesh.endswith(".stl")


@pytest.mark.parametrize("hand", HANDS)
def test_hands_compile_and_replace_fingers(hand):
    built = load_scene(hand, "apple")
    m = built.model
    assert m.nu == 3 and m.ntendon == 3
    spec = load_hand(hand)
    for mount in spec.mounts:
        jd = m.body(f"{mount.slot}/distal").pos
        # The distal joint sits one proximal length above the proximal joint.
        assert jd[2] == pytest.approx(mount.finger.proximal_length)


def _hand_only(hand="modelo"):
    spec = load_hand(hand)
    built = compile_scene(build_hand(spec))
    return spec, built.model, mujoco.MjData(built.model)


def _finger_q(m, d, slot):
    return np.array([d.qpos[m.joint(f"{slot}/proximal").qposadr[0]],
                     d.qpos[m.joint(f"{slot}/distal").qposadr[0]]])


def test_unloaded_springs_return_fingers_to_their_open_stops():
    spec, m, d = _hand_only()
    for mount in spec.mounts:  # start flexed
        d.qpos[m.joint(f"{mount.slot}/proximal").qposadr[0]] = 0.8
        d.qpos[m.joint(f"{mount.slot}/distal").qposadr[0]] = 0.6
    d.ctrl[:] = 1.0  # tendon targets far longer than the tendons: slack lines
    for _ in range(1500):
        mujoco.mj_step(m, d)
    for mount in spec.mounts:
        q = _finger_q(m, d, mount.slot)
        # The rest angle lies beyond the open stop: the spring holds the joint on the stop.
        np.testing.assert_allclose(q, mount.finger.open_angles, atol=0.01)


def test_tendon_closes_proximal_first_then_distal():
    spec, m, d = _hand_only()
    finger = spec.mounts[0].finger
    act = m.actuator("thumb_tendon_act").id
    l_open = -np.dot(finger.pulley_radii, finger.open_angles)
    for mount in spec.mounts:
        d.qpos[m.joint(f"{mount.slot}/proximal").qposadr[0]] = mount.finger.open_angles[0]
        d.qpos[m.joint(f"{mount.slot}/distal").qposadr[0]] = mount.finger.open_angles[1]
    d.ctrl[:] = 1.0
    trace = []
    for k in range(3000):  # pull the thumb tendon at 5 mm/s
        d.ctrl[act] = l_open - 5e-3 * k * m.opt.timestep
        mujoco.mj_step(m, d)
        trace.append(_finger_q(m, d, "thumb"))
    trace = np.array(trace) - finger.open_angles
    moved_p = np.argmax(trace[:, 0] > 0.05)
    moved_d = np.argmax(trace[:, 1] > 0.05)
    assert trace[:, 0].max() > 0.3 and moved_p < moved_d
    # While unloaded, the distal stays on its stop until the proximal has travelled far.
    assert trace[moved_d, 0] > 0.4


def test_distal_flexes_after_contact():
    from vlr.sim.backend import SimHand

    hand = SimHand("apple")
    hand.grasp()  # the object is held by a helper weld while the hand closes
    t = hand.truth()
    for slot, f in t.fingers.items():
        assert f.contact_region == "pad", slot
        assert f.angles[1] - hand.spec.mount(slot).finger.open_angles[1] > 0.05, slot
    hand.close()


@pytest.mark.parametrize("obj", ["apple", "cup3"])
def test_scene_steps_one_second_under_noisy_controls_without_warnings(obj):
    built = load_scene("modelo", obj)
    m = built.model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    for _ in range(1000):
        d.ctrl[:] = rng.uniform(-0.02, 0.0, m.nu)
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning)
    assert np.all(np.isfinite(d.qpos))
