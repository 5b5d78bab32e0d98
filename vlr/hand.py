"""The `Hand` interface: what the estimator and controller may use of any backend.

A backend (the MuJoCo sim in `sim/`, the real Model O in `hardware/`) moves tendons, waits
until the hand settles, and grabs camera frames. Ground truth is NOT part of this interface:
the sim exposes it through a separate accessor used only for scoring.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from vlr.camera import CameraCalibration
from vlr.spec import HandSpec, ObjectSpec


@dataclass(frozen=True)
class ApplyReport:
    """What a tendon move did, as the hand itself can tell.

    Attributes:
        commands: tendon commands u after the move [m], one per finger (pull from the
            calibrated open-hand zero).
        settled: the hand reached quasi-static rest within the step/time budget.
        grasp_held: the object is still held by the fingertips (sim: from contacts; hardware:
            from the tag still being seen, or True when unknown).
        message: why the grasp failed, if it did ("" otherwise).
        tensions: tendon tensions after the move [N], one per finger, where the hand can read
            them (sim: each series spring's static tension, what a servo's current reading
            settles to; hardware: from the servos' settled present current, with a `tension`
            calibration in its config); None where it cannot.
    """

    commands: np.ndarray
    settled: bool
    grasp_held: bool
    message: str = ""
    tensions: np.ndarray | None = None


@dataclass(frozen=True)
class Frame:
    """One camera image and when it was taken (seconds on the backend's clock)."""

    image: np.ndarray
    stamp: float


@runtime_checkable
class Hand(Protocol):
    """A tendon-driven hand with an in-palm camera (docs/METHOD.md 1)."""

    @property
    def spec(self) -> HandSpec:
        """The NOMINAL hand spec the user knows (unknown parameters are whatever the user
        believes them to be; the estimator identifies them)."""

    @property
    def object_spec(self) -> ObjectSpec:
        """The grasped object's spec (tag id and size, mass and centre of mass)."""

    @property
    def calibration(self) -> CameraCalibration:
        """The in-palm camera's intrinsics and extrinsics."""

    @property
    def commands(self) -> np.ndarray:
        """Current tendon commands u [m], one per finger."""

    def grasp(self) -> ApplyReport:
        """Close the hand on the object and settle; raise GraspError if no grasp results."""

    def apply(self, delta: np.ndarray) -> ApplyReport:
        """Change the tendon commands by `delta` [m] (one per finger), ramped, then settle."""

    def grab_frame(self) -> Frame | None:
        """The latest camera frame, or None if the camera dropped it."""

    def close(self) -> None:
        """Release resources (sim renderer; hardware: torque off, port and camera closed)."""


class GraspError(RuntimeError):
    """The hand could not establish or keep a fingertip grasp."""


class CommandError(ValueError):
    """A tendon command is non-finite, has the wrong shape, or is out of range."""


def report_commands(report) -> np.ndarray:
    """The tendon commands u [m] after a move: an `ApplyReport`'s, or the array a world that
    reports nothing else returns (`vlr.synthetic.SyntheticWorld.apply`)."""
    return np.asarray(getattr(report, "commands", report), dtype=float)


def check_delta(delta: np.ndarray, n_fingers: int, max_step: float) -> np.ndarray:
    """Validate a tendon change: finite, one per finger, each |delta| <= max_step [m]."""
    arr = np.asarray(delta, dtype=float)
    if arr.shape != (n_fingers,):
        raise CommandError(f"tendon change {delta!r} must have shape ({n_fingers},), "
                           f"got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CommandError(f"tendon change {arr.tolist()} is not finite")
    if np.any(np.abs(arr) > max_step):
        raise CommandError(f"tendon change {arr.tolist()} m exceeds the per-move limit "
                           f"{max_step} m")
    return arr
