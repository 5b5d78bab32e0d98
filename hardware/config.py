"""The hardware configuration: one YAML file, read once into a frozen dataclass.

See `hardware/example_config.yaml` for every key with its unit, and hardware/README.md.
`load_config(path)` raises `HardwareConfigError` (a ValueError, via vlr's SpecError) naming
the file and the bad key; unknown keys are errors too, so a typo cannot silently fall back to
a default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from vlr.hardware.control_table import (
    EXTENDED_POSITION_LIMIT,
    SDK_BAUD_RATES,
    WATCHDOG_MAX,
    WATCHDOG_UNIT_MS,
    OperatingMode,
)

from vlr.spec import SpecError, load_hand, load_object, load_yaml_mapping

#: `bus.port` value that runs the bus against an in-process emulator (a dry run).
EMULATOR_PORT = "emulator"

FAKE_CAMERAS = ("blank", "sim")

#: The shortest Bus Watchdog accepted [ms]: a transaction retried after timeouts may take
#: tens of milliseconds, and the keep-alive reads at a quarter of the watchdog.
MIN_WATCHDOG_MS = 200
PLANTS = ("kinematic", "sim")
RUN_MODES = {"extended_position": OperatingMode.EXTENDED_POSITION,
             "current_based_position": OperatingMode.CURRENT_BASED_POSITION}


class HardwareConfigError(SpecError):
    """The hardware config file is invalid; the message names the file and the key."""


@dataclass(frozen=True)
class BusConfig:
    """Serial bus. port: device path or "emulator"; baud [bit/s]; latency_ms: USB latency
    budget per packet timeout [ms]; retries: extra tries per failed transaction;
    watchdog_ms: each motor's Bus Watchdog (98) while its torque is on [ms, a multiple of
    20]: a motor that hears no instruction packet for this long stops (a killed host); 0
    leaves it off."""

    port: str
    baud: int = 57_600
    protocol: int = 2
    latency_ms: float = 16.0
    retries: int = 2
    watchdog_ms: int = 2000

    @property
    def watchdog(self) -> int:
        """`watchdog_ms` in register 98's units of 20 ms."""
        return self.watchdog_ms // WATCHDOG_UNIT_MS


@dataclass(frozen=True)
class FingerMotor:
    """The tendon motor of one finger slot.

    direction: +1 if increasing motor ticks pulls (shortens) the tendon, else -1.
    zero: stored calibration, the motor position [ticks] at u = 0 (taut line, open hand);
        None means: find it at start-up by winding until the line is taut.
    """

    slot: str
    id: int
    direction: int = 1
    zero: int | None = None


@dataclass(frozen=True)
class SpreadMotor:
    """The abduction (spread) motor, held at `position` [ticks] for the whole run."""

    id: int
    position: int


@dataclass(frozen=True)
class TendonMotion:
    """How tendons move.

    mode: run-time operating mode (extended position 4, or current-based position 5).
    current_limit_ma: motor current cap [mA] (Goal Current in mode 5; Current Limit always).
    profile_velocity_rpm: speed of a move [rev/min] (0: the motor's maximum).
    spool_radius: tendon spool radius [m]; u = radius * angle.
    max_step: largest tendon change per `apply` [m] (vlr.hand.check_delta).
    range: (lo, hi) absolute tendon command range [m]; commands are clipped to it.
    ramp_steps: goal positions per move (a ramp, not a jump).
    ramp_period: time between ramp steps [s].
    settle_timeout: longest wait for the motors to stop after a move [s].
    settle_ticks: a motor whose position changes less than this between reads has stopped.
    """

    spool_radius: float
    max_step: float
    range: tuple[float, float]
    mode: OperatingMode = OperatingMode.CURRENT_BASED_POSITION
    current_limit_ma: float = 600.0
    profile_velocity_rpm: float = 20.0
    ramp_steps: int = 5
    ramp_period: float = 0.02
    settle_timeout: float = 2.0
    settle_ticks: int = 2


