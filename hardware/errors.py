"""The real hand's base error, apart from the motor bus so that the parts that never touch
the DYNAMIXEL SDK (the camera, the config, the emulator) load without it."""

from __future__ import annotations

from vlr.errors import UserError


class HardwareError(UserError):
    """A hardware problem the user can fix (port, cable, power, motor id, motor fault)."""
