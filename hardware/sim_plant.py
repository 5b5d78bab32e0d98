"""A `MotorPlant` that couples the emulated motors to the MuJoCo hand (sim/backend.py).

With it, the whole hardware path runs against simulated hardware: `HardwareHand` ->
`MotorBus` -> dynamixel_sdk -> pty -> `Emulator` -> this plant -> `SimHand`, and the palm
camera frames are the sim's renders (`FakeCamera(source=plant.render)`).

Mapping (vlr/spec.py): a finger motor's tendon command is u = direction x (shaft - taut) /
ticks-per-metre, where `taut` is the shaft angle at which its line goes taut (u = 0, the open
hand). Until the hand closes, the motors move as in `KinematicPlant` (so the calibration probe
finds the taut point). When every finger has wound to within `GRASP_TOLERANCE` of its
configured grasp command, the plant runs `SimHand.grasp()` (which places the object and closes
until the grasp tensions) and from then on drives `SimHand.apply` so that the sim's commands
follow the motors' u. The offset between the motors' u and the sim's own grasp commands is
fixed at that moment: tendon CHANGES (Delta l, Eq. 7) are reproduced exactly, absolute
commands differ by that constant offset (small when grasp.commands matches the sim's grasp).

Present currents come from the sim's tendon tensions (tension x spool radius / torque
constant). While the sim is catching up with the motors, they report Moving = 1, so the
backend's settle wait covers the simulated settling too.

Threading: MuJoCo data and the EGL renderer belong to ONE thread, the plant's worker; the
emulator thread only exchanges numbers with it, and `render()` asks the worker for a frame.
"""

from __future__ import annotations

import concurrent.futures
import math
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from vlr.hardware.config import HardwareConfig
from vlr.hardware.control_table import TICKS_PER_REV
from vlr.hardware.emulator import EmulatedMotor, KinematicPlant

#: XM430-W350 torque constant [N m/A]: 4.1 N m stall torque at 2.3 A (12 V, datasheet).
TORQUE_CONSTANT = 4.1 / 2.3

#: |u_motor - u_sim| below which the sim has caught up [m] (~1 tick on a 10 mm spool).
CATCH_UP = 2e-5

#: The sim grasps once every finger's u is within this of its configured grasp command [m]:
#: more than a calibration probe step, less than the last ramp step towards the grasp.
GRASP_TOLERANCE = 5e-4