@dataclass(frozen=True)
class CalibrationConfig:
    """Finding u = 0 by winding until the line is taut (current-based position mode).

    current_ma: Goal Current while probing [mA]; taut_current_ma: |present current| that
    means taut [mA]; probe_step: tendon wound per probe [m]; backoff: tendon unwound first,
    so the probe starts slack [m]; max_travel: give up after winding this much [m].
    """

    current_ma: float = 120.0
    taut_current_ma: float = 40.0
    probe_step: float = 0.0002
    backoff: float = 0.002
    max_travel: float = 0.03


@dataclass(frozen=True)
class TensionConfig:
    """Tendon tension from each finger motor's present current once the motors stop,
    T = newton_per_ma x (direction x current - zero_ma), at least 0 (`ApplyReport.tensions`; the
    likelihood weighs them with `vlr identify --set filter.observation.sigma_tension_n=N`).
    Both numbers come from the user's own calibration against a load cell in the line: the
    gearbox's friction makes a servo's current a rough tension sensor, and nothing here has
    been measured on a real hand (docs/RESULTS.md, "A second sensor").

    newton_per_ma: tendon tension per mA of present current [N/mA] (about 0.18 for an XM430
    on a 10 mm spool, from its torque constant, before gear losses); zero_ma: the present
    current at zero tension, per finger in hand slot order [mA].
    """

    newton_per_ma: float
    zero_ma: tuple[float, ...]


@dataclass(frozen=True)
class GraspConfig:
    """commands: tendon commands u of a grasp [m], one per finger (hand slot order);
    check_tag: the grasp holds while the object's tag is seen (False: unknown, so True)."""

    commands: tuple[float, ...]
    check_tag: bool = True


@dataclass(frozen=True)
class CameraConfig:
    """index: OpenCV device index; fake: "blank" or "sim" instead of a device; calibration:
    camera calibration YAML (vlr.camera.load_calibration); None only with fake "sim";
    max_missing_frames: this many reads in a row without a frame stop the run (torque off),
    so that a dead camera is never taken for a held grasp."""

    index: int | None = None
    fake: str | None = None
    calibration: Path | None = None
    max_missing_frames: int = 3


@dataclass(frozen=True)
class EmulatorConfig:
    """For dry runs (`vlr emulate`, or bus.port "emulator"). plant: "kinematic" (motors
    wind a line that goes taut after `slack` [m]) or "sim" (the MuJoCo hand, sim/backend.py)."""

    plant: str = "kinematic"
    slack: float = 0.003


@dataclass(frozen=True)
class HardwareConfig:
    """Everything the hardware backend needs; `path` is the file it came from."""

    path: Path
    hand: str
    object: str
    bus: BusConfig
    fingers: tuple[FingerMotor, ...]
    motion: TendonMotion
    grasp: GraspConfig
    camera: CameraConfig
    spread: SpreadMotor | None = None
    calibration: CalibrationConfig = CalibrationConfig()
    emulator: EmulatorConfig = EmulatorConfig()
    tension: TensionConfig | None = None

    @property
    def ids(self) -> tuple[int, ...]:
        """Every motor id: fingers in slot order, then the spread motor."""
        extra = (self.spread.id,) if self.spread else ()
        return tuple(f.id for f in self.fingers) + extra

    @property
    def labels(self) -> dict[int, str]:
        out = {f.id: f.slot for f in self.fingers}
        if self.spread:
            out[self.spread.id] = "spread"
        return out


# --------------------------------------------------------------------------- loading

