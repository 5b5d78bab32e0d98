"""The validation set (models/README.md, "Validation set"): objects and fingers the
identification's defaults were not tuned on. Their grasps hold through a trial's actions."""

import re

import numpy as np
import pytest
from vlr.models.check_grasps import check_hold

VALIDATION_PAIRS = [("modelo", "tennis_ball"), ("modelo", "baseball"),
                    ("modelo", "cylinder_lying"), ("modelo", "cylinder_upright"),
                    ("modelo", "foam_brick"), ("modelo", "rubiks_cube"),
                    ("nh4", "apple"), ("nh5", "apple")]


@pytest.mark.parametrize("hand, obj", VALIDATION_PAIRS)
def test_validation_grasp_holds_and_shows_its_tag(hand, obj):
    # The full check (50 actions on seeds 0-4, `python -m vlr.models.check_grasps`) held on every
    # seed; CI makes the first 8 actions of seed 0.
    r = check_hold(hand, obj, [0], actions=8)
    assert r.ok, r.messages
    assert 0.1 < r.move_mm < 10.0   # the object moves with the actions, and stays held
    # NF4's long distal link touches the apple beside its pad (seeds 0-4, 50 actions: 149
    # and 104 of 750 finger-states off the pads); every other pair touches with pads alone.
    assert r.finger_states == 3 * 8
    assert (r.off_pad > 0) == (hand in ("nh4", "nh5")), r.off_pad


def _identify(obj: str, **more) -> dict:
    from vlr.run import run_identification
    from vlr.settings import load_settings

    return run_identification(load_settings(
        {"world.backend": "sim", "world.object": obj, "filter.particles": 3000, "seed": 0,
         "loop.max_iterations": 12, **more})).summary


# One row per object kind and one new finger, reduced (3,000 particles, 12 actions, seed 0)
# from docs/sweeps/validation.yaml (60,000, 20 or 35, seeds 0-4; docs/RESULTS.md). Measured
# at these settings: proximal 0.20 / 0.60 / 0.61 / 1.23 deg, coverage 1.0 within 0.1 deg
# each. Thresholds sit above the measured figures; never loosen one to pass.
@pytest.mark.slow
@pytest.mark.parametrize("obj, max_proximal_deg", [
    ("tennis_ball", 1.0), ("cylinder_lying", 1.5), ("cylinder_upright", 1.5),
    ("foam_brick", 1.5)])
def test_validation_known_hand(obj, max_proximal_deg):
    r = _identify(obj)
    assert r["errors"]["proximal_deg_mean"] < max_proximal_deg
    assert r["coverage_tolerant"] >= 5 / 6


@pytest.mark.slow
def test_validation_nh4_unknown_links():
    # NH4's link after 20 actions is known to about its 12 mm interval's width, so one
    # seed's error is a draw: 0.9-10.4 mm over seeds 0-5 at 3,000 particles (10.4, 4.7,
    # 0.9, 9.7, 3.9, 1.8); at 60,000 and 35 actions 2.39 mm (docs/RESULTS.md). The guard
    # is the mean of six seeds: measured 5.22 mm.
    rows = [_identify("apple", **{"seed": seed, "world.true_hand": "nh4",
                                  "loop.max_iterations": 20,
                                  "filter.unknowns": ["length:right.proximal",
                                                      "length:right.distal"]})
            for seed in range(6)]
    assert np.mean([r["errors"]["link_length_mm"]["right"] for r in rows]) < 5.5
    assert np.mean([r["errors"]["proximal_deg_mean"] for r in rows]) < 2.0


@pytest.mark.parametrize("argv, named", [(["modelo:nosuch"], "nosuch"),
                                         (["modelo"], "HAND:OBJECT"),
                                         (["--actions", "0", "modelo:apple"], "--actions 0")])
def test_check_grasps_bad_input_is_one_line(argv, named, capsys):
    from vlr.models.check_grasps import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert named in err[-1] and "Traceback" not in "".join(err)


def test_check_grasps_prints_the_finger_states_off_the_pads(capsys):
    """The command's line for a grasp that touches a link (NH4's right finger on the apple)
    says how many finger-states did, and a pad-only grasp's line says nothing of it."""
    from vlr.models.check_grasps import main

    assert main(["--seeds", "0", "--actions", "3", "nh4:apple", "modelo:apple"]) == 0
    nh4, modelo = capsys.readouterr().out.strip().splitlines()
    assert re.search(r"off the pads in [1-9]\d* of 9 finger-states", nh4), nh4
    assert "off the pads" not in modelo
