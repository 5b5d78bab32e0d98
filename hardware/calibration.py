"""Tendon zero calibration: find each motor's position at u = 0 (line taut, hand open).

Procedure (all fingers at once, current-based position mode, so a probe can never pull hard):

1. Goal Current = `current_ma`; unwind `backoff` so every line starts slack.
2. Wind by `probe_step`, wait until the motors stop, read the present current; a finger whose
   |current| reaches `taut_current_ma` has a taut line: its present position is its zero.
3. Give up with `CalibrationError` naming the finger after `max_travel` of winding.

The result goes into the config as `fingers.<slot>.zero` for later runs (printed by the
backend), so the probe is needed only after re-stringing a tendon.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from vlr.hardware.bus import HardwareError, MotorBus
from vlr.hardware.config import CalibrationConfig, FingerMotor
from vlr.hardware.control_table import CURRENT_UNIT_MA, TICKS_PER_REV, Reg
from vlr.hardware.tendons import read_motion, wait_until_stopped


class CalibrationError(HardwareError):
    """A tendon never became taut (or the probe could not run)."""


def find_zeros(bus: MotorBus, fingers: Sequence[FingerMotor], cfg: CalibrationConfig,
               spool_radius: float, *, settle_timeout: float = 2.0,
               log: Callable[[str], None] = print) -> dict[str, int]:
    """Probe each finger's zero [ticks]; the motors must be in current-based position mode
    with torque on. Returns {slot: zero ticks}."""
    per_metre = TICKS_PER_REV / (2.0 * math.pi * spool_radius)
    probe = max(1, int(round(cfg.probe_step * per_metre)))
    ids = [f.id for f in fingers]
    goal_current = int(round(cfg.current_ma / CURRENT_UNIT_MA))
    for f in fingers:
        bus.write(Reg.GOAL_CURRENT, f.id, goal_current)

    start = read_motion(bus, ids, CURRENT_UNIT_MA).position
    goals = {f.id: start[f.id] - f.direction * int(round(cfg.backoff * per_metre))
             for f in fingers}
    bus.sync_write(Reg.GOAL_POSITION, goals)
    wait_until_stopped(bus, ids, settle_timeout, 1, CURRENT_UNIT_MA)

    zeros: dict[str, int] = {}
    wound = 0
    limit = int(math.ceil((cfg.max_travel + cfg.backoff) * per_metre))
    while len(zeros) < len(fingers):
        pending = [f for f in fingers if f.slot not in zeros]
        if wound > limit:
            names = ", ".join(f"{f.slot} (motor {f.id})" for f in pending)
            raise CalibrationError(
                f"tendon calibration: the line of {names} never became taut within "
                f"{cfg.max_travel * 1e3:.1f} mm of winding (|current| stayed below "
                f"{cfg.taut_current_ma} mA): check the tendon is attached and the motor's "
                "direction in the config")
        for f in pending:
            goals[f.id] += f.direction * probe
        bus.sync_write(Reg.GOAL_POSITION, {f.id: goals[f.id] for f in pending})
        wound += probe
        _, state = wait_until_stopped(bus, [f.id for f in pending], settle_timeout, 1,
                                      CURRENT_UNIT_MA)
        for f in pending:
            if abs(state.current_ma[f.id]) >= cfg.taut_current_ma:
                zeros[f.slot] = state.position[f.id]
                goals[f.id] = state.position[f.id]
                log(f"calibration: {f.slot} (motor {f.id}) taut at {state.position[f.id]} "
                    f"ticks ({state.current_ma[f.id]:.0f} mA)")
    # Rest at u = 0 exactly, where the line is just taut.
    bus.sync_write(Reg.GOAL_POSITION, {f.id: zeros[f.slot] for f in fingers})
    wait_until_stopped(bus, ids, settle_timeout, 1, CURRENT_UNIT_MA)
    return zeros
