"""The hardware backend (HardwareHand) through the real SDK against emulated motors.

Every test that runs the hand checks afterwards that torque is off on every motor.
"""

from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest

pytest.importorskip("dynamixel_sdk", reason="the real hand's tests need the hardware extra "
                    "(pip install -e '.[hardware]')")

from vlr.hardware.backend import HardwareHand, open_hand  # noqa: E402
from vlr.hardware.bus import CommError, MotorFaultError, PortError  # noqa: E402
from vlr.hardware.calibration import CalibrationError  # noqa: E402
from vlr.hardware.camera import CameraError, FakeCamera, OpenCVCamera  # noqa: E402
from vlr.hardware.control_table import CURRENT_UNIT_MA, HardwareError, Reg  # noqa: E402
from vlr.hardware.tendons import TendonMap, resolve_zero  # noqa: E402

from tests.hardware_fixtures import (  # noqa: E402
    CALIBRATION,
    OBJECT,
    config_dict,
    hand_on_emulator,
    make_config,
    write_config,
)
from vlr.hand import CommandError, Hand  # noqa: E402
from vlr.spec import load_hand  # noqa: E402

PER_METRE = 4096 / (2 * math.pi * 0.01)  # ticks per metre of tendon on the 10 mm spool
STORED = {"thumb": {"id": 1, "direction": 1, "zero": 2300},
          "left": {"id": 2, "direction": -1, "zero": 5000},   # a zero from another turn
          "right": {"id": 3, "direction": 1, "zero": 2200}}


def all_off(emulator) -> bool:
    return not any(emulator.torque().values())


def _start_hand(cfg, emu) -> HardwareHand:
    """A hand on a started emulator (for start-up failures; a success would leak it)."""
    return HardwareHand(cfg, spec=load_hand("modelo"), object_spec=OBJECT,
                        calibration=CALIBRATION, camera=FakeCamera(), port=emu.port,
                        log=lambda m: None)


def test_calibration_finds_the_taut_point(tmp_path):
    cfg = make_config(tmp_path)
    with hand_on_emulator(cfg) as (hand, emu):
        assert isinstance(hand, Hand)
        # The emulated lines go taut 2 mm of winding after power-up (emulator.slack).
        for f, zero in zip(cfg.fingers, hand.tendons.zeros, strict=True):
            taut = 2048 + f.direction * 0.002 * PER_METRE
            assert abs(zero - taut) <= 0.0003 * PER_METRE + 2, f.slot
        np.testing.assert_allclose(hand.commands, 0.0)
        assert emu.register(4, Reg.GOAL_POSITION) == 2100  # spread held
        assert emu.register(1, Reg.OPERATING_MODE) == 5
    assert all_off(emu)


