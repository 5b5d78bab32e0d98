"""The common gymnasium environment of the in-hand manipulation tasks (docs/METHOD.md 5-6).

One template for every task (Gymnasium-Robotics style): `reset` opens the backend once,
grasps and self-identifies the hand-object system (Algorithm 1, `vlr.run`, with the same
settings tree and backend defaults as `vlr identify`) so that an episode starts from an
identified VLR, then lets the task set itself up (`_start_task`);
`step` applies a tendon change, re-observes the POM through the camera, lets the particle
filter keep updating the VLR (contacts roll), then asks the task for reward and progress
(`_task_step`).

What a policy sees: tendon commands and camera-derived POM poses only (the observation), and,
through `env.unwrapped`, the identified filter (`pf`), the current commands, the last camera
pose and the record of every move (`moves`) - what the VLR baseline (`tasks.baseline`) uses.
Ground truth (sim only) goes to `info["truth"]` and to the task metrics, never to the filter
or the policy.

Action: the change of the tendon commands [m], a Box of +-`max_step` per tendon (the
identification's largest exploratory step, 0.4 mm; the sim refuses more than 2 mm per move).
Commands are also kept within +-`command_band` of the task's centre command, so that no
sequence of actions slackens a tendon or crushes the object (the grasp's workspace).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from vlr.controller import ControllerConfig, rotation_log
from vlr.errors import UserError

# The tasks' scenes, bands and controllers are the Model O's: one tendon per finger, three.
TENDONS = 3

__all__ = ["Move", "HandTaskEnv", "pose_vector", "save_figure"]


@dataclass(frozen=True)
class Move:
    """One entry of the move record: the commands after a move [m] and the camera pose then
    (None if the tag was not seen)."""

    commands: np.ndarray
    observation: Any


def pose_vector(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """[x, y, z, rx, ry, rz]: position [m] and rotation vector [rad] in the palm frame."""
    return np.concatenate([np.asarray(position, dtype=float), rotation_log(rotation)])


class HandTaskEnv(gym.Env):
    """Base class of the tasks; subclasses set `object_name`, `controller_config` and fill
    `_start_task`, `_task_step`, `_target`, `metrics` and `picture`.

    Args:
        backend: "sim" (MuJoCo) or "hardware" (the real hand; needs `hardware_config`).
        render_mode: None or "rgb_array" (a third-person view of the sim scene; on hardware
            the palm camera's frame).
        particles: particle count of the identification in reset.
        identify_iterations: its exploratory moves (all are made, even after convergence).
        max_step: action bound per tendon and move [m].
        command_band: (release, pull): commands stay within [centre - release, centre +
            pull] of the task's centre command [m]; each a number, or one per tendon in the
            hand's order (a finger that holds more tension can release more). Releasing is
            what loses a fingertip (a side finger's 12 N grasp tension is gone after 0.6 mm
            at 20 N/mm), so the default band releases less than it pulls.
        squeeze: the task's centre command is the grasp command plus this much on every
            tendon [m]; after identification the commands move there (in moves of at most
            `max_step`, the filter following) before the task starts.
        include_image: add the palm camera frame to the observation ("image"), resized to
            `image_size` (height, width) [px].
        hardware_config: the hardware YAML file (backend "hardware").
        settings: the identification's settings beyond the backend's defaults, dotted keys
            of the settings tree (`vlr.settings`, as `vlr identify --set`), e.g.
            {"filter.guess_theta_deg": [-5, 20]}; `particles` and `identify_iterations`
            set filter.particles and the loop's action count.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}
    object_name = "apple"
    controller_config = ControllerConfig()

    def __init__(self, backend: str = "sim", render_mode: str | None = None,
                 particles: int = 5000, identify_iterations: int = 15,
                 max_step: float = 0.4e-3,
                 command_band: tuple[float, float] = (0.25e-3, 0.4e-3),
                 squeeze: float = 0.0,
                 include_image: bool = False, image_size: tuple[int, int] = (120, 160),
                 hardware_config: str | None = None,
                 settings: Mapping[str, Any] | None = None) -> None:
        if backend not in ("sim", "hardware"):
            raise ValueError(f"backend {backend!r}: use 'sim' or 'hardware'")
        if backend == "hardware" and not hardware_config:
            raise ValueError("backend 'hardware' needs hardware_config (the hardware YAML)")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}: use one of "
                             f"{self.metadata['render_modes']}")
        if particles < 10 or identify_iterations < 0:
            raise ValueError("particles must be >= 10 and identify_iterations >= 0")
        if not max_step > 0:
            raise ValueError(f"max_step {max_step!r} must be > 0 [m]")
        self.backend = backend
        self.render_mode = render_mode
        self.particles = int(particles)
        self.identify_iterations = int(identify_iterations)
        self.max_step = float(max_step)
        self.command_band = _band(command_band)
        self.squeeze = float(squeeze)
        self.include_image = bool(include_image)
        self.hardware_config = hardware_config
        self.settings_layer = dict(settings or {})
        # The identification's settings, checked now: a bad key is one error at make().
        self.identification_settings(0)
        self.action_space = spaces.Box(-self.max_step, self.max_step, shape=(TENDONS,),
                                       dtype=np.float64)
        # Poses: position within 1 m of the palm [m], rotation vector (norm <= pi) [rad].
        lim = np.array([1.0] * 3 + [np.pi] * 3)
        obs = {"pose": spaces.Box(-lim, lim, dtype=np.float64),
               "target": spaces.Box(-lim, lim, dtype=np.float64)}
        self._image_shape: tuple[int, int, int] | None = None
        if include_image:
            self._image_shape = (int(image_size[0]), int(image_size[1]), 3)
            obs["image"] = spaces.Box(0, 255, shape=self._image_shape, dtype=np.uint8)
        self.observation_space = spaces.Dict(obs)
        self.hand = None
        self.pf = None
        self.identification = None
        self.moves: list[Move] = []
        self.observation = None      # the latest camera pose (vlr.perception.Observation)
        self.center: np.ndarray | None = None
        self.filter_lost = False
        self.grasp_lost = False
        self.grasp_message = ""
        self.episode = 0
        self.identified = 0          # identifications so far (several per episode: cups)
        self._image: np.ndarray | None = None
        self._u = np.zeros(TENDONS)

    # ------------------------------------------------------------------ backend
    def _open_hand(self):
        """The backend's `Hand` (`vlr.backends.open_hand`). Tasks with their own scene
        (maze, cups) override this."""
        from vlr.backends import open_hand

        if self.backend == "sim":
            return open_hand("sim", object=self.object_name, seed=0)
        return open_hand("hardware", config=self.hardware_config)

    @property
    def commands(self) -> np.ndarray:
        """Current tendon commands [m]."""
        return self._u.copy()

    @property
    def target(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The current target: POM position (3,) [m] and rotation (3, 3), or None when the
        task controls position only."""
        return self._target()

    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The tendon changes [m] (low, high) that keep the commands inside the band and the
        action space now: what `step` would clip an action to."""
        release, pull = self.command_band
        u = self.commands
        low = np.maximum(self.action_space.low, self.center - release - u)
        high = np.minimum(self.action_space.high, self.center + pull - u)
        return np.minimum(low, 0.0), np.maximum(high, 0.0)

    @property
    def has_truth(self) -> bool:
        return hasattr(self.hand, "truth")

    def _observe(self):
        from vlr.perception import observe

        frame = self.hand.grab_frame()
        if frame is None:
            return None
        if self.include_image:
            import cv2

            h, w, _ = self._image_shape
            self._image = cv2.resize(np.asarray(frame.image, dtype=np.uint8), (w, h),
                                     interpolation=cv2.INTER_AREA)
        spec = self.hand.object_spec
        return observe(frame.image, self.hand.calibration, spec.tag_id, spec.tag_size)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if self.hand is None:
            hand = self._open_hand()
            n = hand.spec.n_fingers
            if n != TENDONS:
                hand.close()
                raise UserError(f"the tasks are written for the Model O's {TENDONS} tendons; "
                                f"the backend's hand has {n} fingers")
            self.hand = hand
        self.episode += 1
        self._prepare_episode()
        self._identify_grasp()
        self._start_task()
        return self._get_obs(), self._info()

    def _identification_layer(self) -> dict[str, Any]:
        """Settings the task itself gives its identification (cups: gravity in the palm
        frame, from the arm's pose), over the backend's defaults and under the user's."""
        return {}

    def identification_settings(self, seed: int):
        """The identification's settings tree (`vlr.settings`): the backend's defaults, the
        particle count and the action budget (every action is made: the baseline fits its
        Jacobian correction to them), the task's own, then the user's `settings`."""
        from vlr.settings import load_settings

        n = self.identify_iterations
        return load_settings({"world.backend": self.backend},
                             {"filter.particles": self.particles,
                              "loop.max_iterations": n, "loop.min_iterations": n,
                              "seed": seed},
                             self._identification_layer()
                             if getattr(self, "hand", None) is not None else {},
                             self.settings_layer)

    def _identify_grasp(self) -> None:
        """Grasp and self-identify (Algorithm 1) with a fresh filter, then move the commands
        to the task's centre: what `reset` does, and what a task that grasps several
        objects per episode (cups) does for each. Bumps `identified` (the baseline refits
        its Jacobian correction on a new identification)."""
        import dataclasses

        from vlr.run import run_identification
        from vlr.world import hand_world

        settings = self.identification_settings(int(self.np_random.integers(0, 2**31 - 1)))
        self.moves = []
        self.filter_lost = self.grasp_lost = False
        self.grasp_message = ""
        self.identified += 1
        box: dict[str, Any] = {}

        def observer():
            obs = self._observe()
            self.moves.append(Move(np.asarray(self.hand.commands, dtype=float).copy(), obs))
            return obs

        # The world around the env's own hand, observed through the env (it records every
        # move), and not scored: the filter and the policy never see the truth.
        world = dataclasses.replace(hand_world(self.hand, settings), truth=None)
        try:
            run = run_identification(settings, world=world,
                                     observe_through=lambda w: observer,
                                     watch=lambda pf, rec: box.update(pf=pf))
            self.identification = run.result
        except FloatingPointError:
            # Every particle's solve failed (too few particles, or a prior that misses the
            # grasp): the episode goes on with the VLR lost, `filter_lost` says so. Before
            # the filter exists (a prior that settled in none of its draws) there is no VLR
            # to go on with: the filter's error says what failed.
            if "pf" not in box:
                raise
            self.identification = None
            self.filter_lost = True
        self.pf = box["pf"]
        self._u = np.asarray(self.hand.commands, dtype=float).copy()
        self.observation = next(m.observation for m in reversed(self.moves)
                                if m.observation is not None)
        # The task's centre is the grasp command (identification's exploration leaves the
        # commands anywhere in its band), plus the squeeze.
        self.center = self.moves[0].commands + self.squeeze
        while np.max(np.abs(self.center - self.commands)) > 1e-9 and not self.grasp_lost:
            before = self.commands
            self._apply(np.clip(self.center - self.commands, -self.max_step, self.max_step))
            if np.array_equal(before, self.commands):   # the backend clipped the move away
                raise UserError(f"the task's centre command {np.round(self.center * 1e3, 3)}"
                                " mm cannot be reached (the backend's command range; "
                                "squeeze?)")

    def step(self, action):
        a = np.clip(np.asarray(action, dtype=float).reshape(TENDONS), -self.max_step,
                    self.max_step)
        u = self.commands
        release, pull = self.command_band
        target = np.clip(u + a, self.center - release, self.center + pull)
        self._apply(target - u)
        reward, terminated = self._task_step()
        terminated = bool(terminated or self.grasp_lost)
        return self._get_obs(), float(reward), terminated, False, self._info()

    def _apply(self, delta: np.ndarray) -> None:
        """Apply a tendon change, re-observe, let the filter update the VLR (`pf.step`)."""
        report = self.hand.apply(delta)
        if not getattr(report, "grasp_held", True):
            self.grasp_lost = True
            self.grasp_message = str(getattr(report, "message", ""))
        # The task steers by the commands it sent; the filter sees the commands the motors
        # reached (the same in the sim; on the real hand within a tick of them, or short of
        # a stalled goal).
        self._u = np.asarray(self.hand.commands, dtype=float).copy()
        u = np.asarray(report.commands, dtype=float).copy()
        obs = self._observe()
        self.moves.append(Move(u, obs))
        if obs is not None:
            self.observation = obs
        if self.filter_lost:
            return
        try:
            self.pf.step(u, obs)
        except FloatingPointError:  # every particle's solve failed: the VLR is lost
            self.filter_lost = True

    def render(self):
        if self.render_mode != "rgb_array" or self.hand is None:
            return None
        if self.backend == "sim":
            from sim.camera import render_scene

            return render_scene(self.hand)
        frame = self.hand.grab_frame()
        return None if frame is None else np.asarray(frame.image, dtype=np.uint8)

    def close(self) -> None:
        if self.hand is not None:
            self.hand.close()
            self.hand = None

    # ------------------------------------------------------------------ observation
    def _get_obs(self) -> dict[str, np.ndarray]:
        o = self.observation
        out = {"pose": pose_vector(o.position, o.rotation), "target": self._target_vector()}
        if self.include_image:
            img = self._image if self._image is not None else np.zeros(self._image_shape,
                                                                       np.uint8)
            out["image"] = img.copy()
        return out

    def _target_vector(self) -> np.ndarray:
        pos, rot = self._target()
        if rot is None:
            rot = np.asarray(self.observation.rotation)
        return pose_vector(pos, rot)

    def _info(self) -> dict[str, Any]:
        # No moves yet when a pick inside a step failed (cups): no tag seen since.
        seen = bool(self.moves) and self.moves[-1].observation is not None
        info: dict[str, Any] = {"commands": self.commands, "tag_seen": seen,
                                "filter_lost": self.filter_lost,
                                "grasp_lost": self.grasp_lost}
        info.update(self._task_info())
        if self.backend == "sim" and self.has_truth:
            t = self.hand.truth()
            info["truth"] = {"pom_position": t.pom_position.copy(),
                             "pom_rotation": t.pom_rotation.copy(), **self._truth_info()}
        return info

    def baseline(self, **changes: Any):
        """The VLR baseline policy for this env (`tasks.baseline.VLRBaseline`), with optional
        changes to the task's controller settings (e.g. method="transpose")."""
        from tasks.baseline import VLRBaseline

        return VLRBaseline(self, **changes)

    # ------------------------------------------------------------------ for subclasses
    def _prepare_episode(self) -> None:
        """Set the scene up before the grasp (cups: arrange the table, move the arm)."""

    def _start_task(self) -> None:
        raise NotImplementedError

    def _task_step(self) -> tuple[float, bool]:
        raise NotImplementedError

    def _target(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The current target: POM position (3,) [m] and rotation (3, 3) or None."""
        raise NotImplementedError

    def _task_info(self) -> dict[str, Any]:
        return {}

    def _truth_info(self) -> dict[str, Any]:
        return {}

    def metrics(self) -> dict[str, Any]:
        """The task's result.json content (errors, success)."""
        raise NotImplementedError

    def picture(self, path) -> None:
        """Write the task's picture (PNG) to `path`."""
        raise NotImplementedError


def _band(command_band) -> tuple:
    """(release, pull), each a number [m] or one per tendon (TENDONS values), all >= 0."""
    try:
        release, pull = command_band
        parts = [np.asarray(v, dtype=float) for v in (release, pull)]
    except (TypeError, ValueError):
        raise ValueError(f"command_band {command_band!r} must be (release, pull) [m], each a "
                         "number or one per tendon") from None
    if any(p.shape not in ((), (TENDONS,)) or np.any(p < 0) or not np.all(np.isfinite(p))
           for p in parts):
        raise ValueError(f"command_band {command_band!r}: release and pull must be >= 0, "
                         "each a number or one per tendon [m]")
    return tuple(float(p) if p.ndim == 0 else p for p in parts)


def save_figure(fig, path) -> None:
    """Save a matplotlib figure atomically (temporary file in the same folder, then rename),
    readable by others, and close it: the project's picture writer (`vlr.plots`)."""
    from pathlib import Path

    from vlr.plots import _save

    _save(fig, Path(path))
