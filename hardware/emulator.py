"""An emulated chain of DYNAMIXEL X-series motors (Protocol 2.0) on a pseudo-terminal.

The real `dynamixel_sdk` talks to it byte for byte: give the SDK `Emulator.port` (the pty's
slave path) as its serial port. A background thread serves the master side: it parses
instruction packets (header, stuffing, CRC-16), answers with status packets and advances the
motors' motion through a `MotorPlant`.

What is emulated (XM430-W350, https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/):
PING (also broadcast), READ, WRITE, SYNC_READ, SYNC_WRITE, BULK_READ, REBOOT; a control table
per motor (`hardware.control_table.Reg`); EEPROM (addresses < 64) not writable with torque on
(access error 7); present position moving towards the goal at a bounded rate, so a master
really has to wait; a load model (`KinematicPlant`); and faults to inject: a motor that stops
answering, corrupted replies (bad CRC), replies that leave late (a USB or OS stall: the bytes
behind them wait too, in order), instructions lost on the wire (noise: the motor neither acts
nor answers), and hardware errors (e.g. overload, bit 5 of register 70), now or after a number
of served packets, which switch torque off and set the alert bit 0x80 in every status until
REBOOT.

The Bus Watchdog (98) is emulated: a motor with torque on and 98 set to 1..127 counts the
time since the last instruction packet addressed to it (to its id, broadcast, or a sync or
bulk packet listing it); past 98 x 20 ms it sets 98 to -1, switches its torque off (the
emulated motor releases: see hardware/README.md for what the e-manual says of the real one)
and refuses goal writes (data range error) until 98 is written 0. `Emulator.pass_time`
ages those clocks, to play a host that stopped talking without waiting for it.

Multi-turn position is lost on REBOOT, as on the real motor: present position then reads
within one turn (0..4095). Plants see the continuous `shaft` angle, which a reboot does not
change.
"""

from __future__ import annotations

import math
import os
import random
import select
import threading
import time
import tty
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

from vlr.hardware.control_table import (
    ALERT_BIT,
    CURRENT_UNIT_MA,
    EEPROM_END,
    EXTENDED_POSITION_LIMIT,
    READ_ONLY,
    TICKS_PER_REV,
    VELOCITY_UNIT_RPM,
    WATCHDOG_EXPIRED,
    WATCHDOG_LOCKED,
    WATCHDOG_MAX,
    WATCHDOG_UNIT_MS,
    HardwareError,
    OperatingMode,
    Reg,
)
from vlr.hardware.protocol2 import (
    BROADCAST_ID,
    Instruction,
    Packet,
    PacketParser,
    encode_status,
)

# Status error numbers (Protocol 2.0).
ERR_INSTRUCTION = 2
ERR_CRC = 3
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7

#: Size of the emulated control table [bytes] (the XM430's indirect area is left out).
TABLE_SIZE = 256

#: Defaults of a factory-new XM430-W350 (e-manual, "Control Table"), id and baud aside.
_FACTORY = {
    Reg.MODEL_NUMBER: 1020, Reg.FIRMWARE_VERSION: 46, Reg.BAUD_RATE: 1,
    Reg.RETURN_DELAY_TIME: 250, Reg.OPERATING_MODE: int(OperatingMode.POSITION),
    Reg.MOVING_THRESHOLD: 10, Reg.TEMPERATURE_LIMIT: 80, Reg.CURRENT_LIMIT: 1193,
    Reg.VELOCITY_LIMIT: 200, Reg.MAX_POSITION_LIMIT: 4095, Reg.MIN_POSITION_LIMIT: 0,
    Reg.SHUTDOWN: 52, Reg.STATUS_RETURN_LEVEL: 2, Reg.POSITION_P_GAIN: 800,
    Reg.PRESENT_INPUT_VOLTAGE: 120, Reg.PRESENT_TEMPERATURE: 31,
}


_MODES = frozenset(int(m) for m in OperatingMode)


