"""Tendon length <-> motor position, and waiting for motors to stop.

A tendon wound on a spool of radius r shortens by r * angle, so a command u [m] (the pull from
the calibrated open-hand zero, vlr/spec.py) sits at

    ticks = zero + direction * u / r * TICKS_PER_REV / (2 pi)

where `zero` is the motor position at u = 0 (line just taut, hand open) and `direction` is +1
when increasing ticks pulls the tendon.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from vlr.hardware.bus import MotorBus
from vlr.hardware.control_table import TICKS_PER_REV, Reg


@dataclass(frozen=True)
class TendonMap:
    """Spool geometry of the finger motors, in hand slot order.

    Attributes:
        zeros: motor position at u = 0 [ticks], per finger.
        directions: +1 or -1 per finger (+1: increasing ticks pulls the tendon).
        spool_radius: [m].
    """

    zeros: tuple[int, ...]
    directions: tuple[int, ...]
    spool_radius: float

    @property
    def ticks_per_metre(self) -> float:
        return TICKS_PER_REV / (2.0 * math.pi * self.spool_radius)

    def ticks(self, u: np.ndarray) -> list[int]:
        """Goal positions [ticks] for tendon commands u [m]."""
        u = np.asarray(u, dtype=float)
        return [int(round(z + d * ui * self.ticks_per_metre))
                for z, d, ui in zip(self.zeros, self.directions, u, strict=True)]

    def commands(self, ticks: Sequence[int]) -> np.ndarray:
        """Tendon commands u [m] at motor positions `ticks`."""
        return np.array([d * (t - z) / self.ticks_per_metre
                         for z, d, t in zip(self.zeros, self.directions, ticks, strict=True)])


def resolve_zero(stored: int, present: int, direction: int, spool_radius: float,
                 u_range: tuple[float, float]) -> int:
    """The stored zero shifted by whole turns to match the motor's present turn count.

    An X-series motor forgets whole turns at power-up (present position reads within one
    turn), so a zero stored before a power cycle is only known modulo 4096 ticks. Choose the
    shift that puts the present tendon command closest to the allowed range.
    """
    per_metre = TICKS_PER_REV / (2.0 * math.pi * spool_radius)
    lo, hi = u_range

    def distance(zero: int) -> float:
        u = direction * (present - zero) / per_metre
        return max(lo - u, 0.0, u - hi)

    base = stored + TICKS_PER_REV * round((present - stored) / TICKS_PER_REV)
    return min((base + k * TICKS_PER_REV for k in (-1, 0, 1)), key=lambda z: (distance(z),
                                                                              abs(z - present)))


@dataclass(frozen=True)
class MotionState:
    """One reading of the motors: per id, Goal Position (116), Moving (122), current [mA],
    Present Position (132)."""

    goal: dict[int, int]
    moving: dict[int, bool]
    current_ma: dict[int, float]
    position: dict[int, int]


MOTION_REGS = (Reg.GOAL_POSITION, Reg.MOVING, Reg.PRESENT_CURRENT, Reg.PRESENT_POSITION)


def read_motion(bus: MotorBus, ids: Sequence[int], current_unit_ma: float) -> MotionState:
    """Goal, Moving, present current and present position of `ids`, in one sync read
    (116..135). Every reply's status byte is checked (`MotorBus.check_status`), so a fault
    on any motor read raises."""
    values = bus.sync_read(MOTION_REGS, ids)
    return MotionState(
        goal={i: v[Reg.GOAL_POSITION] for i, v in values.items()},
        moving={i: bool(v[Reg.MOVING]) for i, v in values.items()},
        current_ma={i: v[Reg.PRESENT_CURRENT] * current_unit_ma for i, v in values.items()},
        position={i: v[Reg.PRESENT_POSITION] for i, v in values.items()},
    )


def wait_until_stopped(bus: MotorBus, ids: Sequence[int], timeout: float, settle_ticks: int,
                       current_unit_ma: float, period: float = 0.005,
                       watch: Sequence[int] = ()) -> tuple[bool, MotionState]:
    """Poll until every motor of `ids` has stopped, at most `timeout` seconds; the motors of
    `watch` are read with them (their status bytes checked) but not waited for.

    Stopped means Moving (122) is 0 AND the position changed by at most `settle_ticks` since
    the previous reading. Both, because a sync write has no reply: right after it a motor may
    not have started yet and still read Moving = 0; and a motor stalled against a load (in
    current-based position mode) never reaches its goal but does stop. Every reading checks
    the status error bytes, so a motor fault ends the wait with `MotorFaultError`.

    Returns (stopped, last reading).
    """
    deadline = time.monotonic() + timeout
    read = list(ids) + [i for i in watch if i not in ids]
    previous = read_motion(bus, read, current_unit_ma)
    while True:
        time.sleep(period)
        state = read_motion(bus, read, current_unit_ma)
        still = all(not state.moving[i] and abs(state.position[i] - previous.position[i])
                    <= settle_ticks for i in ids)
        if still:
            return True, state
        if time.monotonic() > deadline:
            return False, state
        previous = state
