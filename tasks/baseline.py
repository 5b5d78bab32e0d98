"""The VLR baseline policy: the Jacobian controller (Eq. 10-12) on the env's identified VLR.

    env = gymnasium.make("vlr/Handwriting-v2")
    obs, info = env.reset(seed=0)
    policy = VLRBaseline(env)
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            break

Each call: retake the Jacobian on the env's particle filter at the current commands
(`vlr.controller.numerical_jacobian`), compute the error from the latest camera pose to the
current target, and return the step (transpose or damped least squares, rows and alpha as
the task sets them in `controller_config`). With `secant` on (the tasks' default, ours), a
correction of the VLR's Jacobian is fitted to the camera's view of the identification's own
exploratory moves at the first call of an episode, then updated after every move
(`JacobianController.fit`, `.learn`); with it off the policy is the paper's controller alone.
The policy reads tendon commands, camera poses and the filter only: never ground truth.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from vlr.controller import ControllerConfig, JacobianController, numerical_jacobian
from vlr.controller import observed_motion as _motion

__all__ = ["VLRBaseline", "move_pairs", "fitted_controller", "fitted_jacobian"]


def move_pairs(moves) -> tuple[np.ndarray, np.ndarray]:
    """The tendon changes (K, 3) [m] and the POM motions the camera saw for them (K, 6)
    [m, rad] between consecutive `moves` (the env's record), skipping unobserved and null
    moves."""
    d, m = [], []
    for a, b in zip(moves[:-1], moves[1:], strict=True):
        du = b.commands - a.commands
        if a.observation is None or b.observation is None or np.max(np.abs(du)) < 1e-7:
            continue
        d.append(du)
        m.append(_motion(a.observation, b.observation))
    return np.reshape(d, (-1, 3)), np.reshape(m, (-1, 6))


def fitted_controller(env: Any, config: ControllerConfig) -> JacobianController:
    """A controller for a freshly identified grasp: the VLR's Jacobian (Eq. 10, on the env's
    filter at its commands) plus, with `secant`, the correction fitted to the camera's view
    of the moves so far (`JacobianController.fit`)."""
    env = env.unwrapped
    try:
        jac = numerical_jacobian(env.pf.motion, env.pf.state, env.commands,
                                 config.jacobian_eps, config.jacobian_particles)
    except FloatingPointError:  # no particle solves here: the camera's fit alone
        jac = np.zeros((6, 3))
    ctrl = JacobianController(config)
    ctrl.fit(*move_pairs(env.moves), jac)
    return ctrl


def fitted_jacobian(env: Any, config: ControllerConfig) -> np.ndarray:
    """The Jacobian the baseline starts an identified grasp with (`fitted_controller`)."""
    return fitted_controller(env, config).jacobian


class VLRBaseline:
    """Callable policy: observation -> action (the tendon change as a share of the env's
    `max_step`, in [-1, 1]; module docstring).

    Args:
        env: a task env (or a wrapper of one).
        config: controller settings (default: the task's `controller_config`).
        **changes: fields of the config to change (e.g. method="transpose", secant=False).
    """

    def __init__(self, env: Any, config: ControllerConfig | None = None,
                 **changes: Any) -> None:
        from vlr.errors import UserError

        self.env = env.unwrapped
        if not self.env.identify:
            raise UserError("the VLR baseline needs the identified VLR: make the env with "
                            "identify=True")
        cfg = config or self.env.controller_config
        self.config = replace(cfg, **changes) if changes else cfg
        self._episode = -1
        self.controller = JacobianController(self.config)
        self._seen = 0

    def _new_episode(self) -> None:
        env = self.env
        self.controller = fitted_controller(env, self.config)
        self._seen = len(env.moves)
        self._episode = env.identified

    def __call__(self, observation: Any = None) -> np.ndarray:
        env = self.env
        if self._episode != env.identified:   # a new episode, or a new grasp (cups)
            self._new_episode()
        else:
            # Learn from the moves made since the last call (the camera's view of them).
            new = env.moves[max(self._seen - 1, 0):]
            for du, dm in zip(*move_pairs(new), strict=True):
                self.controller.learn(du, dm)
            self._seen = len(env.moves)
        pos, rot = env.target
        du = self.controller.act(env.pf.motion, env.pf.state, env.commands, env.observation,
                                 pos, rot, bounds=env.action_bounds())
        # float64, not the space's float32: the change applied is then du itself.
        return np.clip(du / env.max_step, -1.0, 1.0)