def rpm_to_ticks_per_s(rpm: float) -> float:
    return rpm / 60.0 * TICKS_PER_REV


@dataclass
class Faults:
    """Faults injected into one motor.

    Attributes:
        silent: the motor sends no status packets (a broken return line, a flaky
            connector); it still executes what it hears, so a broadcast can still reach it.
        corrupt_replies: the next N status packets carry a bad CRC; -1 means all of them.
        reply_delay: each status packet leaves this late [s]; what the emulator sends after
            it waits behind it (a stall delays the line, it does not reorder it).
        late_replies: how many replies `reply_delay` holds back; -1 means all of them.
        drop_share: the share of instruction packets the motor never receives (its part of
            a sync write included); drawn from the emulator's seeded generator.
        drop_only: the instructions `drop_share` applies to (None: all of them).
        fault_after: raise `fault_bits` once the emulator has served this many packets in
            all (None: never); a fault in the middle of a run.
        fault_bits: the Hardware Error Status bits of that fault.
    """

    silent: bool = False
    corrupt_replies: int = 0
    reply_delay: float = 0.0
    late_replies: int = -1
    drop_share: float = 0.0
    drop_only: frozenset[int] | None = None
    fault_after: int | None = None
    fault_bits: int = 0


class EmulatedMotor:
    """One XM430: its control table bytes plus the continuous shaft angle."""

    def __init__(self, dxl_id: int, shaft: float = 2048.0, model: int = 1020) -> None:
        self.table = bytearray(TABLE_SIZE)
        for reg, value in _FACTORY.items():
            self.set(reg, value)
        self.set(Reg.MODEL_NUMBER, model)
        self.set(Reg.ID, dxl_id)
        self.shaft = float(shaft)  # continuous angle [ticks]; what a plant moves
        # present position = shaft - lost; a power-up or reboot forgets whole turns.
        self.lost = self._whole_turns(shaft)
        self.velocity = 0.0        # [ticks/s]
        self.current = 0.0         # [mA], signed
        self.moving = False
        self.faults = Faults()
        self.heard = time.monotonic()  # when the last instruction packet to it arrived
        self.set(Reg.GOAL_POSITION, self.present_position)

    # ----------------------------------------------------------------- register access
    @property
    def dxl_id(self) -> int:
        return self.get(Reg.ID)

    def get(self, reg: Reg) -> int:
        return reg.decode(self.table[reg.address: reg.address + reg.size])

    def set(self, reg: Reg, value: int) -> None:
        self.table[reg.address: reg.address + reg.size] = reg.encode(value)

    @staticmethod
    def _whole_turns(ticks: float) -> int:
        return int(math.floor(ticks / TICKS_PER_REV)) * TICKS_PER_REV

    @property
    def present_position(self) -> int:
        return int(round(self.shaft - self.lost))

    @property
    def torque_on(self) -> bool:
        return bool(self.get(Reg.TORQUE_ENABLE))

    @property
    def mode(self) -> int:
        return self.get(Reg.OPERATING_MODE)

    @property
    def goal_shaft(self) -> float:
        """The goal position in the shaft frame [ticks]."""
        return float(self.get(Reg.GOAL_POSITION) + self.lost)

    @property
    def current_cap(self) -> float:
        """The most current the motor may draw [mA]: Goal Current in current-based position
        mode, else Current Limit."""
        limit = self.get(Reg.CURRENT_LIMIT)
        if self.mode == OperatingMode.CURRENT_BASED_POSITION:
            limit = min(limit, abs(self.get(Reg.GOAL_CURRENT)))
        return limit * CURRENT_UNIT_MA

    @property
    def max_speed(self) -> float:
        """Speed of a move [ticks/s]: Profile Velocity if set, else Velocity Limit."""
        v = self.get(Reg.PROFILE_VELOCITY) or self.get(Reg.VELOCITY_LIMIT)
        return rpm_to_ticks_per_s(v * VELOCITY_UNIT_RPM)

    def fault(self, bits: int) -> None:
        """Raise a hardware error: set register 70 and switch torque off (Shutdown)."""
        self.set(Reg.HARDWARE_ERROR_STATUS, self.get(Reg.HARDWARE_ERROR_STATUS) | bits)
        self.set(Reg.TORQUE_ENABLE, 0)

    def watchdog(self, now: float) -> bool:
        """Expire the Bus Watchdog if it is armed, torque is on and nothing has been heard
        for longer than 98 x 20 ms: 98 := -1, torque off. Returns whether it expired now."""
        units = self.get(Reg.BUS_WATCHDOG)
        if units <= 0 or not self.torque_on:
            return False
        if now - self.heard <= units * WATCHDOG_UNIT_MS / 1000.0:
            return False
        self.set(Reg.BUS_WATCHDOG, WATCHDOG_EXPIRED)
        self.set(Reg.TORQUE_ENABLE, 0)
        self.velocity, self.moving = 0.0, False
        return True

    def error_byte(self, number: int = 0) -> int:
        return number | (ALERT_BIT if self.get(Reg.HARDWARE_ERROR_STATUS) else 0)

    def sync_present(self) -> None:
        """Copy the motion state into the present-value registers."""
        self.set(Reg.PRESENT_POSITION, self.present_position)
        self.set(Reg.PRESENT_VELOCITY, int(round(self.velocity / rpm_to_ticks_per_s(
            VELOCITY_UNIT_RPM))))
        self.set(Reg.PRESENT_CURRENT, int(round(self.current / CURRENT_UNIT_MA)))
        self.set(Reg.MOVING, int(self.moving))

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """(error number, data) for a READ of `length` bytes at `address`."""
        if length < 1 or address + length > TABLE_SIZE:
            return ERR_ACCESS, b""
        self.sync_present()
        return 0, bytes(self.table[address: address + length])

    def write(self, address: int, data: bytes) -> int:
        """Apply a WRITE; returns the status error number (0 on success)."""
        end = address + len(data)
        if not data or end > TABLE_SIZE:
            return ERR_DATA_LENGTH
        touched = [r for r in Reg if r.address < end and address < r.address + r.size]
        if any(r in READ_ONLY for r in touched):
            return ERR_ACCESS
        if address < EEPROM_END and self.torque_on:
            return ERR_ACCESS
        scratch = bytearray(self.table)
        scratch[address:end] = data
        new = {r: r.decode(scratch[r.address: r.address + r.size]) for r in touched}
        if Reg.OPERATING_MODE in new and new[Reg.OPERATING_MODE] not in _MODES:
            return ERR_DATA_RANGE
        if Reg.TORQUE_ENABLE in new and new[Reg.TORQUE_ENABLE] not in (0, 1):
            return ERR_DATA_RANGE
        if Reg.BUS_WATCHDOG in new and not 0 <= new[Reg.BUS_WATCHDOG] <= WATCHDOG_MAX:
            return ERR_DATA_RANGE  # -1 is the motor's to set
        if (self.get(Reg.BUS_WATCHDOG) == WATCHDOG_EXPIRED
                and any(r in WATCHDOG_LOCKED for r in touched)):
            return ERR_DATA_RANGE  # goals are read-only until 98 is written 0
        if Reg.GOAL_CURRENT in new and abs(new[Reg.GOAL_CURRENT]) > self.get(Reg.CURRENT_LIMIT):
            return ERR_DATA_LIMIT
        if Reg.GOAL_POSITION in new and not self._goal_ok(new[Reg.GOAL_POSITION]):
            return ERR_DATA_LIMIT
        torque_was = self.torque_on
        if Reg.TORQUE_ENABLE in new and new[Reg.TORQUE_ENABLE] and self.get(
                Reg.HARDWARE_ERROR_STATUS):
            scratch[Reg.TORQUE_ENABLE.address] = 0  # a faulted motor keeps torque off
        self.table[:] = scratch
        if self.torque_on and not torque_was and Reg.GOAL_POSITION not in new:
            # Enabling torque holds the shaft where it is rather than jumping to a stale goal.
            self.set(Reg.GOAL_POSITION, self.present_position)
        return 0

    def _goal_ok(self, goal: int) -> bool:
        if self.mode == OperatingMode.POSITION:
            return self.get(Reg.MIN_POSITION_LIMIT) <= goal <= self.get(Reg.MAX_POSITION_LIMIT)
        return abs(goal) <= EXTENDED_POSITION_LIMIT

    def reboot(self) -> None:
        """REBOOT: RAM back to defaults, hardware error cleared, whole turns forgotten."""
        self.table[EEPROM_END:] = bytes(TABLE_SIZE - EEPROM_END)
        for reg, value in _FACTORY.items():
            if not reg.eeprom:
                self.set(reg, value)
        self.lost = self._whole_turns(self.shaft)
        self.velocity, self.current, self.moving = 0.0, 0.0, False
        self.set(Reg.GOAL_POSITION, self.present_position)


