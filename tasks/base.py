"""The common gymnasium environment of the in-hand manipulation tasks (docs/METHOD.md 5-6).

One template for every task, in the conventions of Gymnasium-Robotics' goal environments:
`reset` opens the backend once, grasps and (by default) self-identifies the hand-object
system (Algorithm 1, `vlr.run`, with the same settings tree and backend defaults as `vlr
identify`) so that an episode starts from an identified VLR, then lets the task set itself up
(`_start_task`); `step` applies a tendon change, re-observes the POM through the camera, lets
the particle filter keep updating the VLR (contacts roll), then lets the task advance its
target (`_task_step`).

Action: a Box(-1, 1, (3,), float32): the change of each tendon command as a share of
`max_step` (the identification's largest exploratory step, 0.4 mm by default); the change
applied in metres is `info["action_m"]`, the commands `info["commands"]`. Commands are also
kept within `command_band` of the task's centre command, so that no sequence of actions
slackens a tendon or crushes the object (the grasp's workspace).

Observation: a Dict of `observation` (the POM's camera pose [x, y, z, rotation vector], then
the tendon commands relative to the task's centre [m]), `achieved_goal` (what the task
steers, from the camera: the POM's position, its rotation vector, or both, `goal_rows`) and
`desired_goal` (the current target, alike); with `include_image`, the palm camera frame.
`info["is_success"]` is 1.0 when the camera puts the POM within the task's tolerance of the
target, else 0.0. The goal API is Gymnasium-Robotics' `GoalEnv`'s, and `step` returns what
its three functions give on the observation and info it returns: `compute_reward` (vectorised,
as HER relabels with it): with `reward_type="sparse"` (Fetch's default) -1.0 until success,
then 0.0; with "dense" minus the distance to the target (mm, degrees, or Eq. 12's weighted
pose error). `compute_terminated`: the task is done (`info["task_done"]`) or the grasp is lost.
`compute_truncated`: the identification in reset failed (or a smoke test's few moves are
made, `vlr.smoke`). gymnasium's `TimeLimit` adds the step limit, as for Fetch.

What a policy sees: tendon commands and camera-derived POM poses, and, through
`env.unwrapped`, the identified filter (`pf`), the last camera pose and the record of every
move (`moves`): what the VLR baseline (`tasks.baseline`) uses. Ground truth (sim only) goes
to the task metrics (`vlr task`'s scores), and to `info["truth"]` only when the env is made
with `expose_truth=True`; never to the filter or to a policy.

Failures a vectorised learner survives: an identification that fails in `reset` (no tag
seen, no particle settled) sets `info["identification_failed"]` and the next `step`
truncates the episode; a lost grasp terminates it with `info["grasp_lost"]`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from vlr.tasks import REWARD_TYPES

from vlr import smoke
from vlr.controller import ControllerConfig, rotation_log
from vlr.errors import UserError
from vlr.hand import GraspError

# The tasks' scenes, bands and controllers are the Model O's: one tendon per finger, three.
TENDONS = 3

#: What `achieved_goal` and `desired_goal` hold: their columns of `pose_vector`.
GOAL_COLUMNS = {"position": slice(0, 3), "rotation": slice(3, 6), "pose": slice(0, 6)}

__all__ = ["Move", "HandTaskEnv", "GOAL_COLUMNS", "pose_vector", "save_figure"]


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
    """Base class of the tasks; subclasses set `object_name`, `controller_config`,
    `goal_rows` and fill `_start_task`, `_task_step`, `_target`, `_goal_reached`,
    `metrics` and `picture`.

    Args:
        backend: "sim" (MuJoCo) or "hardware" (the real hand; needs `hardware_config`).
        render_mode: None or "rgb_array" (a third-person view of the sim scene; on hardware
            the palm camera's frame).
        identify: self-identify the grasp in `reset` (Algorithm 1). Off, `reset` costs a
            grasp and `step` a move and a frame, and there is no filter (`pf` is None, the
            VLR baseline cannot run).
        filter_updates: let the filter update the VLR on every step (with `identify`).
        particles: particle count of the identification in reset.
        identify_iterations: its exploratory moves (all are made, even after convergence).
        max_step: the tendon change of an action of 1 [m].
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
        expose_truth: put the simulator's ground truth in `info["truth"]` (for scoring;
            a compared policy must not read it).
        reward_type: "sparse" (-1.0 until success, then 0.0) or "dense" (minus the
            distance to the target), as Gymnasium-Robotics' `reward_type`.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 4}
    object_name = "apple"
    controller_config = ControllerConfig()
    goal_rows = "position"   # a key of GOAL_COLUMNS

    def __init__(self, backend: str = "sim", render_mode: str | None = None, *,
                 identify: bool = True, filter_updates: bool = True,
                 particles: int = 3000, identify_iterations: int = 10,
                 max_step: float = 0.4e-3,
                 command_band: tuple[float, float] = (0.25e-3, 0.4e-3),
                 squeeze: float = 0.0,
                 include_image: bool = False, image_size: tuple[int, int] = (120, 160),
                 hardware_config: str | None = None,
                 settings: Mapping[str, Any] | None = None,
                 expose_truth: bool = False, reward_type: str = "sparse") -> None:
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
        if reward_type not in REWARD_TYPES:
            raise ValueError(f"reward_type {reward_type!r}: use one of {REWARD_TYPES}")
        self.reward_type = reward_type
        self.backend = backend
        self.render_mode = render_mode
        self.identify = bool(identify)
        self.filter_updates = bool(filter_updates)
        self.expose_truth = bool(expose_truth)
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
        self.action_space = spaces.Box(-1.0, 1.0, shape=(TENDONS,), dtype=np.float32)
        # Poses: position within 1 m of the palm [m], rotation vector (norm <= pi) [rad];
        # commands within 1 cm of the centre [m] (the band is a fraction of a millimetre).
        pose = np.array([1.0] * 3 + [np.pi] * 3)
        lim = np.concatenate([pose, [0.01] * TENDONS])
        goal = pose[GOAL_COLUMNS[self.goal_rows]]
        obs = {"observation": spaces.Box(-lim, lim, dtype=np.float64),
               "achieved_goal": spaces.Box(-goal, goal, dtype=np.float64),
               "desired_goal": spaces.Box(-goal, goal, dtype=np.float64)}
        self._image_shape: tuple[int, int, int] | None = None
        if include_image:
            self._image_shape = (int(image_size[0]), int(image_size[1]), 3)
            obs["image"] = spaces.Box(0, 255, shape=self._image_shape, dtype=np.uint8)
        self.observation_space = spaces.Dict(obs)
        self.hand = None
        self.pf = None
        self.identification = None
        # Whether the model explained what the identification saw (`vlr.model_check`).
        self.model_check: dict | None = None
        self.moves: list[Move] = []
        self.observation = None      # the latest camera pose (vlr.perception.Observation)
        self.center: np.ndarray | None = None
        self.filter_lost = False
        self.grasp_lost = False
        self.grasp_message = ""
        self.identification_failed = ""   # why the last identification failed, if it did
        self.task_done = False
        self._last_action_m = np.zeros(TENDONS)   # the tendon change of the last step [m]
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
        """The tendon changes [m] (low, high) that keep the commands inside the band and
        within `max_step` now: what `step` would clip an action's change to."""
        release, pull = self.command_band
        u = self.commands
        low = np.maximum(-self.max_step, self.center - release - u)
        high = np.minimum(self.max_step, self.center + pull - u)
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
        self.identification_failed = ""
        self.task_done = False
        self.observation = None
        self._last_action_m = np.zeros(TENDONS)
        try:
            self._prepare_episode()
            self._identify_grasp()
        except (GraspError, FloatingPointError) as exc:
            # No VLR to start from (no tag seen after the grasp, no particle settled): the
            # episode ends at the first step, with the reason in info.
            self.identification_failed = f"{type(exc).__name__}: {exc}"
            return self._get_obs(), self._info()
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
        self.pf = self.identification = self.model_check = None
        if not self.identify:
            self._grasp_only(settings.loop.first_observation_frames)
            self._go_to_centre()
            return
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
            self.model_check = run.summary.get("model_check")
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
        self._go_to_centre()

    def _grasp_only(self, frames: int) -> None:
        """`reset` without identification: grasp and wait for the tag (at most `frames`)."""
        self.hand.grasp()
        self._u = np.asarray(self.hand.commands, dtype=float).copy()
        for _ in range(frames):
            obs = self._observe()
            self.moves.append(Move(self._u.copy(), obs))
            if obs is not None:
                self.observation = obs
                return
        raise GraspError(f"the object's tag was not seen in {frames} frames after the grasp")

    def _go_to_centre(self) -> None:
        """Move the commands to the task's centre: the grasp command (identification's
        exploration leaves the commands anywhere in its band), plus the squeeze."""
        self.center = self.moves[0].commands + self.squeeze
        while np.max(np.abs(self.center - self.commands)) > 1e-9 and not self.grasp_lost:
            before = self.commands
            self._apply(np.clip(self.center - self.commands, -self.max_step, self.max_step))
            if np.array_equal(before, self.commands):   # the backend clipped the move away
                raise UserError(f"the task's centre command {np.round(self.center * 1e3, 3)}"
                                " mm cannot be reached (the backend's command range; "
                                "squeeze?)")

    def step(self, action):
        a = np.asarray(action, dtype=float)
        if a.shape != (TENDONS,):
            raise ValueError(f"action {action!r}: shape {a.shape}, expected ({TENDONS},)")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action {a.tolist()} is not finite")
        if not self.identification_failed:   # else reset found no VLR: the episode truncates
            u = self.commands
            release, pull = self.command_band
            target = np.clip(u + np.clip(a, -1.0, 1.0) * self.max_step,
                             self.center - release, self.center + pull)
            self._apply(target - u)
            self._last_action_m = self.commands - u
            self.task_done = bool(self._task_step())
        obs, info = self._get_obs(), self._info()
        achieved, desired = obs["achieved_goal"], obs["desired_goal"]
        return (obs, float(self.compute_reward(achieved, desired, info)),
                self.compute_terminated(achieved, desired, info),
                self.compute_truncated(achieved, desired, info), info)

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                       info: Any = None) -> np.ndarray | float:
        """The reward of goals (..., n), vectorised over leading dimensions as
        Gymnasium-Robotics' goal environments' (HER relabels with it). Sparse: -1.0, or 0.0
        where the goals are within the task's tolerance (`_is_success`); dense: minus their
        distance, position in mm, rotation in degrees, a pose as Eq. 12's weighted error (mm
        and `alpha` x degrees, the task's `controller_config`). `info` (None, a dict, or one
        per goal) matters only where the identification failed (`identification_failed`):
        no pose was seen, so no success either."""
        if self.reward_type == "sparse":
            success = self._is_success(achieved_goal, desired_goal)
            failed = _info_flags(info, "identification_failed")
            return np.where(failed, 0.0, success) - 1.0
        pos_mm, rot_deg = _goal_distances(self.goal_rows, achieved_goal, desired_goal)
        if self.goal_rows == "position":
            d = pos_mm
        elif self.goal_rows == "rotation":
            d = rot_deg
        else:
            d = np.hypot(pos_mm, self.controller_config.alpha * rot_deg)
        return 0.0 - d   # (not -d: no -0.0 at the target)

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                           info: Any) -> bool | np.ndarray:
        """Whether the episode ends in the task: it is done (`info["task_done"]`: every
        target visited) or the grasp is lost (`info["grasp_lost"]`). The task's progress, not
        the goals, decides, as Gymnasium-Robotics allows through `info`; a bool for one info
        dict, an array for a batch of them."""
        done = _info_flags(info, "task_done") | _info_flags(info, "grasp_lost")
        return bool(done) if done.ndim == 0 else done

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                          info: Any) -> bool | np.ndarray:
        """Whether the episode is cut short outside the task: the identification in reset
        failed (`info["identification_failed"]`), or, under `VLR_SMOKE` (`vlr.smoke`), a smoke
        test's few moves are recorded (`info["moves"]`). The step limit is gymnasium's
        `TimeLimit`'s, as for Fetch. A bool for one info dict, an array for a batch."""
        cut = _info_flags(info, "identification_failed")
        if smoke.active():
            cut = cut | (_info_values(info, "moves", int) >= smoke.TASK_MOVES)
        return bool(cut) if cut.ndim == 0 else cut

    def _is_success(self, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """1.0 where goals (..., n) are within the task's tolerance (`_goal_reached`), else
        0.0; vectorised, as Fetch's."""
        pos_mm, rot_deg = _goal_distances(self.goal_rows, achieved_goal, desired_goal)
        return np.asarray(self._goal_reached(pos_mm, rot_deg), dtype=float)

    def _goal_reached(self, pos_mm: np.ndarray, rot_deg: np.ndarray) -> np.ndarray | bool:
        """Whether distances (position mm, rotation degrees) are within the task's
        tolerance (`info["is_success"]`)."""
        raise NotImplementedError

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
        if self.pf is None or self.filter_lost or not self.filter_updates:
            return
        try:
            self.pf.step(u, obs)
        except FloatingPointError:  # every particle's solve failed: the VLR is lost
            self.filter_lost = True

    def render(self):
        if self.render_mode != "rgb_array" or self.hand is None:
            return None
        if self.backend == "sim":
            from vlr.sim.camera import render_scene

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
        cols = GOAL_COLUMNS[self.goal_rows]
        if o is None:   # no pose seen (a failed identification)
            pose = np.zeros(6)
            achieved = desired = pose[cols]
            rel = np.zeros(TENDONS)
        else:
            pose = pose_vector(o.position, o.rotation)
            achieved, desired = pose[cols], self._target_vector()[cols]
            rel = self.commands - (self.center if self.center is not None else self.commands)
        out = {"observation": np.concatenate([pose, rel]), "achieved_goal": achieved.copy(),
               "desired_goal": desired.copy()}
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
        info: dict[str, Any] = {"commands": self.commands,
                                "action_m": self._last_action_m.copy(),
                                "tag_seen": seen, "filter_lost": self.filter_lost,
                                "grasp_lost": self.grasp_lost,
                                "identification_failed": self.identification_failed,
                                "task_done": self.task_done, "moves": len(self.moves)}
        if self.observation is None or self.identification_failed:
            info["is_success"] = 0.0
            return info
        info.update(self._task_info())
        pose = pose_vector(self.observation.position, self.observation.rotation)
        cols = GOAL_COLUMNS[self.goal_rows]
        info["is_success"] = float(self._is_success(pose[cols], self._target_vector()[cols]))
        if self.expose_truth and self.backend == "sim" and self.has_truth:
            t = self.hand.truth()
            info["truth"] = {"pom_position": t.pom_position.copy(),
                             "pom_rotation": t.pom_rotation.copy(), **self._truth_info()}
        return info

    def baseline(self, **changes: Any):
        """The VLR baseline policy for this env (`tasks.baseline.VLRBaseline`), with optional
        changes to the task's controller settings (e.g. method="transpose")."""
        from vlr.tasks.baseline import VLRBaseline

        return VLRBaseline(self, **changes)

    # ------------------------------------------------------------------ for subclasses
    def _prepare_episode(self) -> None:
        """Set the scene up before the grasp (cups: arrange the table, move the arm)."""

    def _start_task(self) -> None:
        raise NotImplementedError

    def _task_step(self) -> bool:
        """Advance the task after a move; returns whether the task is done."""
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


def _goal_distances(rows: str, achieved: np.ndarray,
                    desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position distance [mm], rotation angle [deg]) between goals (..., n) of `rows`
    (`GOAL_COLUMNS`); a part the goals do not hold is 0."""
    from scipy.spatial.transform import Rotation

    a, d = np.asarray(achieved, dtype=float), np.asarray(desired, dtype=float)
    lead = np.broadcast_shapes(a.shape, d.shape)[:-1]
    a, d = np.broadcast_to(a, lead + a.shape[-1:]), np.broadcast_to(d, lead + d.shape[-1:])
    zero = np.zeros(lead)
    pos = np.linalg.norm(a[..., :3] - d[..., :3], axis=-1) * 1e3 if rows != "rotation" else zero
    if rows == "position":
        return pos, zero
    # (Copies: scipy wants writable arrays, and broadcast views are read-only.)
    ra, rd = np.array(a[..., -3:]).reshape(-1, 3), np.array(d[..., -3:]).reshape(-1, 3)
    rel = Rotation.from_rotvec(rd) * Rotation.from_rotvec(ra).inv()
    return pos, np.degrees(rel.magnitude()).reshape(lead)


def _info_values(info: Any, key: str, kind: type) -> np.ndarray:
    """`kind(info[key])` (`kind()` where the key is missing) as an array: 0-d for one info dict
    or None, shaped like a batch of them (a list or an object array of dicts, as HER passes,
    or a vector env's info, a dict of arrays)."""
    if info is None or isinstance(info, Mapping):
        value = (info or {}).get(key, kind())
        if isinstance(value, np.ndarray):   # a vector env's: one value per env
            return value.astype(kind)
        return np.asarray(kind(value))
    batch = np.asarray(info, dtype=object)
    values = [kind(i.get(key, kind())) if isinstance(i, Mapping) else kind()
              for i in batch.flat]
    return np.asarray(values, dtype=kind).reshape(batch.shape)


def _info_flags(info: Any, key: str) -> np.ndarray:
    """`info[key]`'s truth (`_info_values`): a message or a flag, False where missing."""
    return _info_values(info, key, bool)


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
