"""MotorBus through the real dynamixel_sdk against the Protocol 2.0 emulator on a pty."""

from __future__ import annotations

import random
import time

import pytest

pytest.importorskip("dynamixel_sdk", reason="the real hand's tests need the hardware extra "
                    "(pip install -e '.[hardware]')")

from dynamixel_sdk import PacketHandler  # noqa: E402
from vlr.hardware.bus import (  # noqa: E402
    CommError,
    MotorBus,
    MotorFaultError,
    MotorStatusError,
    PortError,
)
from vlr.hardware.control_table import (  # noqa: E402
    HardwareError,
    OperatingMode,
    Reg,
    describe_hardware_error,
)
from vlr.hardware.emulator import Emulator, KinematicPlant  # noqa: E402
from vlr.hardware.protocol2 import PacketParser, crc16, encode, stuff, unstuff  # noqa: E402

IDS = (1, 2, 3)


@pytest.fixture
def emu():
    with Emulator(IDS) as emulator:
        yield emulator


@pytest.fixture
def bus(emu):
    b = MotorBus(emu.port, 1_000_000, labels={1: "thumb", 2: "left", 3: "right"},
                 latency_ms=16, retries=2)
    b.connect()
    yield b
    b.close()


def test_crc_matches_the_sdk():
    sdk = PacketHandler(2.0)
    rng = random.Random(0)
    for _ in range(200):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
        assert crc16(data) == sdk.updateCRC(0, list(data), len(data))


def test_stuffing_round_trip_and_parser_resync():
    body = bytes([0x03, 0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD])
    assert stuff(body) == bytes([0x03, 0xFF, 0xFF, 0xFD, 0xFD, 0x01, 0xFF, 0xFF, 0xFD, 0xFD])
    assert unstuff(stuff(body)) == body
    packet = encode(5, 0x03, body[1:])
    parser = PacketParser()
    # Garbage first, then the packet split across two feeds.
    assert parser.feed(b"\x00\xff\x12" + packet[:6]) == []
    (p,) = parser.feed(packet[6:])
    assert (p.dxl_id, p.instruction, p.params, p.crc_ok) == (5, 0x03, body[1:], True)
    bad = packet[:-1] + bytes([packet[-1] ^ 1])
    (q,) = parser.feed(bad)
    assert not q.crc_ok
    # A long run of false headers (bad reserved byte) is skipped, not recursed into.
    (r,) = parser.feed(b"\xff\xff\xfd\x01" * 5000 + packet)
    assert r.crc_ok and r.params == body[1:]


def test_ping_read_write_sync(bus, emu):
    assert bus.ping(2) == 1020
    assert bus.read(Reg.PRESENT_POSITION, 2) == 2048
    bus.write(Reg.OPERATING_MODE, 2, int(OperatingMode.EXTENDED_POSITION))
    assert emu.register(2, Reg.OPERATING_MODE) == 4
    bus.set_torque(IDS, True)
    assert emu.torque() == {1: True, 2: True, 3: True}
    bus.sync_write(Reg.GOAL_POSITION, {1: 2100, 2: 1900, 3: -300})
    deadline = time.monotonic() + 2
    while time.monotonic() < deadline:
        block = bus.sync_read([Reg.MOVING, Reg.PRESENT_CURRENT, Reg.PRESENT_POSITION], IDS)
        present = {i: v[Reg.PRESENT_POSITION] for i, v in block.items()}
        # (Right after a sync write a motor may not have started: Moving alone is not enough.)
        if present == {1: 2100, 2: 1900, 3: 2048} and not any(
                v[Reg.MOVING] for v in block.values()):
            break
    assert present == {1: 2100, 2: 1900, 3: 2048}  # 3 is in position mode: -300 refused
    assert bus.sync_read_one(Reg.PRESENT_POSITION, IDS) == present
    bus.set_torque(IDS, False)
    assert not any(emu.torque().values())


def test_eeprom_write_with_torque_on_is_refused(bus, emu):
    bus.write(Reg.TORQUE_ENABLE, 1, 1)
    with pytest.raises(MotorStatusError, match=r"motor 1 \(thumb\) refused .*access error"):
        bus.write(Reg.OPERATING_MODE, 1, 5)
    assert emu.register(1, Reg.OPERATING_MODE) == 3


