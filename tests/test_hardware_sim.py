"""Simulated hardware end to end: HardwareHand -> SDK -> pty -> emulator -> SimPlant -> SimHand.

The sim-coupled plant must reproduce tendon changes exactly, make the backend wait for the
simulated settling, and serve rendered frames in which the object's tag is seen.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("vlr.sim.backend")
pytest.importorskip("dynamixel_sdk", reason="the real hand's tests need the hardware extra "
                    "(pip install -e '.[hardware]')")

from vlr.hardware.backend import open_hand  # noqa: E402
from vlr.hardware.control_table import Reg  # noqa: E402

from tests.hardware_fixtures import (  # noqa: E402
    hand_on_sim_plant,
    make_config,
    sim_config_dict,
    write_config,
)

PER_METRE = 4096 / (2 * math.pi * 0.01)


def test_sim_plant_follows_the_motors_and_renders_the_tag(tmp_path):
    cfg = make_config(tmp_path, **sim_config_dict())
    with hand_on_sim_plant(cfg) as (hand, emulator, plant):
        assert hand.grasp().grasp_held  # the tag is seen in the rendered frame
        sim_u0 = plant._call(lambda sim: sim.commands)
        hw_u0 = hand.commands
        report = hand.apply(np.array([0.001, -0.0005, 0.0005]))
        assert report.settled and report.grasp_held
        sim_u1 = plant._call(lambda sim: sim.commands)
        # The sim saw the same tendon changes, to a tick of the spool.
        np.testing.assert_allclose(sim_u1 - sim_u0, report.commands - hw_u0,
                                   atol=1.5 / PER_METRE)
        # Present currents come from the sim's tensions (tens of N on a 10 mm spool).
        state = hand.bus.sync_read_one(Reg.PRESENT_CURRENT, hand.finger_ids)
        assert all(abs(v) > 10 for v in state.values())
        frame = hand.grab_frame()
        assert frame.image.shape == (plant.calibration.height, plant.calibration.width, 3)
    assert not any(emulator.torque().values())


def test_open_hand_runs_on_simulated_hardware(tmp_path):
    path = write_config(tmp_path, sim_config_dict())
    with open_hand(config=str(path), object="ignored", seed=1) as hand:
        assert hand.grasp().grasp_held
        assert hand.apply(np.array([0.0005, 0.0005, 0.0005])).grasp_held
    assert not hand.bus.connected
