"""The real Yale OpenHand Model O behind `vlr.hand.Hand` (`--backend hardware`).

One DYNAMIXEL X-series motor per finger winds that finger's tendon on a spool; an optional
spread motor is held at a fixed position (the paper keeps the spread fixed, docs/METHOD.md 1).

Safety, in order of defence:

* Commands: `check_delta` (finite, one per finger, |delta| <= motion.max_step), then clipping
  to motion.range; moves are ramped; the current is capped (Current Limit, and Goal Current
  in current-based position mode).
* Every motor of the config, the spread motor included, is read on every ramp step and every
  settle poll: a hardware error (the alert bit) or a silent motor stops the run.
* Every move is verified once the motors stop: each motor's Goal Position reads back the
  value sent (a lost Sync Write is sent again, acknowledged, at most bus.retries times) and
  its torque is still on. The commands reported (`ApplyReport.commands`) are where the
  motors are, from their present positions, not where they were sent.
* Torque is on only while the hand runs. Any exception inside a move (a motor fault, a silent
  motor, Ctrl-C) switches torque off before it propagates; `close()` checks every motor for a
  hardware error one last time, switches torque off again (a broadcast first, so a motor
  whose replies are lost still hears it) and is called by the context manager and by
  `atexit`. SIGINT, SIGTERM and SIGHUP raise `vlr.errors.Interrupted` (the CLI's one
  "interrupted" line); later signals are ignored while the run shuts down. `close()`
  switches torque off even when its last check fails on a serial error.
* Every motor's Bus Watchdog (98) is armed whenever its torque goes on (bus.watchdog_ms):
  if this process dies (SIGKILL, out of memory) or the cable is pulled, the motors stop
  within that time. The control loop's packets feed it, and a keep-alive thread reads the
  motors whenever the bus has been idle for a quarter of it (a filter update, a prompt).
* The camera: camera.max_missing_frames reads in a row without a frame stop the run with
  torque off (`CameraError` naming the camera), rather than taking a blind camera for a
  held grasp and updating on predictions alone.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from vlr.hardware.bus import HardwareError, MotorBus
from vlr.hardware.calibration import find_zeros
from vlr.hardware.camera import CameraError, FakeCamera, FrameSource, OpenCVCamera
from vlr.hardware.config import EMULATOR_PORT, HardwareConfig, load_config
from vlr.hardware.control_table import (
    CURRENT_UNIT_MA,
    MODEL_NUMBERS,
    VELOCITY_UNIT_RPM,
    WATCHDOG_UNIT_MS,
    OperatingMode,
    Reg,
)
from vlr.hardware.tendons import (
    MotionState,
    TendonMap,
    read_motion,
    resolve_zero,
    wait_until_stopped,
)

from vlr.camera import CameraCalibration
from vlr.errors import Interrupted
from vlr.hand import ApplyReport, Frame, GraspError, check_delta
from vlr.spec import HandSpec, ObjectSpec, load_hand, load_object

_LOG = logging.getLogger(__name__)


class HardwareHand:
    """The Model O on a DYNAMIXEL bus, with a palm camera. Implements `vlr.hand.Hand`.

    Construction connects, pings every motor, configures them, finds (or resolves) the tendon
    zeros, holds the spread motor and opens the hand at u = 0. Files are read by `open_hand`;
    this class takes values.

    Args:
        config: the loaded hardware config.
        spec, object_spec, calibration: the nominal hand, the grasped object, the camera.
        camera: the frame source.
        port: serial port overriding config.bus.port (the emulator's pty in a dry run).
        on_close: callables run last by `close()` (e.g. stopping an emulator).
        log: where progress messages go (default: this module's logger at INFO, warnings
            at WARNING; `vlr.logs` prints them as "[hardware] ..." lines).
    """

    def __init__(self, config: HardwareConfig, *, spec: HandSpec, object_spec: ObjectSpec,
                 calibration: CameraCalibration, camera: FrameSource, port: str | None = None,
                 on_close: tuple[Callable[[], None], ...] = (),
                 log: Callable[[str], None] | None = None) -> None:
        self.config = config
        self._spec = spec
        self._object = object_spec
        self._calibration = calibration
        self.camera = camera
        self.log = log or _LOG.info
        self.warn = _LOG.warning if log is None else (lambda message: log(f"WARNING: {message}"))
        self._on_close = on_close
        self._closed = False
        self._stopped = ""  # why the hand was stopped, if it was
        # Settled present currents [mA] per finger, signed so that pulling is positive.
        self._currents: np.ndarray | None = None
        self._old_signals: dict[int, Any] = {}
        self.finger_ids = [f.id for f in config.fingers]
        self.bus = MotorBus(port or config.bus.port, config.bus.baud, labels=config.labels,
                            latency_ms=config.bus.latency_ms, retries=config.bus.retries,
                            watchdog=config.bus.watchdog)
        self._missing = 0  # camera reads in a row without a frame
        self.tendons: TendonMap | None = None
        self._u = np.zeros(len(self.finger_ids))  # the commands sent (the goals)
        self._reached: np.ndarray | None = None  # the commands the motors reached
        atexit.register(self._release)
        self._install_signal_handlers()
        try:
            self._start()
        except BaseException:
            self._release()
            raise

    # ----------------------------------------------------------------- Hand interface
    @property
    def spec(self) -> HandSpec:
        return self._spec

    @property
    def object_spec(self) -> ObjectSpec:
        return self._object

    @property
    def calibration(self) -> CameraCalibration:
        return self._calibration

    @property
    def commands(self) -> np.ndarray:
        """The tendon commands sent [m] (the motors' verified goals)."""
        return self._u.copy()

    @property
    def reached(self) -> np.ndarray:
        """The tendon commands the motors are at [m], from their present positions after the
        last move settled (read now if nothing moved yet)."""
        if self._reached is None:
            state = read_motion(self.bus, self.finger_ids, CURRENT_UNIT_MA)
            self._reached = self._commands_at(state)
        return self._reached.copy()

    def grasp(self) -> ApplyReport:
        """Close to the configured grasp commands in steps of at most motion.max_step, settle,
        and check the grasp (GraspError if the object's tag is not seen, when checked)."""
        target = np.asarray(self.config.grasp.commands)
        settled = True
        with self._guarded():
            while np.any(np.abs(target - self._u) > 1e-9):
                step = np.clip(target - self._u, -self.config.motion.max_step,
                               self.config.motion.max_step)
                settled = self._move_to(self._u + step)
        held, message = self._grasp_status()
        if not held:
            raise GraspError(f"no grasp at commands {np.round(self._u * 1e3, 2).tolist()} mm: "
                             f"{message}")
        return ApplyReport(commands=self.reached, settled=settled, grasp_held=True,
                           tensions=self._tensions())

    def apply(self, delta: np.ndarray) -> ApplyReport:
        """Change the tendon commands by `delta` [m], clipped to motion.range, ramped; then
        wait until the motors stop (bounded by motion.settle_timeout)."""
        m = self.config.motion
        d = check_delta(delta, len(self.finger_ids), m.max_step)
        target = np.clip(self._u + d, m.range[0], m.range[1])
        if np.any(target != self._u + d):
            self.log(f"tendon commands clipped to motion.range {list(m.range)} m: "
                     f"{np.round((self._u + d) * 1e3, 3).tolist()} mm -> "
                     f"{np.round(target * 1e3, 3).tolist()} mm")
        with self._guarded():
            settled = self._move_to(target)
        held, message = self._grasp_status()
        return ApplyReport(commands=self.reached, settled=settled, grasp_held=held,
                           message=message, tensions=self._tensions())

    def grab_frame(self) -> Frame | None:
        """The camera's newest frame, or None if it delivered none this time;
        camera.max_missing_frames in a row stop the run (`_read_image`)."""
        image = self._read_image()
        if image is None:
            return None
        return Frame(image=image, stamp=time.monotonic())

    def _read_image(self) -> np.ndarray | None:
        """One camera read, counted: a frame resets the count of reads in a row without
        one; reaching camera.max_missing_frames switches torque off and raises
        `CameraError`. A single dropped frame is not an error (the step is then a
        prediction), a camera that stopped is."""
        image = self.camera.read()
        if image is not None:
            self._missing = 0
            return image
        self._missing += 1
        limit = self.config.camera.max_missing_frames
        if self._missing >= limit:
            name = getattr(self.camera, "name", type(self.camera).__name__)
            with self._guarded():
                raise CameraError(
                    f"{name} delivered no frame in {self._missing} reads in a row "
                    f"(camera.max_missing_frames = {limit}): the run stopped with torque off; "
                    "check the camera's cable and that no other program holds it")
        return None

    def close(self) -> None:
        """Check every motor for a hardware error one last time (a fault after the last move
        raises `MotorFaultError` once everything is released, so no run ends as if it had
        succeeded), then `_release`, whatever the check raised (a serial error from a
        pulled cable included). Safe to call more than once."""
        if self._closed:
            return
        fault: HardwareError | None = None
        try:
            if self.bus.connected and not self._stopped:
                try:
                    self.bus.sync_read_one(Reg.HARDWARE_ERROR_STATUS, self.config.ids)
                except HardwareError as exc:
                    fault = exc
                except OSError as exc:  # pyserial's SerialException is one
                    fault = HardwareError(
                        f"the motor bus on {self.bus.port_name} failed during the last check "
                        f"of the motors ({type(exc).__name__}: {exc}); torque off was sent: "
                        "check the cable")
        finally:
            self._release()
        if fault is not None:
            raise fault

    def _release(self) -> None:
        """Torque off (broadcast, then each motor), close the port, the camera and whatever
        `on_close` holds. Safe to call more than once."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.bus.connected:
                for problem in self.bus.torque_off_everywhere(self.config.ids):
                    self.warn(problem)
        finally:
            self.bus.close()
            with contextlib.suppress(Exception):
                self.camera.close()
            for fn in self._on_close:
                with contextlib.suppress(Exception):
                    fn()
            self._restore_signal_handlers()
            atexit.unregister(self._release)

    def __enter__(self) -> HardwareHand:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is not None:
            self._release()  # an error is on its way out already
        self.close()

    # ----------------------------------------------------------------- start-up
    def _start(self) -> None:
        cfg = self.config
        self.bus.connect()
        for dxl_id in cfg.ids:
            model = self.bus.ping(dxl_id)
            if model not in MODEL_NUMBERS:
                self.log(f"{self.bus.label(dxl_id)} is model number {model}, not a known "
                         "X-series motor; continuing with the X-series control table")
        # (A motor in a hardware error state fails its ping with the decoded bits.)
        if cfg.bus.watchdog:
            # Fed from here on, so that no pause of this living process trips it.
            self.bus.start_keepalive(cfg.ids, cfg.bus.watchdog_ms / 1000.0 / 4.0)
        # EEPROM settings need torque off (which also clears a watchdog that expired when
        # an earlier run died: its goals would be read-only).
        self.bus.set_torque(cfg.ids, False)
        m = cfg.motion
        need_probe = any(f.zero is None for f in cfg.fingers)
        first_mode = OperatingMode.CURRENT_BASED_POSITION if need_probe else m.mode
        for dxl_id in self.finger_ids:
            self.bus.write(Reg.OPERATING_MODE, dxl_id, int(first_mode))
            self.bus.write(Reg.CURRENT_LIMIT, dxl_id, int(m.current_limit_ma / CURRENT_UNIT_MA))
            self.bus.write(Reg.PROFILE_VELOCITY, dxl_id,
                           int(round(m.profile_velocity_rpm / VELOCITY_UNIT_RPM)))
        self._torque_on_in_place(self.finger_ids, first_mode)
        if need_probe:
            zeros = find_zeros(self.bus, cfg.fingers, cfg.calibration, m.spool_radius,
                               settle_timeout=m.settle_timeout, log=self.log)
            self.log("tendon zeros found; to skip the probe next time, put them in "
                     f"{cfg.path}: " + ", ".join(f"fingers.{s}.zero: {z}" for s, z in
                                                zeros.items()))
            if m.mode != first_mode:
                self.bus.set_torque(self.finger_ids, False)
                for dxl_id in self.finger_ids:
                    self.bus.write(Reg.OPERATING_MODE, dxl_id, int(m.mode))
                self._torque_on_in_place(self.finger_ids, m.mode)
            zero_ticks = [zeros[f.slot] for f in cfg.fingers]
        else:
            present = self.bus.sync_read_one(Reg.PRESENT_POSITION, self.finger_ids)
            zero_ticks = [resolve_zero(f.zero, present[f.id], f.direction, m.spool_radius,
                                       m.range) for f in cfg.fingers]
        self.tendons = TendonMap(zeros=tuple(zero_ticks),
                                 directions=tuple(f.direction for f in cfg.fingers),
                                 spool_radius=m.spool_radius)
        if m.mode == OperatingMode.CURRENT_BASED_POSITION:
            cap = int(m.current_limit_ma / CURRENT_UNIT_MA)
            for dxl_id in self.finger_ids:
                self.bus.write(Reg.GOAL_CURRENT, dxl_id, cap)
        if cfg.spread is not None:
            s = cfg.spread
            self.bus.write(Reg.OPERATING_MODE, s.id, int(OperatingMode.POSITION))
            self.bus.write(Reg.PROFILE_VELOCITY, s.id,
                           int(round(m.profile_velocity_rpm / VELOCITY_UNIT_RPM)))
            # Goal after torque on: enabling torque may reset the goal to the present position.
            self.bus.set_torque([s.id], True)
            self.bus.write(Reg.GOAL_POSITION, s.id, s.position)
        present = self.bus.sync_read_one(Reg.PRESENT_POSITION, self.finger_ids)
        self._u = self.tendons.commands([present[i] for i in self.finger_ids])
        # Open the hand: back to u = 0 (clipped to the range), in allowed steps.
        with self._guarded():
            home = np.clip(np.zeros_like(self._u), m.range[0], m.range[1])
            start = np.clip(self._u, m.range[0] - m.max_step, m.range[1] + m.max_step)
            self._u = start
            while np.any(np.abs(home - self._u) > 1e-9):
                self._move_to(self._u + np.clip(home - self._u, -m.max_step, m.max_step))
            if cfg.spread is not None:
                wait_until_stopped(self.bus, [cfg.spread.id], m.settle_timeout, m.settle_ticks,
                                   CURRENT_UNIT_MA)
                self._settle({cfg.spread.id: cfg.spread.position})

    def _torque_on_in_place(self, ids: list[int], mode: OperatingMode) -> None:
        """Torque on without a jump: goal := present position first."""
        present = self.bus.sync_read_one(Reg.PRESENT_POSITION, ids)
        for dxl_id in ids:
            self.bus.write(Reg.GOAL_POSITION, dxl_id, present[dxl_id])
        self.bus.set_torque(ids, True)

    # ----------------------------------------------------------------- moving
    def _move_to(self, target: np.ndarray) -> bool:
        """Ramp the goal positions from the current commands to `target`, wait until the
        finger motors stop, and verify the move (`_settle`). Every motor is read on every
        ramp step and poll. Returns whether they stopped within motion.settle_timeout."""
        if self._stopped:
            raise HardwareError(f"the hand was stopped after an error ({self._stopped}); "
                                "close it and open it again")
        assert self.tendons is not None
        m = self.config.motion
        start = self._u.copy()
        for k in range(1, m.ramp_steps + 1):
            t0 = time.monotonic()
            u = start + (target - start) * (k / m.ramp_steps)
            self.bus.sync_write(Reg.GOAL_POSITION,
                                dict(zip(self.finger_ids, self.tendons.ticks(u), strict=True)))
            self._u = u
            # A read per step: its status bytes reveal a motor fault mid-ramp.
            read_motion(self.bus, self.config.ids, CURRENT_UNIT_MA)
            time.sleep(max(0.0, m.ramp_period - (time.monotonic() - t0)))
        self._u = np.asarray(target, dtype=float).copy()
        goals = dict(zip(self.finger_ids, self.tendons.ticks(self._u), strict=True))
        if self.config.spread is not None:
            goals[self.config.spread.id] = self.config.spread.position
        settled, state = self._settle(goals)
        self._reached = self._commands_at(state)
        self._currents = self._pulling_currents(state)
        return settled

    def _settle(self, goals: dict[int, int]) -> tuple[bool, MotionState]:
        """Wait until the finger motors stop (every motor read), then verify: each motor of
        `goals` holds that Goal Position (a Sync Write has no reply and may be lost: send it
        again, acknowledged, at most bus.retries times) and every motor's torque is on."""
        m, bus = self.config.motion, self.bus
        others = [i for i in self.config.ids if i not in self.finger_ids]
        for attempt in range(self.config.bus.retries + 1):
            settled, state = wait_until_stopped(bus, self.finger_ids, m.settle_timeout,
                                                m.settle_ticks, CURRENT_UNIT_MA, watch=others)
            lost = {i: g for i, g in goals.items() if state.goal[i] != g}
            if not lost:
                break
            for dxl_id, goal in lost.items():
                if attempt == self.config.bus.retries:
                    raise HardwareError(
                        f"{bus.label(dxl_id)} holds goal position {state.goal[dxl_id]}, not "
                        f"the {goal} sent {attempt + 1} times: its writes are lost (check the "
                        "cable and the baud rate)")
                self.log(f"{bus.label(dxl_id)} holds goal position {state.goal[dxl_id]}, not "
                         f"the {goal} sent (a lost write): sending it again")
                bus.write(Reg.GOAL_POSITION, dxl_id, goal)
        torque = bus.sync_read_one(Reg.TORQUE_ENABLE, self.config.ids)
        off = [i for i, on in torque.items() if not on]
        expired = [i for i in off if bus.watchdog_expired(i)]
        if expired:
            raise HardwareError(
                f"{', '.join(bus.label(i) for i in expired)} stopped: its bus watchdog expired "
                f"(no packet for {bus.watchdog * WATCHDOG_UNIT_MS} ms, bus.watchdog_ms; "
                "a stalled host or serial line?)")
        if off:
            raise HardwareError(f"{', '.join(bus.label(i) for i in off)} switched torque off "
                                "without a hardware error (a reboot or a supply dip?): check "
                                "the 12 V supply")
        return settled, state

    def _commands_at(self, state: MotionState) -> np.ndarray:
        """The tendon commands [m] at the finger motors' present positions in `state`."""
        assert self.tendons is not None
        return self.tendons.commands([state.position[i] for i in self.finger_ids])

    def _pulling_currents(self, state) -> np.ndarray:
        """Present currents [mA] per finger, signed by each motor's pulling direction: a
        motor that pulls with negative ticks draws negative current under the same
        tension."""
        return np.array([f.direction * state.current_ma[f.id] for f in self.config.fingers],
                        dtype=float)

    def _tensions(self) -> np.ndarray | None:
        """Tendon tensions [N] from the settled present currents (`TensionConfig`); None
        without a tension calibration in the config."""
        t = self.config.tension
        if t is None:
            return None
        # (Read now if no move yet: a grasp already at its commands.)
        return np.maximum(0.0, t.newton_per_ma * (self.pulling_currents - np.asarray(t.zero_ma)))

    @property
    def pulling_currents(self) -> np.ndarray:
        """The finger motors' present currents after the last move settled [mA], signed by
        each one's pulling direction, in hand slot order (read now if nothing moved yet):
        what a `tension` calibration maps to tensions (`vlr tension-calibrate`)."""
        if self._currents is None:
            self._currents = self._pulling_currents(
                read_motion(self.bus, self.finger_ids, CURRENT_UNIT_MA))
        return self._currents.copy()

    @property
    def reads_tensions(self) -> bool:
        """Whether each move reports tendon tensions (a `tension` section in the config)."""
        return self.config.tension is not None

    @contextlib.contextmanager
    def _guarded(self) -> Iterator[None]:
        """Any exception while the motors move (including Ctrl-C) switches torque off."""
        try:
            yield
        except BaseException as exc:
            self._stopped = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            if self.bus.connected:
                for problem in self.bus.torque_off_everywhere(self.config.ids):
                    self.warn(problem)
            raise

    def _grasp_status(self) -> tuple[bool, str]:
        """Whether the object is held, as far as the palm camera can tell."""
        if not self.config.grasp.check_tag:
            return True, ""
        image = self._read_image()
        if image is None:
            return True, ""  # a dropped frame: unknown (a camera that stopped raises)
        from vlr.perception import detect_tags, to_gray

        if any(d.tag_id == self._object.tag_id for d in detect_tags(to_gray(image))):
            return True, ""
        return False, (f"the object's tag (36h11 id {self._object.tag_id}) is not seen by the "
                       "palm camera")

    # ----------------------------------------------------------------- signals
    def _install_signal_handlers(self) -> None:
        """SIGINT, SIGTERM and SIGHUP -> `Interrupted`, so `finally` blocks switch torque off
        and the CLI prints its one line (the default action of SIGTERM and SIGHUP kills the
        process with torque still on). A handler the program set itself is left alone."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig, default in ((signal.SIGINT, signal.default_int_handler),
                             (signal.SIGTERM, signal.SIG_DFL), (signal.SIGHUP, signal.SIG_DFL)):
            if signal.getsignal(sig) is default:
                self._old_signals[sig] = signal.signal(sig, _interrupt)

    def _restore_signal_handlers(self) -> None:
        """Back to the handlers found, unless a signal came: then later ones stay ignored
        until the process has exited (no second message, no shutdown tracebacks)."""
        if threading.current_thread() is not threading.main_thread():
            return
        if not _SIGNALLED:
            for sig, old in self._old_signals.items():
                with contextlib.suppress(ValueError, OSError):
                    signal.signal(sig, old)
        self._old_signals.clear()


_SIGNALLED: list[int] = []  # the signal that stopped a hand, if one did
_HANDLED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _interrupt(signum: int, frame: object) -> None:
    """The first signal ends the run (torque off on the way out); later ones are ignored."""
    for sig in _HANDLED:
        signal.signal(sig, signal.SIG_IGN)
    _SIGNALLED.append(signum)
    raise Interrupted(signum)


def open_hand(*, config: str, **ignored: Any) -> HardwareHand:
    """Backend factory for the CLI: `vlr ... --backend hardware --config FILE`.

    Other options the CLI passes (object, seed, ...) are ignored: the config file says which
    object is grasped. With bus.port "emulator" the motors are emulated in-process (a dry
    run; see hardware/README.md).
    """
    cfg = load_config(config)
    spec = load_hand(cfg.hand)
    object_spec = load_object(cfg.object)
    on_close: list[Callable[[], None]] = []
    try:
        port = None
        plant = None
        if cfg.bus.port == EMULATOR_PORT:
            from vlr.hardware.emulate import build_emulator

            emulator, plant = build_emulator(cfg)
            port = emulator.start()
            on_close.append(emulator.stop)
            if hasattr(plant, "close"):
                on_close.append(plant.close)
        if cfg.camera.calibration is not None:
            from vlr.camera import load_calibration

            calibration = load_calibration(cfg.camera.calibration)
        else:
            calibration = plant.calibration  # camera.fake "sim" (checked by load_config)
        camera = _camera(cfg, calibration, plant)
    except BaseException:
        for fn in reversed(on_close):
            fn()
        raise
    return HardwareHand(cfg, spec=spec, object_spec=object_spec, calibration=calibration,
                        camera=camera, port=port, on_close=tuple(reversed(on_close)))


def _camera(cfg: HardwareConfig, calibration: CameraCalibration, plant: Any) -> FrameSource:
    if cfg.camera.fake == "blank":
        return FakeCamera(calibration.width, calibration.height, name="camera.fake 'blank'")
    if cfg.camera.fake == "sim":
        if plant is None or not hasattr(plant, "render"):
            raise HardwareError("camera.fake 'sim' needs bus.port 'emulator' with "
                                "emulator.plant 'sim' (frames come from the simulated hand)")
        return FakeCamera(calibration.width, calibration.height, source=plant.render,
                          name="camera.fake 'sim'")
    assert cfg.camera.index is not None
    return OpenCVCamera(cfg.camera.index, calibration.width, calibration.height)