def test_moves_follow_the_spool_math(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        # Stored zeros are known modulo a turn: 5000 reads as 904 after a power-up.
        assert hand.tendons.zeros == (2300, 904, 2200)
        report = hand.grasp()
        # Sent: the commands; reported: where the motors are, within a tick of them.
        np.testing.assert_allclose(hand.commands, [0.004, 0.003, 0.003])
        np.testing.assert_allclose(report.commands, [0.004, 0.003, 0.003],
                                   atol=1.01 / PER_METRE)
        report = hand.apply(np.array([0.001, -0.0005, 0.002]))
        assert report.settled and report.grasp_held
        u = np.array([0.005, 0.0025, 0.005])
        np.testing.assert_allclose(hand.commands, u)
        np.testing.assert_allclose(report.commands, u, atol=1.01 / PER_METRE)
        expected = {1: round(2300 + u[0] * PER_METRE), 2: round(904 - u[1] * PER_METRE),
                    3: round(2200 + u[2] * PER_METRE)}
        for dxl_id, ticks in expected.items():
            assert emu.register(dxl_id, Reg.GOAL_POSITION) == ticks
            assert abs(emu.register(dxl_id, Reg.PRESENT_POSITION) - ticks) <= 1  # settled
        np.testing.assert_allclose(
            TendonMap(hand.tendons.zeros, (1, -1, 1), 0.01).commands(list(expected.values())),
            u, atol=1 / PER_METRE)
        assert hand.grab_frame().image.shape == (48, 64, 3)
    assert all_off(emu)


def test_bad_commands_are_refused_and_the_range_clips(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        with pytest.raises(CommandError, match="exceeds the per-move limit"):
            hand.apply(np.array([0.003, 0.0, 0.0]))
        with pytest.raises(CommandError, match="not finite"):
            hand.apply(np.array([np.nan, 0.0, 0.0]))
        with pytest.raises(CommandError, match="shape"):
            hand.apply(np.zeros(2))
        report = hand.apply(np.array([-0.001, 0.001, 0.0]))  # thumb would go below 0
        np.testing.assert_allclose(hand.commands, [0.0, 0.001, 0.0])
        np.testing.assert_allclose(report.commands, [0.0, 0.001, 0.0], atol=1.01 / PER_METRE)
    assert all_off(emu)


def test_a_motor_that_stops_answering_is_named(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        emu.silence(2)
        with pytest.raises(CommError, match=r"motor 2 \(left\) does not answer"):
            hand.apply(np.array([0.001, 0.001, 0.001]))
        assert all_off(emu)  # switched off at the error, before close
        with pytest.raises(Exception, match="stopped after an error"):
            hand.apply(np.zeros(3))
    assert all_off(emu)


def test_corrupted_replies_recover_or_fail_clearly(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        emu.corrupt(3, 2)  # two bad replies: retries absorb them
        assert hand.apply(np.array([0.001, 0.001, 0.001])).settled
        emu.corrupt(3, -1)
        with pytest.raises(CommError, match=r"replies from motor 3 \(right\) are corrupted"):
            hand.apply(np.array([0.001, 0.001, 0.001]))
    assert all_off(emu)


def test_overload_stops_the_run_with_decoded_bits(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        emu.inject_hardware_error(1, HardwareError.OVERLOAD | HardwareError.OVERHEATING)
        with pytest.raises(MotorFaultError,
                           match=r"motor 1 \(thumb\).*bit 2 overheating, bit 5 overload"):
            hand.apply(np.array([0.001, 0.001, 0.001]))
        assert all_off(emu)
    assert all_off(emu)


def test_fault_at_start_up_is_reported(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    from vlr.hardware.emulate import build_emulator

    emu, _ = build_emulator(cfg)
    emu.inject_hardware_error(3)
    with emu, pytest.raises(MotorFaultError, match=r"motor 3 \(right\) is in a hardware error "
                                                   r"state.*bit 5 overload"):
        _start_hand(cfg, emu)
    assert all_off(emu)


def test_missing_motor_at_start_up_is_named(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    from vlr.hardware.emulate import build_emulator

    emu, _ = build_emulator(cfg)
    emu.silence(4)
    with emu, pytest.raises(CommError, match=r"motor 4 \(spread\) does not answer \(ping\)"):
        _start_hand(cfg, emu)
    assert all_off(emu)


def test_a_line_that_never_goes_taut(tmp_path):
    data = config_dict()
    data["fingers"]["right"]["direction"] = -1  # wired the wrong way round
    cfg = make_config(tmp_path, fingers=data["fingers"])
    from vlr.hardware.emulate import build_emulator

    emu, plant = build_emulator(cfg)
    plant.directions[3] = 1  # the motor really winds with +ticks
    plant.taut[3] = 2048 + 0.002 * PER_METRE
    with emu, pytest.raises(CalibrationError, match=r"right \(motor 3\) never became taut"):
        _start_hand(cfg, emu)
    assert all_off(emu)


def test_ctrl_c_and_sigterm_switch_torque_off(tmp_path):
    cfg = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(cfg) as (hand, emu):
        assert all(emu.torque().values())
        # Ctrl-C in the middle of a move (SIGALRM stands in for the keyboard).
        old = signal.signal(signal.SIGALRM, lambda *a: (_ for _ in ()).throw(
            KeyboardInterrupt()))
        try:
            signal.setitimer(signal.ITIMER_REAL, 0.004)
            with pytest.raises(KeyboardInterrupt):
                for _ in range(100):
                    hand.apply(np.array([0.001, 0.001, 0.001]))
                    hand.apply(np.array([-0.001, -0.001, -0.001]))
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
        assert all_off(emu)
        assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
    assert all_off(emu)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored by close()


def test_extended_position_mode_and_no_spread(tmp_path):
    data = config_dict()
    data["motion"]["mode"] = "extended_position"
    data.pop("spread")
    cfg = make_config(tmp_path, motion=data["motion"], spread=None)
    with hand_on_emulator(cfg) as (hand, emu):
        assert [emu.register(i, Reg.OPERATING_MODE) for i in (1, 2, 3)] == [4, 4, 4]
        assert hand.grasp().grasp_held
    assert all_off(emu)


def test_open_hand_dry_run_and_errors(tmp_path):
    obj = tmp_path / "ball.yaml"
    obj.write_text("shape: sphere\nsize: [0.03]\nmass: 0.05\ncom: [0, 0, 0.03]\ntag_id: 3\n"
                   "tag_size: 0.02\ngrasp_height: 0.08\n")
    path = write_config(tmp_path, config_dict(object="ball.yaml", fingers=STORED))
    hand = open_hand(config=str(path), seed=3)
    try:
        assert hand.object_spec.tag_id == 3
        assert hand.calibration.width == 640  # from hardware/example_camera.yaml
        assert hand.grasp().grasp_held
        port = hand.bus.port_name
    finally:
        hand.close()
    assert not hand.bus.connected and port.startswith("/dev/")
    # The tag check: a blank frame shows no tag, so there is no grasp.
    data = config_dict(object="ball.yaml", fingers=STORED)
    data["grasp"]["check_tag"] = True
    with open_hand(config=str(write_config(tmp_path, data, "tag.yaml"))) as hand:
        from vlr.hand import GraspError

        with pytest.raises(GraspError, match="tag .*id 3.* not seen"):
            hand.grasp()
    data = config_dict(object="ball.yaml")
    data["bus"]["port"] = "/dev/ttyNOPE7"
    with pytest.raises(PortError, match="/dev/ttyNOPE7 does not exist"):
        open_hand(config=str(write_config(tmp_path, data, "noport.yaml")))


def test_resolve_zero_picks_the_turn():
    # Stored 5000, present 904 + a bit of pull: the zero is 904 in this power cycle.
    assert resolve_zero(5000, 950, 1, 0.01, (0.0, 0.035)) == 904
    assert resolve_zero(100, 4000, -1, 0.01, (0.0, 0.035)) == 4196
    assert resolve_zero(2300, 2300, 1, 0.01, (0.0, 0.035)) == 2300


def test_cameras():
    frames = iter([np.ones((2, 2, 3), np.uint8), None])
    cam = FakeCamera(source=lambda: next(frames))
    assert cam.read().sum() == 12 and cam.read() is None
    cam.close()
    with pytest.raises(CameraError):
        cam.read()
    with pytest.raises(CameraError, match="cannot open camera 57"):
        OpenCVCamera(57)


def test_emulate_command_serves_and_stops(tmp_path, capsys):
    from vlr.cli import main

    path = write_config(tmp_path, config_dict())
    t0 = time.monotonic()
    assert main(["emulate", "--config", str(path), "--seconds", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "emulating motors [1, 2, 3, 4]" in out and "/dev/pts/" in out
    assert time.monotonic() - t0 < 5


def test_a_camera_that_ignores_the_size_is_refused(monkeypatch):
    import cv2

    class Capture:  # a driver that delivers 320x240 whatever is asked
        def __init__(self, index):
            pass

        def isOpened(self):  # noqa: N802 (OpenCV's names)
            return True

        def set(self, prop, value):
            return True

        def grab(self):
            return True

        def retrieve(self):
            return True, np.zeros((240, 320, 3), np.uint8)

        def release(self):
            pass

    monkeypatch.setattr(cv2, "VideoCapture", Capture)
    assert OpenCVCamera(0, 320, 240).read().shape == (240, 320, 3)
    with pytest.raises(CameraError, match="delivers 320x240 frames, not the calibration's "
                                          "640x480"):
        OpenCVCamera(0, 640, 480).read()


def test_tensions_from_the_settled_currents(tmp_path):
    """With a `tension` calibration each move reports tendon tensions from the motors'
    present current once they stop, T = newton_per_ma x (direction x current - zero_ma), at
    least 0;
    without one, none (and an identification that weighs tensions is refused before the hand
    moves)."""
    from vlr.errors import UserError
    from vlr.settings import load_settings
    from vlr.world import open_world

    cfg = make_config(tmp_path, fingers=STORED,
                      tension={"newton_per_ma": 0.18, "zero_ma": [5.0, 5.0, 5.0]})
    with hand_on_emulator(cfg) as (hand, emu):
        assert hand.reads_tensions
        hand.grasp()
        report = hand.apply(np.array([0.001, 0.0, 0.002]))
        current = np.array([emu.register(i, Reg.PRESENT_CURRENT) for i in (1, 2, 3)],
                           dtype=float)
        current = np.where(current >= 2**15, current - 2**16, current) * CURRENT_UNIT_MA
        pulling = current * np.array([1, -1, 1])  # the left motor pulls with negative ticks
        np.testing.assert_allclose(report.tensions,
                                   np.maximum(0.0, 0.18 * (pulling - 5.0)), atol=1e-9)
        assert report.tensions.shape == (3,) and np.all(report.tensions > 1.0)
    plain = make_config(tmp_path, fingers=STORED)
    with hand_on_emulator(plain) as (hand, emu):
        assert not hand.reads_tensions
        assert hand.grasp().tensions is None
    path = write_config(tmp_path, config_dict(fingers=STORED), "plain.yaml")
    with pytest.raises(UserError, match="does not report tendon tensions"):
        open_world(load_settings({"world.backend": "hardware",
                                  "world.options.config": str(path),
                                  "filter.observation.sigma_tension_n": 0.5}))
