"""Example policies for `vlr task NAME --policy tasks.examples:NAME` (docs/TASKS.md).

A policy factory takes the unwrapped environment after its identification and returns a
callable from the observation to the action, the three tendon changes as shares of the env's
`max_step` ([-1, 1]). These two are references to compare a controller against, not
controllers worth using:

- `hold`: never moves. The task's error when nothing is done: what a controller must beat.
- `camera_only`: a proportional step through a Jacobian fitted to the camera's view of the
  identification's own exploratory moves alone (least squares, no VLR): what the camera
  teaches without the identified model (the baseline adds the VLR's Jacobian, Eq. 10).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from vlr.tasks.base import GOAL_COLUMNS
from vlr.tasks.baseline import move_pairs

from vlr.controller import ROWS

__all__ = ["hold", "camera_only"]


def hold(env: Any):
    """The policy that never moves."""
    return lambda obs: np.zeros(3)


def camera_only(env: Any, gain: float = 0.5):
    """A step of `gain` times the least-squares tendon change that the camera-fitted Jacobian
    says removes the pose error on the task's controlled rows (`vlr.controller.ROWS`, as the
    baseline's `controller_config.rows`; no Eq. 12 weighting), refitted after every move.
    The pose error is the difference of the rotation vectors, good for small errors."""
    rows = list(ROWS[env.controller_config.rows])

    def policy(obs: dict) -> np.ndarray:
        du, dm = move_pairs(env.moves)
        if len(du) < 3:
            return np.zeros(3)
        jac = np.linalg.lstsq(du, dm, rcond=None)[0].T          # (6, 3): dm = J du
        pose = np.asarray(obs["observation"], dtype=float)[:6]
        target = pose.copy()
        target[GOAL_COLUMNS[env.goal_rows]] = obs["desired_goal"]
        step = np.linalg.lstsq(jac[rows], (target - pose)[rows], rcond=None)[0]
        return np.clip(gain * step / env.max_step, -1.0, 1.0)

    return policy