def test_silent_motor_is_named(bus, emu):
    emu.silence(3)
    with pytest.raises(CommError, match=r"motor 3 \(right\) does not answer \(ping\)") as e:
        bus.ping(3)
    assert e.value.ids == (3,)
    # A sync read times out as a group; the per-motor fallback names the silent one.
    with pytest.raises(CommError, match=r"motor 3 \(right\) does not answer"):
        bus.sync_read_one(Reg.PRESENT_POSITION, IDS)
    emu.silence(3, False)
    assert bus.sync_read_one(Reg.PRESENT_POSITION, IDS)[3] == 2048


def test_corrupted_reply_is_retried_then_reported(bus, emu):
    emu.corrupt(2, 1)  # one bad CRC: a retry recovers
    assert bus.read(Reg.PRESENT_POSITION, 2) == 2048
    emu.corrupt(2, 1)
    assert bus.sync_read_one(Reg.PRESENT_POSITION, IDS) == {1: 2048, 2: 2048, 3: 2048}
    emu.corrupt(2, -1)  # always corrupted: bounded retries, then a clear error
    with pytest.raises(CommError, match=r"replies from motor 2 \(left\) are corrupted"):
        bus.read(Reg.PRESENT_POSITION, 2)
    emu.corrupt(2, 0)
    assert bus.ping(2) == 1020


def test_overload_is_decoded_and_cleared_by_reboot(bus, emu):
    bus.set_torque(IDS, True)
    emu.inject_hardware_error(1, HardwareError.OVERLOAD)
    assert emu.torque()[1] is False
    with pytest.raises(MotorFaultError, match=r"motor 1 \(thumb\).*bit 5 overload.*0x20") as e:
        bus.sync_read_one(Reg.PRESENT_POSITION, IDS)
    assert (e.value.dxl_id, e.value.bits) == (1, 0x20)
    with pytest.raises(MotorFaultError):
        bus.read(Reg.PRESENT_POSITION, 1)
    bus.reboot(1)
    time.sleep(0.01)
    assert bus.read(Reg.HARDWARE_ERROR_STATUS, 1) == 0
    assert describe_hardware_error(0x24) == "bit 2 overheating, bit 5 overload (persistent " \
        "load above the motor's limit)"


def test_torque_off_everywhere_reaches_a_motor_whose_replies_are_lost(bus, emu):
    bus.set_torque(IDS, True)
    emu.silence(2)
    problems = bus.torque_off_everywhere(IDS)
    assert not any(emu.torque().values())  # the broadcast got through
    assert len(problems) == 1 and "motor 2 (left)" in problems[0]


def test_missing_and_busy_ports(emu):
    with pytest.raises(PortError, match="serial port /dev/ttyNOPE9 does not exist"):
        MotorBus("/dev/ttyNOPE9", 57_600).connect()
    with pytest.raises(PortError, match="baud rate 12345"):
        MotorBus(emu.port, 12_345).connect()
    first = MotorBus(emu.port, 1_000_000)
    first.connect()
    try:
        with pytest.raises(PortError, match="is busy"):
            MotorBus(emu.port, 1_000_000).connect()
    finally:
        first.close()


def test_values_that_would_need_stuffing_are_refused(bus):
    with pytest.raises(ValueError, match="FF FF FD"):
        bus.write(Reg.GOAL_POSITION, 1, 0x00FDFFFF)


def test_interrupted_transaction_leaves_the_port_usable(bus, emu):
    bus.port.is_using = True  # what a KeyboardInterrupt inside the SDK leaves behind
    assert bus.ping(1) == 1020  # the retry path clears it


def test_kinematic_plant_stalls_at_the_current_cap():
    plant = KinematicPlant(taut={1: 2100.0}, preload=60, stiffness=1.0)
    with Emulator([1], plant=plant) as emu:
        bus = MotorBus(emu.port, 1_000_000, latency_ms=16)
        bus.connect()
        try:
            bus.write(Reg.OPERATING_MODE, 1, int(OperatingMode.CURRENT_BASED_POSITION))
            bus.write(Reg.TORQUE_ENABLE, 1, 1)
            bus.write(Reg.GOAL_CURRENT, 1, 60)  # 161 mA: stall 101 ticks past taut
            bus.write(Reg.GOAL_POSITION, 1, 3000)
            time.sleep(0.3)
            assert abs(bus.read(Reg.PRESENT_POSITION, 1) - 2201) <= 1
            assert bus.read(Reg.MOVING, 1) == 0
            assert 150 < bus.read(Reg.PRESENT_CURRENT, 1) * 2.69 < 170
        finally:
            bus.close()
