"""Shared set-up for the hardware tests: a fast config, an emulator for it, a hand on it.

Fast means: 1,000,000 baud on the pseudo-terminal, an 8 ms latency budget (a silent motor
costs ~18 ms per try, yet a busy shared machine does not time out a healthy one), short
ramps, motors at full speed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml
from vlr.hardware.camera import FakeCamera
from vlr.hardware.config import HardwareConfig, load_config
from vlr.hardware.emulate import build_emulator
from vlr.hardware.emulator import Emulator

from vlr.camera import CameraCalibration
from vlr.spec import ObjectSpec, load_hand, load_object

if TYPE_CHECKING:  # the hand needs the `hardware` extra; the configs do not
    from vlr.hardware.backend import HardwareHand

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_CAMERA = ROOT / "hardware" / "example_camera.yaml"

OBJECT = ObjectSpec(name="test_ball", shape="sphere", size=(0.03,), mass=0.05,
                    com=(0.0, 0.0, 0.03), tag_id=3, tag_size=0.02, grasp_height=0.08)

CALIBRATION = CameraCalibration(
    width=64, height=48, K=np.array([[40.0, 0.0, 31.5], [0.0, 40.0, 23.5], [0.0, 0.0, 1.0]]),
    dist=np.zeros(5), T_palm_cam=np.eye(4))


def config_dict(**overrides: Any) -> dict[str, Any]:
    """A valid, fast config as a mapping; `overrides` replace top-level sections."""
    data: dict[str, Any] = {
        "hand": "modelo",
        "object": "apple",
        "bus": {"port": "emulator", "baud": 1_000_000, "latency_ms": 16, "retries": 2},
        "fingers": {"thumb": {"id": 1, "direction": 1},
                    "left": {"id": 2, "direction": -1},
                    "right": {"id": 3, "direction": 1}},
        "spread": {"id": 4, "position": 2100},
        "motion": {"spool_radius": 0.01, "mode": "current_based_position",
                   "current_limit_ma": 600, "profile_velocity_rpm": 0, "max_step": 0.002,
                   "range": [0.0, 0.035], "ramp_steps": 3, "ramp_period": 0.002,
                   "settle_timeout": 1.0, "settle_ticks": 1},
        "calibration": {"current_ma": 120, "taut_current_ma": 40, "probe_step": 0.0003,
                        "backoff": 0.001, "max_travel": 0.01},
        "grasp": {"commands": [0.004, 0.003, 0.003], "check_tag": False},
        "camera": {"fake": "blank", "calibration": str(EXAMPLE_CAMERA)},
        "emulator": {"plant": "kinematic", "slack": 0.002},
    }
    data.update(overrides)
    return data


def write_config(tmp_path: Path, data: dict[str, Any], name: str = "hw.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def make_config(tmp_path: Path, **overrides: Any) -> HardwareConfig:
    return load_config(write_config(tmp_path, config_dict(**overrides)))


@contextlib.contextmanager
def hand_on_emulator(cfg: HardwareConfig, camera: FakeCamera | None = None
                     ) -> Iterator[tuple[HardwareHand, Emulator]]:
    """A started emulator for `cfg` and a hand on it (with `camera`, default a blank one);
    the emulator outlives the hand so that tests can inspect the torque registers after the
    hand closed."""
    from vlr.hardware.backend import HardwareHand

    emulator, _ = build_emulator(cfg)
    emulator.start()
    try:
        hand = HardwareHand(cfg, spec=load_hand(cfg.hand), object_spec=OBJECT,
                            calibration=CALIBRATION, camera=camera or FakeCamera(64, 48),
                            port=emulator.port, log=lambda message: None)
        try:
            yield hand, emulator
        finally:
            hand.close()
    finally:
        emulator.stop()


def sim_config_dict(**extra: Any) -> dict[str, Any]:
    """A config whose emulated motors drive the MuJoCo hand holding the apple (`SimPlant`),
    with the sim's rendered frames as the camera."""
    data = config_dict(
        object="apple",
        grasp={"commands": [0.003, 0.0027, 0.0027], "check_tag": True},
        camera={"fake": "sim"},
        emulator={"plant": "sim", "slack": 0.002},
        **extra)
    data.pop("spread")
    data["motion"]["settle_timeout"] = 3.0
    return data


@contextlib.contextmanager
def hand_on_sim_plant(cfg: HardwareConfig) -> Iterator[tuple[HardwareHand, Emulator, Any]]:
    """A hand on emulated motors that drive the simulated hand: (hand, emulator, plant). The
    hand is open inside the block; the emulator is stopped and the plant closed after it."""
    from vlr.hardware.backend import HardwareHand

    emulator, plant = build_emulator(cfg)
    emulator.start()
    try:
        hand = HardwareHand(cfg, spec=load_hand(cfg.hand), object_spec=load_object("apple"),
                            calibration=plant.calibration,
                            camera=FakeCamera(source=plant.render), port=emulator.port,
                            log=lambda m: None)
        with hand:
            yield hand, emulator, plant
    finally:
        emulator.stop()
        plant.close()
