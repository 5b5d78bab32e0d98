"""The real hand's last lines of defence, against the emulated motors: a camera that stops
delivering frames stops the run with torque off; every motor's Bus Watchdog is armed while
its torque is on, so that a host that stops talking (a killed process) leaves no motor
holding; and `close()` switches torque off even when its last check fails on the wire."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("dynamixel_sdk", reason="the real hand's tests need the hardware extra "
                    "(pip install -e '.[hardware]')")

import serial  # noqa: E402
from vlr.hardware.backend import HardwareHand  # noqa: E402
from vlr.hardware.bus import HardwareError, MotorBus, MotorStatusError  # noqa: E402
from vlr.hardware.camera import CameraError, FakeCamera  # noqa: E402
from vlr.hardware.config import HardwareConfigError  # noqa: E402
from vlr.hardware.control_table import Reg  # noqa: E402
from vlr.hardware.emulate import build_emulator  # noqa: E402
from vlr.hardware.emulator import Emulator  # noqa: E402

from tests.hardware_fixtures import (  # noqa: E402
    CALIBRATION,
    OBJECT,
    ROOT,
    config_dict,
    hand_on_emulator,
    make_config,
    sim_config_dict,
    write_config,
)
from vlr.spec import load_hand  # noqa: E402

IDS = (1, 2, 3, 4)  # the fixtures' fingers and spread motor


def frames_then_none(n: int, width: int = 64, height: int = 48) -> FakeCamera:
    """A camera that delivers `n` frames, then none (a camera unplugged mid-run)."""
    count = [0]

    def source():
        count[0] += 1
        return np.zeros((height, width, 3), np.uint8) if count[0] <= n else None
    return FakeCamera(width, height, source=source, name="camera 5 (/dev/video5)")


def wait_for(condition, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


# ------------------------------------------------------------------------------ camera

def test_a_camera_that_stops_delivering_frames_stops_the_run_with_torque_off(tmp_path):
    cfg = make_config(tmp_path)
    assert cfg.camera.max_missing_frames == 3  # the default
    with hand_on_emulator(cfg, camera=frames_then_none(1)) as (hand, emulator):
        hand.grasp()
        assert hand.grab_frame() is not None
        assert all(emulator.torque().values())
        assert hand.grab_frame() is None  # a dropped frame or two: a prediction-only step
        assert hand.grab_frame() is None
        with pytest.raises(CameraError) as info:
            hand.grab_frame()
        message = str(info.value)
        assert "\n" not in message
        assert "camera 5 (/dev/video5)" in message and "3 reads in a row" in message
        assert not any(emulator.torque().values())  # stopped at once, not at close
        with pytest.raises(HardwareError, match="stopped"):
            hand.apply(np.zeros(3))


def test_a_blind_camera_is_not_taken_for_a_held_grasp(tmp_path):
    """The grasp check reads the camera too: no frames means no grasp known, and after the
    limit the run stops instead of reporting the grasp held step after step."""
    cfg = make_config(tmp_path, grasp={"commands": [0.004, 0.003, 0.003], "check_tag": True},
                      camera={"fake": "blank", "calibration": str(ROOT / "hardware" /
                                                                  "example_camera.yaml"),
                              "max_missing_frames": 2})
    with hand_on_emulator(cfg, camera=frames_then_none(0)) as (hand, emulator):
        assert hand.grasp().grasp_held  # one missing frame: not known, so not a failure
        with pytest.raises(CameraError, match="2 reads in a row"):
            hand.apply(np.full(3, 0.0005))
        assert not any(emulator.torque().values())


def test_a_frame_resets_the_count_of_missing_ones(tmp_path):
    cfg = make_config(tmp_path)
    pattern = iter([None, None, 1, None, None, 1, None, None])

    def source():
        return None if next(pattern) is None else np.zeros((48, 64, 3), np.uint8)
    with hand_on_emulator(cfg, camera=FakeCamera(64, 48, source=source)) as (hand, _):
        frames = [hand.grab_frame() is not None for _ in range(8)]
    assert frames == [False, False, True, False, False, True, False, False]


@pytest.mark.parametrize(("section", "key", "value"), [
    ("camera", "max_missing_frames", 0), ("bus", "watchdog_ms", 30),
    ("bus", "watchdog_ms", 100), ("bus", "watchdog_ms", 3000)])
def test_bad_safety_settings_are_refused_naming_the_key(tmp_path, section, key, value):
    data = config_dict()
    data[section][key] = value
    with pytest.raises(HardwareConfigError, match=rf"{section}\.{key} = {value}"):
        make_config(tmp_path, **{section: data[section]})


def test_vlr_identify_stops_non_zero_naming_the_camera_and_writes_no_result(
        tmp_path, monkeypatch, capsys):
    """The simulated hand behind emulated motors; its camera dies after a few frames."""
    pytest.importorskip("vlr.sim.backend")
    import vlr.hardware.backend
    import vlr.hardware.emulate

    from vlr.cli import main

    emulators = []
    build = vlr.hardware.emulate.build_emulator

    def recording(cfg):
        emulator, plant = build(cfg)
        emulators.append(emulator)
        return emulator, plant
    monkeypatch.setattr(vlr.hardware.emulate, "build_emulator", recording)
    make_camera = vlr.hardware.backend._camera

    def dying_camera(cfg, calibration, plant):
        camera = make_camera(cfg, calibration, plant)
        render, count = camera.source, [0]

        def source():
            count[0] += 1
            return render() if count[0] <= 4 else None
        camera.source = source
        return camera
    monkeypatch.setattr(vlr.hardware.backend, "_camera", dying_camera)
    path = write_config(tmp_path, sim_config_dict())
    out = tmp_path / "run"
    rc = main(["identify", "--backend", "hardware", "--config", str(path), "--particles",
               "300", "--max-iterations", "8", "--out", str(out), "--quiet"])
    err = [line for line in capsys.readouterr().err.splitlines()
           if not line.startswith("[hardware]")]  # progress lines
    assert rc == 2
    assert err == ["vlr identify: error: camera.fake 'sim' delivered no frame in 3 reads in a "
                   "row (camera.max_missing_frames = 3): the run stopped with torque off; "
                   "check the camera's cable and that no other program holds it"]
    assert not (out / "result.json").exists()
    assert not any(emulators[0].torque().values())


# ------------------------------------------------------------------------------ watchdog

def test_torque_on_arms_the_watchdog_on_every_motor_and_a_clean_close_disarms_it(tmp_path):
    cfg = make_config(tmp_path)
    assert cfg.bus.watchdog_ms == 2000 and cfg.bus.watchdog == 100  # the default: 2 s
    with hand_on_emulator(cfg) as (hand, emulator):
        hand.grasp()
        assert {i: emulator.register(i, Reg.BUS_WATCHDOG) for i in IDS} == dict.fromkeys(
            IDS, 100)
        hand.close()
        assert {i: emulator.register(i, Reg.BUS_WATCHDOG) for i in IDS} == dict.fromkeys(
            IDS, 0)
        assert not any(emulator.torque().values())


def test_a_host_that_stops_talking_leaves_no_motor_holding(tmp_path):
    """The watchdog expires on every motor once nothing talks to it for 2 s: torque off,
    98 = -1, goals refused; the next run clears it and starts cleanly."""
    cfg = make_config(tmp_path)
    with hand_on_emulator(cfg) as (hand, emulator):
        hand.grasp()
        assert all(emulator.torque().values())
        hand.bus.stop_keepalive()  # the process is gone: nothing talks any more
        emulator.pass_time(1.5)
        time.sleep(0.05)
        assert all(emulator.torque().values())  # not yet: 98 x 20 ms = 2 s
        emulator.pass_time(0.6)
        assert wait_for(lambda: not any(emulator.torque().values()), 1.0)
        assert {i: emulator.register(i, Reg.BUS_WATCHDOG) for i in IDS} == dict.fromkeys(
            IDS, -1)
        with emulator.lock:  # a goal sent now is refused, so nothing moves
            m = emulator.motors[1]
            assert m.write(Reg.GOAL_POSITION.address, Reg.GOAL_POSITION.encode(3000)) == 4
        hand._release()  # what atexit would have done; the motors are already free
        # A new run on the same motors clears the expired watchdogs and moves again.
        with HardwareHand(cfg, spec=load_hand(cfg.hand), object_spec=OBJECT,
                          calibration=CALIBRATION, camera=FakeCamera(64, 48),
                          port=emulator.port, log=lambda m: None) as again:
            assert again.grasp().settled
            assert emulator.register(1, Reg.BUS_WATCHDOG) == 100


def test_the_emulated_watchdog_is_fed_only_by_packets_to_its_motor():
    with Emulator([1, 2]) as emulator:
        bus = MotorBus(emulator.port, 1_000_000, latency_ms=16, watchdog=100)
        bus.connect()
        try:
            bus.set_torque([1, 2], True)
            emulator.pass_time(1.5)
            bus.read(Reg.PRESENT_POSITION, 1)  # feeds motor 1 only
            emulator.pass_time(1.0)
            assert wait_for(lambda: not emulator.torque()[2], 1.0)
            assert emulator.torque()[1]
            assert bus.watchdog_expired(2) and not bus.watchdog_expired(1)
            with pytest.raises(MotorStatusError, match="data range error"):
                bus.write(Reg.GOAL_POSITION, 2, 2100)
            bus.set_torque([2], True)  # clears it (98 := 0), arms it again, torque on
            bus.write(Reg.GOAL_POSITION, 2, 2100)
            assert emulator.torque()[2] and emulator.register(2, Reg.BUS_WATCHDOG) == 100
        finally:
            bus.close()


CHILD = """
import sys, time
from vlr.hardware.backend import HardwareHand
from vlr.hardware.camera import FakeCamera
from vlr.hardware.config import load_config
from tests.hardware_fixtures import CALIBRATION, OBJECT
from vlr.spec import load_hand