class _Section:
    """Typed access to one mapping of the file, with errors naming file and key."""

    def __init__(self, data: Any, where: str, path: Path) -> None:
        self.path, self.where = path, where
        if not isinstance(data, dict):
            self.fail(where or "the file", data, "must be a mapping")
        self.data: dict[str, Any] = data
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.where}.{name}" if self.where else name

    def fail(self, key: str, value: Any, why: str) -> NoReturn:
        raise HardwareConfigError(f"{self.path}: {key} = {value!r} {why}")

    def get(self, name: str, default: Any = ...) -> Any:
        self.used.add(name)
        if name not in self.data:
            if default is ...:
                raise HardwareConfigError(f"{self.path}: missing key {self.key(name)!r}")
            return default
        return self.data[name]

    def number(self, name: str, default: Any = ..., lo: float | None = None,
               hi: float | None = None, strict_lo: bool = False) -> float:
        value = self.get(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
                value):
            self.fail(self.key(name), value, "must be a finite number")
        if lo is not None and (value <= lo if strict_lo else value < lo):
            self.fail(self.key(name), value, f"must be {'>' if strict_lo else '>='} {lo}")
        if hi is not None and value > hi:
            self.fail(self.key(name), value, f"must be <= {hi}")
        return float(value)

    def integer(self, name: str, default: Any = ..., lo: int | None = None,
                hi: int | None = None, allow_none: bool = False) -> int | None:
        value = self.get(name, default)
        if value is None and allow_none:
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(self.key(name), value, "must be an integer")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            self.fail(self.key(name), value, f"must be in [{lo}, {hi}]")
        return value

    def string(self, name: str, default: Any = ..., choices: tuple[str, ...] = ()) -> str:
        value = self.get(name, default)
        if not isinstance(value, str) or not value:
            self.fail(self.key(name), value, "must be a non-empty string")
        if choices and value not in choices:
            self.fail(self.key(name), value, f"must be one of {', '.join(choices)}")
        return value

    def boolean(self, name: str, default: Any = ...) -> bool:
        value = self.get(name, default)
        if not isinstance(value, bool):
            self.fail(self.key(name), value, "must be true or false")
        return value

    def numbers(self, name: str, n: int) -> tuple[float, ...]:
        value = self.get(name)
        if (not isinstance(value, (list, tuple)) or len(value) != n or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                for v in value)):
            self.fail(self.key(name), value, f"must be a list of {n} finite numbers")
        return tuple(float(v) for v in value)

    def section(self, name: str, optional: bool = False) -> _Section | None:
        value = self.get(name, None if optional else ...)
        if value is None and optional:
            return None
        return _Section(value, self.key(name), self.path)

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used))
            raise HardwareConfigError(f"{self.path}: unknown key {self.key(unknown[0])!r} "
                                      f"(known here: {known})")


def load_config(path: str | Path) -> HardwareConfig:
    """Read and validate a hardware config YAML file."""
    path = Path(path)
    data = load_yaml_mapping(path, "hardware config file", HardwareConfigError)
    top = _Section(data, "", path)
    base = path.parent

    hand_name = top.string("hand", "modelo")
    try:
        hand = load_hand(_maybe_relative(hand_name, base))
    except SpecError as exc:
        raise HardwareConfigError(f"{path}: hand = {hand_name!r}: {exc}") from None
    object_name = _maybe_relative(top.string("object"), base)
    try:
        load_object(object_name)
    except SpecError as exc:
        raise HardwareConfigError(f"{path}: object = {object_name!r}: {exc}") from None

    bus = _bus(top.section("bus"))
    fingers = _fingers(top.section("fingers"), hand.finger_names)
    spread = _spread(top.section("spread", optional=True))
    motion = _motion(top.section("motion"))
    lo, hi = motion.range
    grasp_s = top.section("grasp")
    commands = grasp_s.numbers("commands", len(fingers))
    for slot, u in zip(hand.finger_names, commands, strict=True):
        if not lo <= u <= hi:
            grasp_s.fail(grasp_s.key("commands"), list(commands),
                         f"has {slot} = {u} m outside motion.range [{lo}, {hi}]")
    grasp = GraspConfig(commands=commands, check_tag=grasp_s.boolean("check_tag", True))
    grasp_s.done()
    camera = _camera(top.section("camera"), base)
    calibration = _calibration(top.section("calibration", optional=True))
    emulator = _emulator(top.section("emulator", optional=True))
    tension = _tension(top.section("tension", optional=True), len(fingers))
    top.done()

    ids = [f.id for f in fingers] + ([spread.id] if spread else [])
    if len(set(ids)) != len(ids):
        raise HardwareConfigError(f"{path}: motor ids {ids} (fingers, spread) must be distinct")
    if calibration.current_ma > motion.current_limit_ma:
        raise HardwareConfigError(f"{path}: calibration.current_ma = {calibration.current_ma} "
                                  f"must not exceed motion.current_limit_ma = "
                                  f"{motion.current_limit_ma} (the motors' Current Limit)")
    if camera.fake == "sim" and (emulator.plant != "sim" or bus.port != EMULATOR_PORT):
        raise HardwareConfigError(f"{path}: camera.fake = 'sim' needs bus.port = "
                                  f"'{EMULATOR_PORT}' and emulator.plant = 'sim' (the frames "
                                  "come from the simulated hand in this process)")
    return HardwareConfig(path=path, hand=str(hand_name), object=object_name, bus=bus,
                          fingers=fingers, motion=motion, grasp=grasp, camera=camera,
                          spread=spread, calibration=calibration, emulator=emulator,
                          tension=tension)