class MotorPlant(Protocol):
    """What moves the motors' shafts: goal positions in, positions and currents out.

    `step` is called by the emulator's thread every few milliseconds, with the lock held, so
    it must be quick (a slow simulation belongs in its own thread; see `hardware.sim_plant`).
    It reads `goal_shaft`, `torque_on`, `current_cap`, `max_speed` of each motor and sets
    `shaft`, `velocity`, `current` and `moving`.
    """

    def step(self, motors: Mapping[int, EmulatedMotor], dt: float) -> None: ...


class KinematicPlant:
    """A motor winding a tendon: moves at bounded speed; once the line is taut, it carries
    the springs' preload plus a tension growing with further winding, and the motor stalls
    where that load reaches its current cap.

    Args:
        taut: shaft angle [ticks] at which each motor's line goes taut; a motor absent from
            the mapping drives no load.
        directions: +1 if increasing ticks winds the line (default +1).
        preload: load current as soon as the line is taut [mA] (the Model O's joint springs
            are preloaded against their open stops, vlr/spec.py).
        stiffness: further load current per tick wound past taut [mA/tick] (0.15 mA/tick:
            ~400 mA after 35 mm on a 10 mm spool, a closed hand within the XM430's limits).
        friction: current of an unloaded move [mA].
    """

    def __init__(self, taut: Mapping[int, float] | None = None,
                 directions: Mapping[int, int] | None = None, preload: float = 60.0,
                 stiffness: float = 0.15, friction: float = 8.0) -> None:
        self.taut = dict(taut or {})
        self.directions = dict(directions or {})
        self.preload = preload
        self.stiffness = stiffness
        self.friction = friction

    def load(self, dxl_id: int, shaft: float) -> float:
        """Load current [mA] (>= 0) at `shaft`: 0 while slack, then preload + stiffness x
        the winding past taut."""
        if dxl_id not in self.taut:
            return 0.0
        past = self.directions.get(dxl_id, 1) * (shaft - self.taut[dxl_id])
        return self.preload + self.stiffness * past if past > 0 else 0.0

    def step(self, motors: Mapping[int, EmulatedMotor], dt: float) -> None:
        for dxl_id, m in motors.items():
            d = self.directions.get(dxl_id, 1)
            if not m.torque_on:
                # Unpowered, the springs unwind the line back to where it is just taut.
                if dxl_id in self.taut and self.load(dxl_id, m.shaft) > 0:
                    m.shaft = self.taut[dxl_id]
                m.velocity, m.moving, m.current = 0.0, False, 0.0
                continue
            start = m.shaft
            reach = m.max_speed * dt
            target = start + max(-reach, min(reach, m.goal_shaft - start))
            if dxl_id in self.taut and d * (target - start) > 0:
                # Winding further stalls once the load reaches the current cap.
                past = max(0.0, (m.current_cap - self.preload) / self.stiffness)
                stall = self.taut[dxl_id] + d * past
                if d * (target - stall) > 0:
                    target = stall if d * (stall - start) > 0 else start
            m.shaft = target
            m.velocity = (target - start) / dt if dt > 0 else 0.0
            m.moving = abs(target - start) > 1e-6
            sign = (m.velocity > 0) - (m.velocity < 0)
            m.current = d * self.load(dxl_id, target) + sign * (self.friction if m.moving else 0)