cfg = load_config(sys.argv[1])
hand = HardwareHand(cfg, spec=load_hand(cfg.hand), object_spec=OBJECT,
                    calibration=CALIBRATION, camera=FakeCamera(64, 48), port=sys.argv[2],
                    log=lambda m: None)
hand.grasp()
print("held", flush=True)
time.sleep(60)  # a long pause of a living process (the filter's update): kept fed
"""


def test_a_killed_host_process_leaves_no_motor_holding(tmp_path):
    """A real SIGKILL: a child process grasps through the emulator's pty, idles well past
    the watchdog (its keep-alive feeds the motors), and is killed; the motors let go."""
    data = config_dict()
    data["bus"]["watchdog_ms"] = 400
    path = write_config(tmp_path, data)
    cfg = make_config(tmp_path, bus=data["bus"])
    emulator, _ = build_emulator(cfg)
    with emulator:
        child = subprocess.Popen([sys.executable, "-c", CHILD, str(path), emulator.port],
                                 cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 env={**os.environ, "PYTHONPATH": str(ROOT)})
        try:
            ready, _, _ = select.select([child.stdout], [], [], 30.0)
            line = child.stdout.readline() if ready else b""
            assert line.strip() == b"held", child.stderr.read1(4000) if not ready else line
            time.sleep(1.0)  # 2.5 watchdogs of an idle but living host
            assert all(emulator.torque().values())
            assert emulator.watchdog_expiries == 0
            child.send_signal(signal.SIGKILL)
            child.wait(5)
            t0 = time.monotonic()
            assert wait_for(lambda: not any(emulator.torque().values()), 3.0)
            assert time.monotonic() - t0 < 1.5
            assert emulator.watchdog_expiries == len(IDS)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait(5)


# ------------------------------------------------------------------------------ close

def test_close_switches_torque_off_when_its_last_check_fails_on_a_serial_error(tmp_path):
    cfg = make_config(tmp_path)
    with hand_on_emulator(cfg) as (hand, emulator):
        hand.grasp()
        port = hand.bus.port
        read = port.readPort
        calls = [0]

        def flaky(length):
            calls[0] += 1
            if calls[0] == 1:  # pyserial, when the adapter vanishes mid-read
                raise serial.SerialException("device reports readiness to read but returned "
                                             "no data (device disconnected?)")
            return read(length)
        port.readPort = flaky
        with pytest.raises(HardwareError) as info:
            hand.close()
        assert calls[0] >= 1
        assert "\n" not in str(info.value) and hand.bus.port_name in str(info.value)
        assert not any(emulator.torque().values())
        assert not hand.bus.connected