def _maybe_relative(name: str, base: Path) -> str:
    """A spec path relative to the config file; a bare name stays a name."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") and not p.is_absolute():
        return str((base / p).resolve())
    return name


def _bus(s: _Section) -> BusConfig:
    port = s.string("port")
    baud = s.integer("baud", 57_600)
    if baud not in SDK_BAUD_RATES:
        s.fail(s.key("baud"), baud, f"is not a baud rate the DYNAMIXEL SDK supports "
               f"({', '.join(map(str, SDK_BAUD_RATES))})")
    protocol = s.get("protocol", 2)
    if protocol not in (2, 2.0):
        s.fail(s.key("protocol"), protocol, "is not supported: only Protocol 2.0 (X series) "
               "is implemented")
    watchdog_ms = s.integer("watchdog_ms", 2000, lo=0, hi=WATCHDOG_MAX * WATCHDOG_UNIT_MS)
    if watchdog_ms and (watchdog_ms % WATCHDOG_UNIT_MS or watchdog_ms < MIN_WATCHDOG_MS):
        s.fail(s.key("watchdog_ms"), watchdog_ms, f"must be 0 (off) or a multiple of "
               f"{WATCHDOG_UNIT_MS} ms from {MIN_WATCHDOG_MS} to "
               f"{WATCHDOG_MAX * WATCHDOG_UNIT_MS} (register 98's unit and range)")
    out = BusConfig(port=port, baud=baud, protocol=2,
                    latency_ms=s.number("latency_ms", 16.0, lo=0.0),
                    retries=s.integer("retries", 2, lo=0, hi=10), watchdog_ms=watchdog_ms)
    s.done()
    return out


def _motor_id(s: _Section, name: str = "id") -> int:
    return s.integer(name, lo=0, hi=252)


def _fingers(s: _Section, slots: tuple[str, ...]) -> tuple[FingerMotor, ...]:
    missing = [slot for slot in slots if slot not in s.data]
    if missing:
        raise HardwareConfigError(f"{s.path}: fingers has no entry for slot {missing[0]!r}; "
                                  f"the hand's slots are {', '.join(slots)}")
    out = []
    for slot in slots:
        f = s.section(slot)
        direction = f.integer("direction", 1)
        if direction not in (1, -1):
            f.fail(f.key("direction"), direction, "must be 1 or -1")
        out.append(FingerMotor(slot=slot, id=_motor_id(f), direction=direction,
                               zero=f.integer("zero", None, lo=-EXTENDED_POSITION_LIMIT,
                                              hi=EXTENDED_POSITION_LIMIT, allow_none=True)))
        f.done()
    s.done()
    return tuple(out)


def _spread(s: _Section | None) -> SpreadMotor | None:
    if s is None:
        return None
    out = SpreadMotor(id=_motor_id(s), position=s.integer("position", lo=0, hi=4095))
    s.done()
    return out


def _motion(s: _Section) -> TendonMotion:
    mode_name = s.string("mode", "current_based_position", tuple(RUN_MODES))
    rng = s.numbers("range", 2)
    if not rng[0] < rng[1]:
        s.fail(s.key("range"), list(rng), "must be [lo, hi] with lo < hi")
    out = TendonMotion(
        spool_radius=s.number("spool_radius", lo=0.0, hi=0.1, strict_lo=True),
        max_step=s.number("max_step", lo=0.0, hi=0.05, strict_lo=True),
        range=(rng[0], rng[1]),
        mode=RUN_MODES[mode_name],
        current_limit_ma=s.number("current_limit_ma", 600.0, lo=0.0, strict_lo=True),
        profile_velocity_rpm=s.number("profile_velocity_rpm", 20.0, lo=0.0),
        ramp_steps=int(s.integer("ramp_steps", 5, lo=1, hi=1000)),
        ramp_period=s.number("ramp_period", 0.02, lo=0.0, hi=1.0),
        settle_timeout=s.number("settle_timeout", 2.0, lo=0.0, strict_lo=True),
        settle_ticks=int(s.integer("settle_ticks", 2, lo=0)),
    )
    s.done()
    return out


def _camera(s: _Section, base: Path) -> CameraConfig:
    index = s.integer("index", None, lo=0, allow_none=True)
    fake = s.get("fake", None)
    if fake is not None:
        fake = s.string("fake", choices=FAKE_CAMERAS)
    if (index is None) == (fake is None):
        raise HardwareConfigError(f"{s.path}: camera needs exactly one of 'index' (an OpenCV "
                                  f"device) or 'fake' ({', '.join(FAKE_CAMERAS)})")
    calib = s.get("calibration", None)
    calibration = None
    if calib is not None:
        calibration = Path(s.string("calibration"))
        if not calibration.is_absolute():
            calibration = (base / calibration).resolve()
        if not calibration.is_file():
            s.fail(s.key("calibration"), str(calib), f"does not exist ({calibration})")
    elif fake != "sim":
        raise HardwareConfigError(f"{s.path}: missing key 'camera.calibration' (the camera "
                                  "calibration YAML; only camera.fake = 'sim' brings its own)")
    missing = s.integer("max_missing_frames", 3, lo=1, hi=1000)
    s.done()
    return CameraConfig(index=index, fake=fake, calibration=calibration,
                        max_missing_frames=missing)


def _calibration(s: _Section | None) -> CalibrationConfig:
    if s is None:
        return CalibrationConfig()
    out = CalibrationConfig(
        current_ma=s.number("current_ma", 120.0, lo=0.0, strict_lo=True),
        taut_current_ma=s.number("taut_current_ma", 40.0, lo=0.0, strict_lo=True),
        probe_step=s.number("probe_step", 0.0002, lo=0.0, hi=0.005, strict_lo=True),
        backoff=s.number("backoff", 0.002, lo=0.0, hi=0.05),
        max_travel=s.number("max_travel", 0.03, lo=0.0, hi=0.2, strict_lo=True),
    )
    if out.taut_current_ma >= out.current_ma:
        s.fail(s.key("taut_current_ma"), out.taut_current_ma,
               f"must be below calibration.current_ma = {out.current_ma} (the probe could "
               "never reach it)")
    s.done()
    return out


def _tension(s: _Section | None, n_fingers: int) -> TensionConfig | None:
    if s is None:
        return None
    out = TensionConfig(newton_per_ma=s.number("newton_per_ma", lo=0.0, hi=10.0,
                                                strict_lo=True),
                        zero_ma=s.numbers("zero_ma", n_fingers))
    s.done()
    return out


def _emulator(s: _Section | None) -> EmulatorConfig:
    if s is None:
        return EmulatorConfig()
    out = EmulatorConfig(plant=s.string("plant", "kinematic", PLANTS),
                         slack=s.number("slack", 0.003, lo=0.0, hi=0.05))
    s.done()
    return out