class Emulator:
    """Motors on a pseudo-terminal, served by a background thread.

    Use as a context manager, or `start()` / `stop()`. `port` is the path to give the SDK.

    Args:
        ids: the motors' ids.
        plant: what moves them (default: a `KinematicPlant` without load).
        shafts: initial shaft angles [ticks] per id (default 2048: mid-turn).
        tick: period of the motion update when the bus is idle [s].
        seed: seeds the draws of lost instructions (`drop_instructions`).
    """

    def __init__(self, ids: Iterable[int], plant: MotorPlant | None = None,
                 shafts: Mapping[int, float] | None = None, tick: float = 0.002,
                 seed: int = 0) -> None:
        shafts = shafts or {}
        self.motors: dict[int, EmulatedMotor] = {
            i: EmulatedMotor(i, shafts.get(i, 2048.0)) for i in ids}
        self.plant: MotorPlant = plant if plant is not None else KinematicPlant()
        self.tick = tick
        self.lock = threading.RLock()
        self.packets_served = 0
        self.dropped = 0  # instruction packets lost on the wire (`drop_instructions`)
        self.watchdog_expiries = 0  # Bus Watchdogs that expired (motors that let go)
        self._rng = random.Random(seed)
        self._late: list[tuple[float, bytes]] = []  # (when, bytes) waiting to be sent
        self._line_free = 0.0  # when the last queued bytes leave: later ones go after them
        self._parser = PacketParser()
        self._master = self._slave = -1
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._last = time.monotonic()
        self.port = ""

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> str:
        """Open the pty and start serving; returns the port path for the SDK."""
        self._master, self._slave = os.openpty()
        # Raw from the start: no echo or line editing before the SDK configures the port.
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._last = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="dxl-emulator", daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1

    def __enter__(self) -> Emulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ----------------------------------------------------------------- inspection and faults
    def register(self, dxl_id: int, reg: Reg) -> int:
        """The value of `reg` on motor `dxl_id`, as the motor holds it now."""
        with self.lock:
            m = self.motors[dxl_id]
            m.sync_present()
            return m.get(reg)

    def torque(self) -> dict[int, bool]:
        """Torque Enable of every motor."""
        with self.lock:
            return {i: m.torque_on for i, m in self.motors.items()}

    def silence(self, dxl_id: int, silent: bool = True) -> None:
        """Make a motor stop (or resume) answering."""
        with self.lock:
            self.motors[dxl_id].faults.silent = silent

    def corrupt(self, dxl_id: int, count: int = 1) -> None:
        """Give the next `count` replies of a motor a bad CRC (-1: all of them)."""
        with self.lock:
            self.motors[dxl_id].faults.corrupt_replies = count

    def inject_hardware_error(self, dxl_id: int, bits: int = HardwareError.OVERLOAD,
                              after_packets: int | None = None) -> None:
        """Raise a hardware error on a motor (default: overload, bit 5 of register 70): now,
        or once `after_packets` more packets have been served."""
        with self.lock:
            m = self.motors[dxl_id]
            if after_packets is None:
                m.fault(int(bits))
            else:
                m.faults.fault_after = self.packets_served + after_packets
                m.faults.fault_bits = int(bits)

    def delay_replies(self, dxl_id: int, seconds: float, count: int = -1) -> None:
        """Send a motor's next `count` replies (-1: all) `seconds` late, in order."""
        with self.lock:
            f = self.motors[dxl_id].faults
            f.reply_delay, f.late_replies = seconds, count

    def drop_instructions(self, dxl_id: int, share: float,
                          only: Iterable[int] | None = None) -> None:
        """Lose this share of the instruction packets meant for a motor (`only`: of these
        instructions, e.g. `Instruction.SYNC_WRITE`)."""
        with self.lock:
            f = self.motors[dxl_id].faults
            f.drop_share = share
            f.drop_only = None if only is None else frozenset(int(i) for i in only)

    def pass_time(self, seconds: float) -> None:
        """Make every motor's Bus Watchdog see `seconds` more without a packet, as if the
        host had been silent that long (a killed process); the plant does not move for it.
        The next service tick expires the watchdogs that this takes past their limit."""
        with self.lock:
            for m in self.motors.values():
                m.heard -= seconds

    # ----------------------------------------------------------------- serving
    def _serve(self) -> None:
        while not self._stop.is_set():
            wait = self.tick
            if self._late:
                wait = max(0.0, min(wait, self._late[0][0] - time.monotonic()))
            try:
                ready, _, _ = select.select([self._master], [], [], wait)
            except (OSError, ValueError):
                return
            data = b""
            if ready:
                try:
                    data = os.read(self._master, 4096)
                except OSError:  # no slave open at the moment (EIO): keep waiting
                    time.sleep(self.tick)
            with self.lock:
                self._advance()
                now = time.monotonic()
                for m in self.motors.values():
                    if m.watchdog(now):
                        self.watchdog_expiries += 1
                self._send_due()
                for packet in self._parser.feed(data) if data else ():
                    reply = self._handle(packet)
                    self.packets_served += 1
                    self._scheduled_faults()
                    if reply:
                        self._send(reply)

    def _send(self, reply: bytes, when: float = 0.0) -> None:
        """Send now, or queue until `when`; bytes never overtake bytes queued before them."""
        if when <= time.monotonic() and not self._late:
            self._write(reply)
            return
        when = max(when, self._line_free)
        self._line_free = when
        self._late.append((when, reply))

    def _send_due(self) -> None:
        now = time.monotonic()
        while self._late and self._late[0][0] <= now:
            self._write(self._late.pop(0)[1])

    def _write(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except OSError:
            pass

    def _scheduled_faults(self) -> None:
        for m in self.motors.values():
            f = m.faults
            if f.fault_after is not None and self.packets_served >= f.fault_after:
                m.fault(f.fault_bits)
                f.fault_after = None

    def _lost(self, m: EmulatedMotor, instruction: int) -> bool:
        """Whether this instruction packet never reaches motor `m` (`drop_instructions`)."""
        f = m.faults
        if f.drop_share <= 0.0 or (f.drop_only is not None and instruction not in f.drop_only):
            return False
        if self._rng.random() < f.drop_share:
            self.dropped += 1
            return True
        return False

    def _advance(self) -> None:
        now = time.monotonic()
        dt, self._last = now - self._last, now
        if dt > 0:
            self.plant.step(self.motors, dt)

    def _status(self, m: EmulatedMotor, number: int = 0, params: bytes = b"") -> bytes:
        """One motor's status packet, or b"" if the motor is silent or its reply is late
        (then it is queued, `_send`)."""
        f = m.faults
        if f.silent:
            return b""
        packet = encode_status(m.dxl_id, m.error_byte(number), params)
        if f.corrupt_replies:
            if f.corrupt_replies > 0:
                f.corrupt_replies -= 1
            packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])
        if f.reply_delay > 0 and f.late_replies != 0:
            if f.late_replies > 0:
                f.late_replies -= 1
            self._send(packet, time.monotonic() + f.reply_delay)
            return b""
        if self._late:  # the line is stalled: wait behind what is queued
            self._send(packet, time.monotonic())
            return b""
        return packet

    def _targets(self, dxl_id: int, instruction: int) -> list[EmulatedMotor]:
        if dxl_id == BROADCAST_ID:
            return [self.motors[i] for i in sorted(self.motors)
                    if not self._lost(self.motors[i], instruction)]
        m = self._by_id(dxl_id)
        return [m] if m and not self._lost(m, instruction) else []

    def _by_id(self, dxl_id: int) -> EmulatedMotor | None:
        for m in self.motors.values():
            if m.dxl_id == dxl_id:  # the id register, which a WRITE to address 7 changes
                return m
        return None

    def _handle(self, p: Packet) -> bytes:
        targets = self._targets(p.dxl_id, p.instruction)
        unicast = p.dxl_id != BROADCAST_ID
        if not p.crc_ok:
            return self._status(targets[0], ERR_CRC) if unicast and targets else b""
        inst, params = p.instruction, p.params
        now = time.monotonic()
        for m in self._addressed(inst, params, targets, unicast):
            m.heard = now  # any instruction packet to a motor feeds its Bus Watchdog
        if inst == Instruction.PING:
            return b"".join(self._status(m, 0, m.get(Reg.MODEL_NUMBER).to_bytes(2, "little")
                                         + bytes([m.get(Reg.FIRMWARE_VERSION)]))
                            for m in targets)
        if inst == Instruction.READ and unicast and targets:
            if len(params) != 4:
                return self._status(targets[0], ERR_DATA_LENGTH)
            number, data = targets[0].read(_u16(params, 0), _u16(params, 2))
            return self._status(targets[0], number, data)
        if inst == Instruction.WRITE:
            if len(params) < 3:
                return self._status(targets[0], ERR_DATA_LENGTH) if unicast and targets else b""
            numbers = [m.write(_u16(params, 0), params[2:]) for m in targets]
            return self._status(targets[0], numbers[0]) if unicast and targets else b""
        if inst == Instruction.REBOOT:
            reply = self._status(targets[0]) if unicast and targets else b""
            for m in targets:
                m.reboot()
            return reply
        if inst in (Instruction.SYNC_READ, Instruction.SYNC_WRITE) and len(params) < 4:
            return b""  # too short to name an address and a length: no motor can answer
        if inst == Instruction.SYNC_READ and not unicast:
            address, length = _u16(params, 0), _u16(params, 2)
            out = []
            for dxl_id in params[4:]:
                m = self._by_id(dxl_id)
                if m is not None and m in targets:
                    number, data = m.read(address, length)
                    out.append(self._status(m, number, data))
            return b"".join(out)
        if inst == Instruction.SYNC_WRITE and not unicast:
            address, length = _u16(params, 0), _u16(params, 2)
            body = params[4:]
            for k in range(0, len(body) - length, length + 1):
                m = self._by_id(body[k])
                if m is not None and m in targets:
                    m.write(address, body[k + 1: k + 1 + length])  # no status: broadcast
            return b""
        if inst == Instruction.BULK_READ and not unicast:
            out = []
            for k in range(0, len(params) - 4, 5):
                m = self._by_id(params[k])
                if m is not None and m in targets:
                    number, data = m.read(_u16(params, k + 1), _u16(params, k + 3))
                    out.append(self._status(m, number, data))
            return b"".join(out)
        # REG_WRITE/ACTION, FACTORY_RESET, fast sync read etc. are not emulated.
        return self._status(targets[0], ERR_INSTRUCTION) if unicast and targets else b""


    def _addressed(self, inst: int, params: bytes, targets: list[EmulatedMotor],
                   unicast: bool) -> list[EmulatedMotor]:
        """The motors a packet is addressed to: its target, every motor for a broadcast,
        only the listed ones for a sync or bulk packet."""
        if unicast or inst not in (Instruction.SYNC_READ, Instruction.SYNC_WRITE,
                                   Instruction.BULK_READ):
            return targets
        if len(params) < 4:
            return []
        if inst == Instruction.SYNC_READ:
            ids = set(params[4:])
        elif inst == Instruction.SYNC_WRITE:
            length = _u16(params, 2)
            ids = set(params[4::length + 1])
        else:
            ids = set(params[0::5])
        return [m for m in targets if m.dxl_id in ids]


def _u16(data: bytes, offset: int) -> int:
    return data[offset] | (data[offset + 1] << 8)
