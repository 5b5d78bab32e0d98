"""The DYNAMIXEL X-series (Protocol 2.0) control table, as data.

Source: ROBOTIS e-manual, XM430-W350,
https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/#control-table
(the XM430-W210, XM540 and XH430 share these addresses and sizes).

Registers are members of an Enum, never free strings, so that a typo fails at import time and
the bus, the backend and the emulator all read addresses from this one table.
"""

from __future__ import annotations

from enum import Enum, IntEnum, IntFlag

#: Baud rates the SDK accepts (it refuses others before touching the port); here, so that a
#: config is checked without the SDK installed.
SDK_BAUD_RATES = (9_600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 500_000, 576_000,
                  921_600, 1_000_000, 1_152_000, 2_000_000, 2_500_000, 3_000_000, 3_500_000,
                  4_000_000)

MANUAL_URL = "https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/#control-table"

#: Addresses below this are EEPROM: writable only while torque is off (access error 7).
EEPROM_END = 64

#: Encoder resolution [ticks per revolution] of the X series.
TICKS_PER_REV = 4096

#: Unit of Current Limit (38), Goal Current (102) and Present Current (126) on the XM430 [mA].
CURRENT_UNIT_MA = 2.69

#: Unit of Profile Velocity (112) and Present Velocity (128) [rev/min].
VELOCITY_UNIT_RPM = 0.229

#: Goal Position range in extended position mode [ticks] (+-256 revolutions).
EXTENDED_POSITION_LIMIT = 1_048_575

#: Unit of Bus Watchdog (98) [ms]; 1..127 arms it, 0 disarms it (and clears its error), and
#: the motor sets it to -1 when it expires (firmware v38 and later).
WATCHDOG_UNIT_MS = 20
WATCHDOG_MAX = 127
WATCHDOG_EXPIRED = -1

#: Model numbers read at address 0, for messages and for the emulator's default.
MODEL_NUMBERS: dict[int, str] = {
    1020: "XM430-W350",
    1030: "XM430-W210",
    1120: "XM540-W270",
    1130: "XM540-W150",
    1000: "XH430-W350",
    1010: "XH430-W210",
}


class Reg(Enum):
    """One register: (address, size in bytes, signed)."""

    MODEL_NUMBER = (0, 2, False)
    FIRMWARE_VERSION = (6, 1, False)
    ID = (7, 1, False)
    BAUD_RATE = (8, 1, False)
    RETURN_DELAY_TIME = (9, 1, False)
    DRIVE_MODE = (10, 1, False)
    OPERATING_MODE = (11, 1, False)
    HOMING_OFFSET = (20, 4, True)
    MOVING_THRESHOLD = (24, 4, False)
    TEMPERATURE_LIMIT = (31, 1, False)
    CURRENT_LIMIT = (38, 2, False)
    VELOCITY_LIMIT = (44, 4, False)
    MAX_POSITION_LIMIT = (48, 4, False)
    MIN_POSITION_LIMIT = (52, 4, False)
    SHUTDOWN = (63, 1, False)
    TORQUE_ENABLE = (64, 1, False)
    LED = (65, 1, False)
    STATUS_RETURN_LEVEL = (68, 1, False)
    HARDWARE_ERROR_STATUS = (70, 1, False)
    POSITION_P_GAIN = (84, 2, False)
    BUS_WATCHDOG = (98, 1, True)
    GOAL_PWM = (100, 2, True)
    GOAL_CURRENT = (102, 2, True)
    GOAL_VELOCITY = (104, 4, True)
    PROFILE_ACCELERATION = (108, 4, False)
    PROFILE_VELOCITY = (112, 4, False)
    GOAL_POSITION = (116, 4, True)
    MOVING = (122, 1, False)
    MOVING_STATUS = (123, 1, False)
    PRESENT_PWM = (124, 2, True)
    PRESENT_CURRENT = (126, 2, True)
    PRESENT_VELOCITY = (128, 4, True)
    PRESENT_POSITION = (132, 4, True)
    PRESENT_INPUT_VOLTAGE = (144, 2, False)
    PRESENT_TEMPERATURE = (146, 1, False)

    @property
    def address(self) -> int:
        return self.value[0]

    @property
    def size(self) -> int:
        return self.value[1]

    @property
    def signed(self) -> bool:
        return self.value[2]

    @property
    def eeprom(self) -> bool:
        """True if the register lives in EEPROM (writable only with torque off)."""
        return self.address < EEPROM_END

    def encode(self, value: int) -> bytes:
        """Little-endian bytes of `value`, as the device stores it."""
        return int(value).to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes | bytearray | list[int]) -> int:
        """The register's value from its little-endian bytes."""
        return int.from_bytes(bytes(data[: self.size]), "little", signed=self.signed)


#: Read-only registers of the RAM area (a write gets access error 7).
READ_ONLY = frozenset({
    Reg.MODEL_NUMBER, Reg.FIRMWARE_VERSION, Reg.HARDWARE_ERROR_STATUS, Reg.MOVING,
    Reg.MOVING_STATUS, Reg.PRESENT_PWM, Reg.PRESENT_CURRENT, Reg.PRESENT_VELOCITY,
    Reg.PRESENT_POSITION, Reg.PRESENT_INPUT_VOLTAGE, Reg.PRESENT_TEMPERATURE,
})


#: The goal registers a motor makes read-only while its Bus Watchdog has expired: a write gets
#: data range error 4 until 98 is written 0 (e-manual, "Bus Watchdog(98)").
WATCHDOG_LOCKED = frozenset({Reg.GOAL_PWM, Reg.GOAL_CURRENT, Reg.GOAL_VELOCITY,
                             Reg.GOAL_POSITION})


class OperatingMode(IntEnum):
    """Values of Operating Mode (11)."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


#: Baud Rate (8) register values -> bits per second.
BAUD_RATES: dict[int, int] = {
    0: 9_600, 1: 57_600, 2: 115_200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000,
    6: 4_000_000, 7: 4_500_000,
}


class HardwareError(IntFlag):
    """Bits of Hardware Error Status (70). Any of them disables torque until REBOOT."""

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


_HARDWARE_ERROR_TEXT = {
    HardwareError.INPUT_VOLTAGE: "input voltage out of range",
    HardwareError.OVERHEATING: "overheating",
    HardwareError.MOTOR_ENCODER: "motor encoder error",
    HardwareError.ELECTRICAL_SHOCK: "electrical shock (or insufficient power)",
    HardwareError.OVERLOAD: "overload (persistent load above the motor's limit)",
}


def describe_hardware_error(bits: int) -> str:
    """Human-readable decoding of Hardware Error Status (70), e.g. "bit 5 overload (...)"."""
    parts = [f"bit {flag.value.bit_length() - 1} {text}"
             for flag, text in _HARDWARE_ERROR_TEXT.items() if bits & flag]
    unknown = bits & ~sum(_HARDWARE_ERROR_TEXT)
    if unknown:
        parts.append(f"unknown bits 0x{unknown:02X}")
    return ", ".join(parts) if parts else "no error"


#: Status packet error byte (Protocol 2.0): bit 7 is the alert bit, bits 0-6 an error number.
ALERT_BIT = 0x80

STATUS_ERRORS: dict[int, str] = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}


def describe_status_error(error: int) -> str:
    """Decoding of a status packet's error byte, e.g. "access error" or "alert"."""
    parts = []
    if error & ALERT_BIT:
        parts.append("alert (hardware error status set)")
    number = error & 0x7F
    if number:
        parts.append(STATUS_ERRORS.get(number, f"error number {number}"))
    return ", ".join(parts) if parts else "no error"
