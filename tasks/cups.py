"""Cup stacking (METHOD.md 6): the hand on an arm picks four cups in decreasing size, each
grasped at an unknown tilt, corrects each in the hand (weighted SE(3), Eq. 12, alpha 9.5)
and stacks them on the target cup.

Geometry, and why. The cups (models/objects/cup1..5.yaml) carry their tag under the bottom,
so the palm camera sees the tag only when the palm faces the bottom: the cups stand upside
down on the table and the hand comes from above, palm down. Upside-down cups stack as a
tower, not nested: each cup's rim rests on the upturned bottom of the next larger cup
(radii 40, 36, 32, 28, 24 mm: a cup's rim lies on the bottom below it if its axis is within
4 mm of that cup's axis), and every tag stays visible from above. So the target cup1 stands
upside down at `TARGET_XY`, and cups 2, 3, 4, 5 are picked in decreasing size and placed on
top, each on the one before.

Each cup but the target rests tilted on a small support block under one side of its rim
(tilt `tilt_deg`, a seeded direction within 30 degrees of +-x, between the fingers, and a
seeded yaw), so its pose in the hand after the pick is unknown. The arm (`sim.scenes.
CupsHand`: three servoed wrist joints, palm down; its pose is its own known kinematics)
takes the hand over the cup's nominal place on the table (it does not know the tilt), the
fingers close, the arm lifts, and the filter identifies the grasp (Algorithm 1).

Per cup the task is then: the in-hand target pose is the camera's POM position after the
identification with the cup levelled (its axis along the palm normal, yaw kept). The policy
moves the tendons (weighted SE(3) error: [dx, dy, dz] in mm and alpha [droll, dpitch, dyaw]
in degrees, alpha 9.5) until the camera puts the POM within `tolerance_mm` and
`tolerance_deg` of the target or `steps_per_cup` moves are spent. The arm then carries the
cup over the stack and lowers it so that the target in-hand pose would sit exactly on the
stack (the arm plans with the target, not the true pose: the hand's remaining error is the
placement error), stopping `clearance` above contact as the camera sees the cup. The errors
at release are the true in-hand pose's distance from the target (sim) just before the hand
opens: position [mm], rotation angle [deg] (the whole rotation, yaw included, though a
cylinder does not care about yaw; the tilt alone is reported too). Then the hand opens, the
cup drops the last millimetres, the arm lifts and goes to the next cup, which is picked and
identified inside the same `step` (an episode is one stack of four cups: only the first
identification runs in `reset`).

On hardware: there is no arm driver in this project, so the env refuses the hardware backend
with a UserError naming what it would need (an arm with a wrist pose command, palm down).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tasks.base import HandTaskEnv, save_figure
from tasks.maze import axis_angle
from vlr.controller import ControllerConfig, pose_error, row_weights
from vlr.errors import UserError
from vlr.hand import GraspError
from vlr.motion import rotvec_to_matrix
from vlr.observation import rotation_angle

__all__ = ["TARGET_XY", "PICK_XY", "PICK_HEIGHT", "CupStackingEnv"]

TARGET_XY = (0.0, 0.0)                    # m, world: the target cup1
PICK_XY = ((0.13, 0.0), (0.26, 0.0), (0.39, 0.0), (0.52, 0.0))   # cups 2..5 on the table
PICK_HEIGHT = 0.07      # m, palm to tag at the pick: the sim's fingertip grasp of a cup
                        # holds there (at the cup specs' 0.055 the proximal links touch)
CARRY_CLEARANCE = 0.05  # m above the stack while the arm carries a cup
CUPS = ("cup1", "cup2", "cup3", "cup4", "cup5")


def _quat(rot: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, dtype=float).ravel())
    return q


class CupStackingEnv(HandTaskEnv):
    """`vlr/CupStacking-v0` (module docstring).

    Args (besides `HandTaskEnv`'s):
        n_cups: cups to stack on the target (1-4; the paper: 4).
        tilt_deg: (low, high) of the seeded tilt of each cup on its support [deg].
        tolerance_mm, tolerance_deg: a cup's in-hand target counts as reached within both.
        steps_per_cup: move budget of the in-hand correction of one cup.
        clearance: the arm stops the cup's lowest rim point this far above the stack [m].
        command_band: as `HandTaskEnv`'s (its default: with the palm down, gravity pulls
            the cup out of the grasp, and a 0.4 mm release lost a fingertip on seed 0).
    """

    object_name = "cup2"
    controller_config = ControllerConfig(rows="full", alpha=9.5, method="dls", secant=True,
                                         tolerance_pos=0.3e-3,
                                         tolerance_rot=float(np.radians(0.3)))

    def __init__(self, backend: str = "sim", render_mode: str | None = None, *,
                 n_cups: int = 4, tilt_deg: tuple[float, float] = (5.0, 10.0),
                 tolerance_mm: float = 0.3, tolerance_deg: float = 0.3,
                 steps_per_cup: int = 20, clearance: float = 0.002,
                 command_band: tuple[float, float] = (0.25e-3, 0.4e-3),
                 **kwargs: Any) -> None:
        if backend == "hardware":
            raise UserError("cup stacking needs an arm (a wrist pose command, palm down, "
                            "over the cups): this project has no arm driver, so the task "
                            "runs in the sim only")
        super().__init__(backend, render_mode, command_band=command_band, **kwargs)
        if not isinstance(n_cups, int) or not 1 <= n_cups <= 4:
            raise ValueError(f"n_cups {n_cups!r} must be 1..4")
        lo, hi = (float(v) for v in tilt_deg)
        if not 0 <= lo <= hi <= 15:
            raise ValueError(f"tilt_deg {tilt_deg!r}: need 0 <= low <= high <= 15")
        if tolerance_mm <= 0 or tolerance_deg <= 0 or steps_per_cup < 1 or clearance < 0:
            raise ValueError("tolerance_mm, tolerance_deg, steps_per_cup must be positive, "
                             "clearance >= 0")
        self.n_cups = n_cups
        self.tilt_range = (lo, hi)
        self.tolerance = (tolerance_mm * 1e-3, float(np.radians(tolerance_deg)))
        self.steps_per_cup = int(steps_per_cup)
        self.clearance = float(clearance)
        self.records: list[dict[str, Any]] = []
        self.cup = 1                     # index into CUPS of the cup in the hand
        self.layout: dict[str, dict[str, float]] = {}

    def _open_hand(self):
        from sim.scenes import CupsHand

        return CupsHand(CUPS, seed=0)

    def _motion_config(self):
        from vlr.motion import MotionConfig

        # Gravity in the palm frame from the arm's known pose (palm down: +z).
        return MotionConfig(gravity=tuple(float(g) for g in self.hand.gravity_in_palm()))

    # ------------------------------------------------------------------ the table
    def _prepare_episode(self) -> None:
        """Reset the scene, lay the table out (seeded tilts), take the arm to cup 2."""
        hand = self.hand
        hand.reset_scene()
        rng = self.np_random
        poses, supports = {}, {}
        self.layout = {}
        for k, name in enumerate(CUPS):
            spec = hand.cups[name]
            r = spec.size[0]
            depth = _rim_depth(spec)
            down = np.diag([1.0, -1.0, -1.0])          # upside down: z_O points down
            if k == 0:
                xy, tilt, phi, yaw = np.array(TARGET_XY), 0.0, 0.0, 0.0
            else:
                xy = np.array(PICK_XY[k - 1])
                tilt = float(np.radians(rng.uniform(*self.tilt_range)))
                phi = float(np.radians(rng.uniform(-30, 30)) + (np.pi if rng.random() < 0.5
                                                               else 0.0))
                yaw = float(rng.uniform(-np.pi, np.pi))
            d = np.array([np.cos(phi), np.sin(phi), 0.0])      # the raised side
            tilt_rot = rotvec_to_matrix(-np.cross(np.array([0.0, 0.0, 1.0]), d) * tilt)
            rot = tilt_rot @ rotvec_to_matrix(np.array([0.0, 0.0, yaw])) @ down
            rim_centre = np.array([xy[0], xy[1], r * np.sin(tilt)])
            poses[name] = (rim_centre - depth * rot[:, 2], _quat(rot))
            if k == 0:
                supports[name] = np.array([0.6, 0.45, 0.005])   # not needed: parked
            else:
                sup = np.array([xy[0], xy[1], 0.0]) + d * r * np.cos(tilt)
                sup[2] = 2 * r * np.sin(tilt) - 0.005       # block top under the rim
                supports[name] = sup
            self.layout[name] = {"tilt_deg": float(np.degrees(tilt)),
                                 "direction_deg": float(np.degrees(phi)),
                                 "yaw_deg": float(np.degrees(yaw))}
        hand.arrange(poses, supports)
        self.records = []
        self.cup = 1
        self._go_pick()

    def _go_pick(self) -> None:
        """Take the open hand over the current cup's nominal place and lower it to the
        pick height (the arm knows where the cups stand, not how they tilt)."""
        hand = self.hand
        name = CUPS[self.cup]
        spec = hand.cups[name]
        x, y = PICK_XY[self.cup - 1]
        pos, _ = hand.arm_pose()
        top = self._stack_top() + _rim_depth(hand.cups[CUPS[0]]) + 0.15
        hand.move_arm([pos[0], pos[1], max(pos[2], top)])
        hand.move_arm([x, y, max(pos[2], top)])
        hand.move_arm([x, y, _rim_depth(spec) + PICK_HEIGHT], speed=0.1)
        hand.select(name)

    def _stack_top(self) -> float:
        """Height of the stack's top face (the upturned bottom of its last cup) [m]."""
        return float(sum(2 * self.hand.cups[CUPS[k]].size[1] for k in range(self.cup)))

    # ------------------------------------------------------------------ task hooks
    def _start_task(self) -> None:
        obs = self.observation
        rot = np.asarray(obs.rotation, dtype=float)
        n = rot[:, 2]                      # the cup's axis, tag to rim
        z = np.array([0.0, 0.0, 1.0])      # the palm normal: level when the palm faces down
        axis = np.cross(n, z)
        s = np.linalg.norm(axis)
        fix = np.eye(3) if s < 1e-12 else axis_angle(axis, np.arctan2(s, n @ z))
        self.goal = (np.asarray(obs.position, dtype=float).copy(), fix @ rot)
        self.steps_here = 0
        self.start_error = self._true_error() if self.has_truth else None

    def _target(self) -> tuple[np.ndarray, np.ndarray]:
        return self.goal

    def _camera_errors(self) -> tuple[float, float]:
        pos, rot = self.goal
        return (float(np.linalg.norm(np.asarray(self.observation.position) - pos)),
                float(rotation_angle(np.asarray(self.observation.rotation), rot)))

    def _weighted_error(self) -> float:
        """|Delta phi'| of Eq. 12 (mm and alpha x degrees) from the camera pose."""
        o = self.observation
        pos, rot = self.goal
        e = pose_error(o.position, o.rotation, pos, rot)
        return float(np.linalg.norm(row_weights("full", self.controller_config.alpha) * e))

    def _true_error(self) -> dict[str, float]:
        t = self.hand.truth()
        pos, rot = self.goal
        z = t.pom_rotation[:, 2]
        return {"position_mm": float(np.linalg.norm(t.pom_position - pos) * 1e3),
                "rotation_deg": float(np.degrees(rotation_angle(t.pom_rotation, rot))),
                "tilt_deg": float(np.degrees(np.arccos(np.clip(z[2], -1, 1))))}

    def _task_step(self) -> tuple[float, bool]:
        if self.cup > self.n_cups:
            return 0.0, True
        self.steps_here += 1
        reward = -self._weighted_error()
        pos_err, rot_err = self._camera_errors()
        reached = pos_err <= self.tolerance[0] and rot_err <= self.tolerance[1]
        if reached or self.steps_here >= self.steps_per_cup or self.grasp_lost:
            self._place(pos_err, rot_err, reached)
            if self.cup <= self.n_cups and not self.grasp_lost:
                try:
                    self._go_pick()
                    self._identify_grasp()
                except GraspError as exc:    # the pick failed: the episode ends here
                    self.grasp_lost, self.grasp_message = True, str(exc)
                    return reward, True
                self._start_task()
        return reward, self.cup > self.n_cups

    def _place(self, pos_err: float, rot_err: float, reached: bool) -> None:
        """Carry the cup over the stack, lower it, record the errors, open, lift."""
        hand = self.hand
        name = CUPS[self.cup]
        spec = hand.cups[name]
        pos, rot = self.goal
        wrist_pos, wrist_rot = hand.arm_pose()
        # Where the target in-hand pose would put the tag: on the stack's axis, the rim on
        # the stack top. The camera's view of the cup sets how far above to stop: its
        # lowest rim point `clearance` above the top.
        o = self.observation
        tilt = float(np.arccos(np.clip(np.asarray(o.rotation)[2, 2], -1, 1)))
        drop = self.clearance + spec.size[0] * np.sin(tilt)
        tag = np.array([TARGET_XY[0], TARGET_XY[1],
                        self._stack_top() + _rim_depth(spec) + drop])
        wrist = tag - wrist_rot @ pos
        carry = self._stack_top() + _rim_depth(spec) + pos[2] + CARRY_CLEARANCE
        hand.move_arm([wrist_pos[0], wrist_pos[1], max(carry, wrist_pos[2])])
        hand.move_arm([wrist[0], wrist[1], max(carry, wrist_pos[2])])
        hand.move_arm(wrist, speed=0.05)
        obs = self._observe()
        if obs is not None:
            self.observation = obs
        cam_pos, cam_rot = self._camera_errors()
        rec: dict[str, Any] = {"cup": name, "steps": self.steps_here, "reached": reached,
                               "camera_position_mm": cam_pos * 1e3,
                               "camera_rotation_deg": float(np.degrees(cam_rot)),
                               "grasp_lost": self.grasp_lost,
                               "table_tilt_deg": self.layout[name]["tilt_deg"]}
        if self.has_truth:
            rec.update(self._true_error())
            if self.start_error is not None:
                rec["before_correction"] = self.start_error
        self.records.append(rec)
        hand.release()
        up, _ = hand.arm_pose()
        hand.move_arm([up[0], up[1], up[2] + 0.05], speed=0.1)
        self.cup += 1

    def _task_info(self) -> dict[str, Any]:
        done = self.cup > self.n_cups
        pos_err, rot_err = (0.0, 0.0) if done else self._camera_errors()
        return {"cup": CUPS[min(self.cup, len(CUPS) - 1)], "cups_placed": len(self.records),
                "position_error_mm": pos_err * 1e3,
                "rotation_error_deg": float(np.degrees(rot_err))}

    def _truth_info(self) -> dict[str, Any]:
        return {"cups": {n: self.hand.cup_pose(n)[0] for n in CUPS}}

    # ------------------------------------------------------------------ results
    def stacked(self) -> list[bool]:
        """Ground truth (sim): for each placed cup, whether it rests on the one below: its
        rim's centre within (r_below - r) of the lower cup's axis, its axis within 3 degrees
        of vertical and its rim within 3 mm of the lower cup's top."""
        hand = self.hand
        out = []
        for k in range(1, 1 + len(self.records)):
            lo, hi = hand.cups[CUPS[k - 1]], hand.cups[CUPS[k]]
            p0, r0 = hand.cup_pose(CUPS[k - 1])
            p1, r1 = hand.cup_pose(CUPS[k])
            top0 = p0 + r0[:, 2] * _card(lo)            # the lower cup's bottom face
            rim1 = p1 + r1[:, 2] * _rim_depth(hi)       # this cup's rim centre
            off = float(np.linalg.norm((rim1 - top0)[:2]))
            tilt = float(np.degrees(np.arccos(np.clip(-r1[2, 2], -1, 1))))
            ok = (off <= lo.size[0] - hi.size[0] and tilt <= 3.0
                  and abs(rim1[2] - top0[2]) <= 3e-3)
            out.append(bool(ok))
        return out

    def metrics(self) -> dict[str, Any]:
        """errors.position_mm_mean / rotation_deg_mean (at release, ground truth in the
        sim) over the placed cups, and `cups_stacked` (a tower resting cup on cup, counted
        from the target up)."""
        recs = self.records
        key_p = "position_mm" if self.has_truth else "camera_position_mm"
        key_r = "rotation_deg" if self.has_truth else "camera_rotation_deg"
        p = np.array([r[key_p] for r in recs] or [np.nan])
        r = np.array([r[key_r] for r in recs] or [np.nan])
        stacked = self.stacked() if self.has_truth else []
        tower = 0
        for ok in stacked:
            if not ok:
                break
            tower += 1
        return {"errors": {"position_mm_mean": float(np.mean(p)),
                           "position_mm_sd": float(np.std(p)),
                           "rotation_deg_mean": float(np.mean(r)),
                           "rotation_deg_sd": float(np.std(r)),
                           "tilt_deg_mean": float(np.mean([x.get("tilt_deg", np.nan)
                                                           for x in recs] or [np.nan])),
                           "source": "ground truth" if self.has_truth else "camera",
                           "per_cup": recs},
                "cups_stacked": tower, "cups": self.n_cups,
                "stacked_per_cup": stacked,
                "table": self.layout,
                "moves": int(sum(x["steps"] for x in recs)),
                "grasp_lost": self.grasp_lost, "filter_lost": self.filter_lost}

    def picture(self, path) -> None:
        """The final stack (third-person render) beside the per-cup errors at release."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from sim.camera import render_scene

        img = render_scene(self.hand, camera="stack_camera")
        m = self.metrics()
        fig, (a0, a1) = plt.subplots(1, 2, figsize=(9.5, 4.0),
                                     gridspec_kw={"width_ratios": [1.35, 1]})
        a0.imshow(img)
        a0.axis("off")
        a0.set_title(f"final stack: {m['cups_stacked']}/{self.n_cups} cups stacked",
                     fontsize=9)
        recs = m["errors"]["per_cup"]
        names = [r["cup"] for r in recs]
        x = np.arange(len(recs))
        a1.bar(x - 0.2, [r.get("position_mm", r["camera_position_mm"]) for r in recs], 0.4,
               label="position [mm]", color="tab:blue")
        a1.bar(x + 0.2, [r.get("rotation_deg", r["camera_rotation_deg"]) for r in recs], 0.4,
               label="rotation [deg]", color="tab:red")
        before = [r.get("before_correction", {}).get("rotation_deg") for r in recs]
        if all(b is not None for b in before) and before:
            a1.plot(x + 0.2, before, "k_", ms=14, mew=2, label="rotation before correction")
        a1.set_xticks(x, names)
        a1.axhline(2.1, color="tab:blue", ls=":", lw=1)
        a1.axhline(5.16, color="tab:red", ls=":", lw=1)
        e = m["errors"]
        a1.set_title(f"at release: {e['position_mm_mean']:.2f} mm, "
                     f"{e['rotation_deg_mean']:.2f} deg (paper 2.1 mm, 5.16 deg)", fontsize=8)
        a1.legend(fontsize=7)
        fig.tight_layout()
        save_figure(fig, path)

    def render(self):
        if self.render_mode == "rgb_array" and self.hand is not None:
            from sim.camera import render_scene

            return render_scene(self.hand, camera="cups_camera")
        return super().render()


def _rim_depth(spec) -> float:
    from sim.scenes import cup_rim_depth

    return cup_rim_depth(spec)


def _card(spec) -> float:
    from sim.model import TAG_CARD_THICKNESS

    return TAG_CARD_THICKNESS
