"""The MuJoCo backend: grasps that hold, ground truth on the pads, determinism, bad input."""

import numpy as np
import pytest
from vlr.sim.backend import SimHand, SimOptions

from vlr.explore import ExplorationRange, random_action
from vlr.hand import CommandError, Hand
from vlr.spec import SpecError

OBJECTS = ["apple", "wine_glass", "toy_block", "flat_screwdriver", "gelatin_box"]


def _explore(hand: SimHand, n: int, seed: int) -> list:
    rng = np.random.default_rng(seed)
    explore = ExplorationRange.for_stiffness(hand.spec.tendon_stiffness)
    center = hand.commands
    reports = []
    for _ in range(n):
        reports.append(hand.apply(random_action(rng, hand.commands, center, explore)))
    return reports


def test_simhand_is_a_hand():
    with SimHand("apple") as hand:
        assert isinstance(hand, Hand)


@pytest.mark.parametrize("obj", OBJECTS)
def test_grasp_survives_50_exploratory_actions(obj):
    with SimHand(obj, seed=0) as hand:
        hand.grasp()
        rng = np.random.default_rng(0)
        explore = ExplorationRange.for_stiffness(hand.spec.tendon_stiffness)
        center = hand.commands
        tensions = [hand.static_tensions()]
        for k in range(50):
            r = hand.apply(random_action(rng, hand.commands, center, explore))
            assert r.grasp_held, f"action {k}: {r.message}"
            tensions.append(hand.static_tensions())
        # The default range is sized to change tensions by a few newtons per action.
        steps = np.abs(np.diff(np.array(tensions), axis=0))
        assert 1.0 < np.median(steps) < 10.0


@pytest.mark.parametrize("obj", ["apple", "gelatin_box"])
def test_ground_truth_contacts_lie_on_the_pads(obj):
    with SimHand(obj) as hand:
        hand.grasp()
        _explore(hand, 5, seed=1)
        t = hand.truth()
        for slot, f in t.fingers.items():
            finger = hand.true_spec.mount(slot).finger
            r = np.linalg.norm(f.contact_distal - np.asarray(finger.pad_center))
            assert f.contact_region == "pad"
            # On the sphere, up to the contact's penetration (stiff solref: < 1 mm).
            assert abs(r - finger.pad_radius) < 1e-3, (slot, r)
            assert f.contact_force > 0.1
            # The virtual distal link runs from the distal joint to the contact (METHOD 2).
            assert f.virtual_distal_length == pytest.approx(
                np.hypot(f.contact_distal[1], f.contact_distal[2]))
        assert t.pom_position[2] > 0.03
        np.testing.assert_allclose(t.pom_rotation @ t.pom_rotation.T, np.eye(3), atol=1e-9)


def test_same_seed_same_trajectory():
    runs = []
    for _ in range(2):
        with SimHand("toy_block", seed=3) as hand:
            hand.grasp()
            _explore(hand, 5, seed=3)
            runs.append(hand.data.qpos.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_unknown_names_and_bad_specs_are_clear_errors(tmp_path):
    with pytest.raises(SpecError, match="unknown object 'banana'"):
        SimHand("banana")
    with pytest.raises(SpecError, match="unknown hand 'modelx'"):
        SimHand("apple", hand="modelx")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nshape: sphere\nsize: [0.03]\nmass: -1\ncom: [0,0,0]\n"
                   "tag_id: 1\ntag_size: 0.03\ngrasp_height: 0.06\n")
    with pytest.raises(SpecError, match="mass -1"):
        SimHand(str(bad))
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [unclosed\n")
    with pytest.raises(SpecError, match="not valid YAML"):
        SimHand(str(broken))
    finger = tmp_path / "finger.yaml"
    finger.write_text((__import__("models").ROOT / "fingers" / "modelo.yaml").read_text()
                      .replace("../assets/fingers/modelo_proximal.stl", "missing.stl"))
    from vlr.spec import load_finger

    with pytest.raises(SpecError, match="mesh file .*missing.stl does not exist"):
        load_finger(finger)


def test_bad_tendon_commands_are_refused_without_moving():
    with SimHand("apple") as hand:
        hand.grasp()
        before = hand.data.qpos.copy()
        for bad, pattern in [([np.nan, 0, 0], "not finite"), ([0.01, 0, 0], "exceeds"),
                             ([0, 0], "shape"), ([np.inf, 0, 0], "not finite")]:
            with pytest.raises(CommandError, match=pattern):
                hand.apply(np.array(bad))
        np.testing.assert_array_equal(before, hand.data.qpos)


def test_unknown_override_is_refused():
    with pytest.raises(SpecError, match="override"):
        SimHand("apple", options=SimOptions(overrides={"thumb.middle.stiffness": 0.1}))


@pytest.mark.parametrize("kwargs, match", [
    (dict(width=0), "width = 0"), (dict(height=480.5), "height = 480.5"),
    (dict(fovy_deg=180.0), "fovy_deg = 180.0"),
])
def test_bad_sizes_are_refused(kwargs, match):
    with pytest.raises(SpecError, match=match):
        SimOptions(**kwargs)


def test_bad_values_in_spec_files_are_named(tmp_path):
    from vlr.spec import load_hand, load_object

    obj = tmp_path / "obj.yaml"
    obj.write_text("shape: sphere\nsize: [0.03]\nmass: 0.05\ncom: [0, 0, 0.03]\ntag_id: 3\n"
                   "tag_size: 0.02\ngrasp_height: 0.08\nfriction: high\n")
    with pytest.raises(SpecError, match="friction = 'high' must be a number"):
        load_object(obj)
    obj.write_text(obj.read_text().replace("friction: high", "extras: [1]"))
    with pytest.raises(SpecError, match=r"extras = \[1\] must be a mapping"):
        load_object(obj)
    hand = tmp_path / "hand.yaml"
    hand.write_text("tendon_stiffness: 20000\nspread: wide\n"
                    "slots: [{slot: a, position: [0, 0, 0], yaw: 0, finger: modelo}]\n")
    with pytest.raises(SpecError, match="spread = 'wide' must be a number"):
        load_hand(hand)