class SimPlant:
    """Emulated finger motors driving a `sim.backend.SimHand` (see the module docstring).

    Args:
        cfg: the hardware config (fingers, spool radius, grasp commands, hand and object).
        taut: shaft angle [ticks] where each finger motor's line goes taut (u = 0).
        sim_factory: builds the SimHand (default: `SimHand(object=cfg.object,
            hand=cfg.hand)`); called in the worker thread.
    """

    def __init__(self, cfg: HardwareConfig, taut: Mapping[int, float],
                 sim_factory: Callable[[], Any] | None = None) -> None:
        self.cfg = cfg
        self.ids = [f.id for f in cfg.fingers]
        self.directions = {f.id: f.direction for f in cfg.fingers}
        self.taut = dict(taut)
        self.per_metre = TICKS_PER_REV / (2.0 * math.pi * cfg.motion.spool_radius)
        self.kinematic = KinematicPlant(taut=taut, directions=self.directions)
        self._grasp_commands = np.asarray(cfg.grasp.commands)
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._target = np.zeros(len(self.ids))   # motors' u, from the emulator thread
        self._sim_u = np.zeros(len(self.ids))    # what the sim has applied, u_motor frame
        self._tension = np.zeros(len(self.ids))  # [N]
        self._offset = np.zeros(len(self.ids))   # u_motor - u_sim after the grasp
        self._phase = "open"                     # open -> grasping -> grasped (or failed)
        self.error = ""                          # why the sim stopped following, if it did
        self._requests: list[tuple[Callable[[Any], Any], concurrent.futures.Future]] = []
        self._stop = False
        factory = sim_factory or self._default_factory
        ready: concurrent.futures.Future = concurrent.futures.Future()
        self._thread = threading.Thread(target=self._worker, args=(factory, ready),
                                        name="sim-plant", daemon=True)
        self._thread.start()
        ready.result(timeout=120)  # re-raises a failure to build the sim (e.g. a bad object)

    def _default_factory(self) -> Any:
        from vlr.sim.backend import SimHand

        return SimHand(object=self.cfg.object, hand=self.cfg.hand, seed=0)

    # ----------------------------------------------------------------- emulator side
    def u_of(self, dxl_id: int, shaft: float) -> float:
        return self.directions[dxl_id] * (shaft - self.taut[dxl_id]) / self.per_metre

    def step(self, motors: Mapping[int, EmulatedMotor], dt: float) -> None:
        """Move the shafts (kinematics), hand the fingers' u to the sim, report its state."""
        self.kinematic.step(motors, dt)
        fingers = [motors[i] for i in self.ids]
        u = np.array([self.u_of(m.dxl_id, m.shaft) for m in fingers])
        with self._lock:
            self._target = u
            phase = self._phase
            if phase == "open" and np.all(u >= self._grasp_commands - GRASP_TOLERANCE):
                self._phase = phase = "grasping"
            behind = np.max(np.abs(u - self._sim_u)) > CATCH_UP
            tension = self._tension.copy()
            self._wake.notify()
        if phase == "open" or phase == "failed":
            return
        for k, m in enumerate(fingers):
            if m.torque_on:
                m.moving = m.moving or phase == "grasping" or behind
                m.current = (self.directions[m.dxl_id] * tension[k]
                             * self.cfg.motion.spool_radius / TORQUE_CONSTANT * 1000.0)

    # ----------------------------------------------------------------- backend side
    @property
    def calibration(self) -> Any:
        """The sim's palm camera calibration (vlr.camera.CameraCalibration)."""
        return self._call(lambda sim: sim.calibration)

    def render(self) -> np.ndarray | None:
        """The palm camera's current frame (None if the sim dropped it)."""
        frame = self._call(lambda sim: sim.grab_frame())
        return None if frame is None else frame.image

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._wake.notify()
        self._thread.join(timeout=10)

    def _call(self, fn: Callable[[Any], Any], timeout: float = 30.0) -> Any:
        future: concurrent.futures.Future = concurrent.futures.Future()
        with self._lock:
            if self._stop:
                raise RuntimeError("the sim plant is closed")
            self._requests.append((fn, future))
            self._wake.notify()
        return future.result(timeout=timeout)

    # ----------------------------------------------------------------- worker thread
    def _worker(self, factory: Callable[[], Any], ready: concurrent.futures.Future) -> None:
        try:
            sim = factory()
        except BaseException as exc:  # reported to the constructor
            ready.set_exception(exc)
            return
        ready.set_result(None)
        try:
            while True:
                with self._lock:
                    while not (self._stop or self._requests or self._has_work()):
                        self._wake.wait(timeout=0.05)
                    if self._stop:
                        return
                    requests, self._requests = self._requests, []
                    phase, target = self._phase, self._target.copy()
                for fn, future in requests:
                    try:
                        future.set_result(fn(sim))
                    except Exception as exc:
                        future.set_exception(exc)
                if phase == "grasping":
                    self._grasp(sim)
                elif phase == "grasped":
                    self._follow(sim, target)
        finally:
            sim.close()

    def _has_work(self) -> bool:
        """(lock held) Is the sim behind the motors?"""
        if self._phase == "grasping":
            return True
        return self._phase == "grasped" and bool(
            np.max(np.abs(self._target - self._sim_u)) > CATCH_UP)

    def _grasp(self, sim: Any) -> None:
        from vlr.hand import GraspError

        try:
            sim.grasp()
        except GraspError as exc:
            with self._lock:
                self._phase, self.error = "failed", f"the simulated grasp failed: {exc}"
            return
        with self._lock:
            # The motors' u now (they have finished the grasp ramp: the backend waits while
            # the plant reports Moving) corresponds to the sim's grasp.
            self._offset = self._target - sim.commands
            self._sim_u = self._target.copy()
            self._tension = sim.static_tensions()
            self._phase = "grasped"

    def _follow(self, sim: Any, target: np.ndarray) -> None:
        from vlr.sim.backend import COMMAND_RANGE, MAX_STEP

        want = np.clip(target - self._offset, COMMAND_RANGE[0], COMMAND_RANGE[1])
        delta = np.clip(want - sim.commands, -MAX_STEP, MAX_STEP)
        sim.apply(delta)
        # A finger clipped to the sim's range counts as caught up: it cannot go further.
        clipped = want != target - self._offset
        with self._lock:
            self._sim_u = np.where(clipped, target, sim.commands + self._offset)
            self._tension = sim.static_tensions()
