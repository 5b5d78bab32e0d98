"""Task scenes beyond a hand holding one object: the marble maze (tasks/maze.py) and the
cup-stacking table (tasks/cups.py).

`MazeHand` is a `SimHand` whose held object (models/objects/maze_holder.yaml) carries a post
and a maze plate with walls, plus a marble: a free body parked off the plate (welded to the
world) until `place_marble` puts it on the plate, as the paper places the marble after
identification. The maze's walls come from the task as segments in the plate frame (origin
at the plate's top centre, axes those of the object frame O), so that the layout lives with
the task and the sim only builds it.

`CupsHand` is a `SimHand` on an arm: the palm rides on three servoed slide joints (the wrist of
an arm with known kinematics, moved by `move_arm`; its orientation is fixed), palm facing down
over a table with five upright nesting cups (models/objects/cup1.yaml to cup5.yaml), their tags
on the inside bottom where the palm camera sees them through the opening when the hand comes
from above. Each cup but the target rests tilted on a small support block under one side of its
bottom (a 12 x 20 mm block whose height sets the tilt), so its pose in the hand after a pick is
unknown. The held object is whichever cup `select` names; `grasp` picks it where it stands (no
reset: the rest of the table keeps its state).

Ground truth here (marble position, plate pose, cup poses) is for scoring and `info` only.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

os.environ.setdefault("MUJOCO_GL", "egl")
# Mesa's llvmpipe renders on threads of its own, which a fork() does not copy: a process
# forked after a frame was rendered (gymnasium's AsyncVectorEnv, Stable-Baselines3's
# SubprocVecEnv) waits for them for ever. On the caller's thread it is fork-safe.
os.environ.setdefault("LP_NUM_THREADS", "0")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from dm_control import mjcf  # noqa: E402
from vlr.sim.backend import SimHand, SimOptions  # noqa: E402
from vlr.sim.model import (  # noqa: E402
    SOLREF,
    TAG_CARD_THICKNESS,
    build_hand,
    build_object,
    build_scene,
    cup_dimensions,
)

from vlr.hand import ApplyReport, GraspError  # noqa: E402
from vlr.spec import HandSpec, ObjectSpec, load_object  # noqa: E402

__all__ = ["plate_mount", "build_maze_scene", "MazeHand", "CUPS", "build_cups_scene",
           "CupsHand", "cup_floor_depth"]

MARBLE_PARK = (0.30, 0.0, 0.02)     # m, world: off the hand, out of every view
MARBLE_COLOR = (0.15, 0.35, 0.85, 1.0)
WALL_COLOR = (0.92, 0.92, 0.88, 1.0)
PLATE_COLOR = (0.80, 0.80, 0.75, 1.0)


def plate_mount(obj: ObjectSpec) -> tuple[np.ndarray, np.ndarray]:
    """The plate frame in the object frame O: its origin (the plate's top centre) [m] and
    rotation. The plate sits on the post, turned by `plate_tilt_deg` about x_O."""
    e = obj.extras
    a = math.radians(float(e.get("plate_tilt_deg", 0.0)))
    rot = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    pivot = np.array([0.0, 0.0, TAG_CARD_THICKNESS + 2 * obj.size[2] + e["post_height"]])
    return pivot + rot @ np.array([0.0, 0.0, e["plate_thickness"]]), rot


def _maze_inertia(obj: ObjectSpec) -> list[float]:
    """Diagonal inertia [kg m^2] of handle + post + plate about the spec's centre of mass
    (the parts as boxes and a rod, parallel-axis terms along z)."""
    e = obj.extras
    hx, hy, hz = obj.size
    zc = obj.com[2]
    c = TAG_CARD_THICKNESS
    parts = [  # mass, half extents, centre z
        (e["handle_mass"], (hx, hy, hz), c + hz),
        (e["post_mass"], (e["post_radius"],) * 2 + (e["post_height"] / 2,),
         c + 2 * hz + e["post_height"] / 2),
        (e["plate_mass"], (e["plate_half"], e["plate_half"], e["plate_thickness"] / 2),
         c + 2 * hz + e["post_height"] + e["plate_thickness"] / 2)]
    ixx = iyy = izz = 0.0
    for m, (a, b, h), z in parts:
        d2 = (z - zc) ** 2
        ixx += m * ((2 * b) ** 2 + (2 * h) ** 2) / 12 + m * d2
        iyy += m * ((2 * a) ** 2 + (2 * h) ** 2) / 12 + m * d2
        izz += m * ((2 * a) ** 2 + (2 * b) ** 2) / 12
    return [ixx, iyy, izz]


def build_maze_scene(hand: HandSpec, obj: ObjectSpec, walls: Sequence[Sequence[float]], *,
                     width: int = 640, height: int = 480,
                     fovy_deg: float = 60.0) -> mjcf.RootElement:
    """The hand holding the maze holder: `build_scene`, plus post, plate, the walls (each
    (x0, y0, x1, y1) in the plate frame [m], axis-aligned) and the parked marble."""
    e = obj.extras
    root = build_scene(hand, obj, width=width, height=height, fovy_deg=fovy_deg)
    body = root.find("body", "object/object")
    body.inertial.diaginertia = _maze_inertia(obj)
    col = dict(condim=3, friction=[0.6, 0.005, 0.0001], group=2)
    base = TAG_CARD_THICKNESS + 2 * obj.size[2]
    body.add("geom", name="post", type="cylinder", size=[e["post_radius"],
             e["post_height"] / 2], pos=[0, 0, base + e["post_height"] / 2], mass=0,
             rgba=list(obj.rgba), **col)
    # The plate and its walls: a massless child body on the post, turned by the mount
    # (its mass is in the object's inertial above).
    a = math.radians(float(e.get("plate_tilt_deg", 0.0)))
    maze = body.add("body", name="maze", pos=[0, 0, base + e["post_height"]],
                    quat=[math.cos(a / 2), math.sin(a / 2), 0, 0])
    th = e["plate_thickness"]
    maze.add("geom", name="plate", type="box", size=[e["plate_half"], e["plate_half"], th / 2],
             pos=[0, 0, th / 2], mass=0, rgba=list(PLATE_COLOR), **col)
    t, hw = e["wall_thickness"] / 2, e["wall_height"] / 2
    for k, (x0, y0, x1, y1) in enumerate(walls):
        half = [abs(x1 - x0) / 2 + t, abs(y1 - y0) / 2 + t, hw]
        maze.add("geom", name=f"wall{k}", type="box", size=half,
                 pos=[(x0 + x1) / 2, (y0 + y1) / 2, th + hw], mass=0,
                 rgba=list(WALL_COLOR), **col)
    maze.add("site", name="plate_top", pos=[0, 0, th], size=[0.001])
    marble = root.worldbody.add("body", name="marble", pos=list(MARBLE_PARK))
    marble.add("freejoint", name="marble_free")
    marble.add("geom", name="marble", type="sphere", size=[e["marble_radius"]],
               mass=e["marble_mass"], rgba=list(MARBLE_COLOR), condim=3,
               friction=[0.6, 0.005, 0.0001], group=2)
    root.equality.add("weld", name="marble_hold", body1="marble")
    # A view of the plate from above and in front, for render_mode="rgb_array".
    root.worldbody.add("camera", name="maze_camera", pos=[0.0, -0.20, 0.34],
                       xyaxes=[1, 0, 0, 0, 0.72, 0.69], fovy=45)
    return root


class MazeHand(SimHand):
    """A `SimHand` holding the maze holder, with a marble (module docstring).

    Args:
        walls: maze walls, (x0, y0, x1, y1) per wall in the plate frame [m].
        object: the holder spec (name or ObjectSpec) with the maze `extras`.
    """

    def __init__(self, walls: Sequence[Sequence[float]], object: str | ObjectSpec =
                 "maze_holder", hand: str | HandSpec = "modelo", seed: int = 0,
                 options: SimOptions | None = None) -> None:
        spec = object if isinstance(object, ObjectSpec) else load_object(object)
        walls = [tuple(float(v) for v in w) for w in walls]

        def builder(hand_spec, obj_spec, **kw):
            return build_maze_scene(hand_spec, obj_spec, walls, **kw)

        super().__init__(object=spec, hand=hand, seed=seed, options=options, scene=builder)
        m = self.model
        self._marble_body = m.body("marble").id
        self._marble_qadr = m.joint("marble_free").qposadr[0]
        self._marble_dadr = m.joint("marble_free").dofadr[0]
        self._marble_weld = m.equality("marble_hold").id
        self._plate_site = m.site("object/plate_top").id
        self.marble_radius = float(spec.extras["marble_radius"])

    def place_marble(self, xy: Sequence[float]) -> None:
        """Put the marble at rest on the plate at `xy` of the plate frame [m] and free it."""
        d = self.data
        mujoco.mj_forward(self.model, d)
        rot = d.site_xmat[self._plate_site].reshape(3, 3)
        p = d.site_xpos[self._plate_site] + rot @ np.array(
            [xy[0], xy[1], self.marble_radius + 1e-4])
        q = self._marble_qadr
        d.qpos[q:q + 3] = p
        d.qpos[q + 3:q + 7] = [1, 0, 0, 0]
        d.qvel[self._marble_dadr:self._marble_dadr + 6] = 0.0
        d.eq_active[self._marble_weld] = 0
        mujoco.mj_forward(self.model, d)

    def wait(self, seconds: float) -> None:
        """Let time pass with the tendon commands held (the marble rolls)."""
        n = int(round(seconds / self.model.opt.timestep))
        if n > 0:
            mujoco.mj_step(self.model, self.data, nstep=n)

    def marble_on_plate(self) -> np.ndarray:
        """Ground truth: the marble centre in the plate frame [m] (scoring only)."""
        d = self.data
        rot = d.site_xmat[self._plate_site].reshape(3, 3)
        return rot.T @ (d.xpos[self._marble_body] - d.site_xpos[self._plate_site])

    def plate_tilt_deg(self) -> float:
        """Ground truth: the plate normal's angle from the world vertical [deg]."""
        z = self.data.site_xmat[self._plate_site].reshape(3, 3)[:, 2]
        return float(math.degrees(math.acos(np.clip(z[2], -1.0, 1.0))))


# --------------------------------------------------------------------------- cup stacking

CUPS = ("cup1", "cup2", "cup3", "cup4", "cup5")   # largest (the target) first
ARM_HOME = (0.0, -0.25, 0.45)     # m, world: the wrist's start, palm facing down
PALM_DOWN = (0.0, 1.0, 0.0, 0.0)  # quat (w, x, y, z): the palm turned by pi about x
ARM_KP, ARM_KV, ARM_DAMPING = 2.0e4, 400.0, 50.0   # N/m, N s/m: a stiff arm's position loop
TABLE_COLOR = (0.55, 0.45, 0.35, 1.0)
SUPPORT_COLOR = (0.30, 0.30, 0.30, 1.0)


def cup_floor_depth(obj: ObjectSpec) -> float:
    """How far the cup's outer bottom face lies from its tag along z_O [m]: the height of
    O above the table when the cup stands level (`sim.model.cup_dimensions`)."""
    return cup_dimensions(obj)["floor_depth"]


def build_cups_scene(hand: HandSpec, obj: ObjectSpec, cups: Sequence[ObjectSpec], *,
                     width: int = 640, height: int = 480,
                     fovy_deg: float = 60.0) -> mjcf.RootElement:
    """The hand on an arm (three servoed slide joints at the wrist, palm down, at
    `ARM_HOME`), a table (top at z = 0), the
    cups as free bodies (`<cup>/object`, weld `<cup>_hold` kept off: no helper here) parked
    in a row, and one mocap support block per cup (placed by `CupsHand.arrange`). `obj` is
    unused (the held cup is chosen at run time); it keeps `SceneBuilder`'s signature."""
    root = build_hand(hand, width=width, height=height, fovy_deg=fovy_deg)
    palm = root.find("body", "palm")
    palm.pos = list(ARM_HOME)
    palm.quat = list(PALM_DOWN)
    palm.gravcomp = 1.0      # the arm carries the palm's own weight
    # The arm: three slide joints at the wrist, each a stiff position servo. A mocap palm
    # would be teleported: contacts see no velocity at a mocap body, so its fingers' friction
    # never lifted a cup (measured); joints give the fingers real velocities. Axes are in the
    # palm frame (turned by pi about x): these point along world +x, +y, +z.
    for name, axis in (("arm_x", [1, 0, 0]), ("arm_y", [0, -1, 0]), ("arm_z", [0, 0, -1])):
        palm.add("joint", name=name, type="slide", axis=axis, damping=ARM_DAMPING,
                 armature=0.5)
        root.actuator.add("position", name=f"{name}_act", joint=name, kp=ARM_KP,
                          kv=ARM_KV, ctrllimited=False)
    root.worldbody.add("geom", name="table", type="box", size=[0.45, 0.30, 0.01],
                       pos=[0.15, 0.0, -0.01], rgba=list(TABLE_COLOR), condim=3,
                       friction=[0.8, 0.005, 0.0001], solref=list(SOLREF), group=2)
    for k, spec in enumerate(cups):
        croot = build_object(spec)
        croot.model = spec.name
        frame = root.worldbody.attach(croot)
        frame.pos = [0.12 * k, 0.35, cup_floor_depth(spec)]
        frame.quat = list(PALM_DOWN)            # upright: z_O (tag to bottom) points down
        frame.add("freejoint", name="object_free")
        root.equality.add("weld", name=f"{spec.name}_hold", body1=f"{spec.name}/object",
                          body2="palm", solref=[0.01, 1], active=False)
        sup = root.worldbody.add("body", name=f"{spec.name}_support", mocap=True,
                                 pos=[0.12 * k, 0.45, 0.005])
        sup.add("geom", name=f"{spec.name}_support", type="box", size=[0.006, 0.010, 0.005],
                rgba=list(SUPPORT_COLOR), condim=3, friction=[0.8, 0.005, 0.0001],
                solref=list(SOLREF), group=2)
    # A view of the table and the stack, for render_mode="rgb_array" and the picture.
    root.worldbody.add("camera", name="cups_camera", pos=[0.24, -0.55, 0.42],
                       xyaxes=[1, 0, 0, 0, 0.55, 0.835], fovy=45)
    root.worldbody.add("camera", name="stack_camera", pos=[0.0, -0.42, 0.30],
                       xyaxes=[1, 0, 0, 0, 0.3, 0.954], fovy=45)
    return root


class CupsHand(SimHand):
    """A `SimHand` on an arm over a table of upright nesting cups (module docstring).

    Args:
        cups: the cup specs (names or ObjectSpec), largest (the target) first.
        hand, seed, options: as `SimHand`'s.
    """

    def __init__(self, cups: Sequence[str | ObjectSpec] = CUPS, hand: str | HandSpec =
                 "modelo", seed: int = 0, options: SimOptions | None = None) -> None:
        specs = [c if isinstance(c, ObjectSpec) else load_object(c) for c in cups]
        if len(specs) < 2:
            raise ValueError("cup stacking needs a target cup and at least one more")
        self.cups = {s.name: s for s in specs}

        def builder(hand_spec, obj_spec, **kw):
            return build_cups_scene(hand_spec, obj_spec, specs, **kw)

        super().__init__(object=specs[1], hand=hand, seed=seed, options=options,
                         scene=builder, held=specs[1].name)
        m = self.model
        self._palm = m.body("palm").id
        self._arm_act = np.array([m.actuator(f"{n}_act").id for n in ("arm_x", "arm_y",
                                                                        "arm_z")])
        self._cup_qadr = {n: m.joint(f"{n}/object_free/").qposadr[0] for n in self.cups}
        self._cup_dadr = {n: m.joint(f"{n}/object_free/").dofadr[0] for n in self.cups}
        self._cup_body = {n: m.body(f"{n}/object").id for n in self.cups}
        self._support = {n: m.body_mocapid[m.body(f"{n}_support").id] for n in self.cups}
        self.held = specs[1].name

    def _reset_state(self) -> None:
        super()._reset_state()
        self.data.eq_active[:] = 0     # no helper welds here: picks are physical
        mujoco.mj_forward(self.model, self.data)

    def reset_scene(self) -> None:
        """Everything back to the model's initial state: hand open, arm home, cups parked."""
        self._reset_state()
        self.select(next(iter(self.cups)) if self.held not in self.cups else self.held)

    # ----------------------------------------------------------------- the arm
    def arm_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The wrist (palm frame) in the world: position [m] and rotation (3, 3): the arm's
        own kinematics, known to the controller."""
        d = self.data
        return d.xpos[self._palm].copy(), d.xmat[self._palm].reshape(3, 3).copy()

    def gravity_in_palm(self) -> np.ndarray:
        """Gravity in the palm frame [m/s^2], from the arm's pose (for the motion model)."""
        _, rot = self.arm_pose()
        return rot.T @ np.asarray(self.model.opt.gravity)

    def move_arm(self, position: Sequence[float], speed: float = 0.25) -> None:
        """Move the wrist in a straight line to `position` [m] at `speed` [m/s] (a smooth
        ramp, physics stepping, tendon commands held), then let the held cup settle."""
        d = self.data
        home = np.asarray(ARM_HOME)
        start = d.ctrl[self._arm_act] + home
        goal = np.asarray(position, dtype=float)
        n = max(1, int(np.linalg.norm(goal - start) / speed / self.model.opt.timestep))
        for k in range(1, n + 1):
            s = k / n
            s = s * s * (3 - 2 * s)                 # smoothstep: no jerk at the ends
            d.ctrl[self._arm_act] = start + (goal - start) * s - home
            mujoco.mj_step(self.model, d)
        self._settle()

    # ----------------------------------------------------------------- the table
    def select(self, name: str) -> None:
        """Hold `name` from now on: grasp, checks and ground truth follow this cup."""
        if name not in self.cups:
            raise ValueError(f"no cup {name!r}; cups: {sorted(self.cups)}")
        self._bind_object(name)
        self._object = self.cups[name]
        self.held = name

    def arrange(self, poses: dict[str, tuple[np.ndarray, np.ndarray]],
                supports: dict[str, np.ndarray], settle: float = 0.5) -> None:
        """Place cups (world position of O [m], quaternion (w, x, y, z)) and support blocks
        (world position [m]), at rest, then let them settle on the table for `settle` s."""
        d = self.data
        for name, (pos, quat) in poses.items():
            q = self._cup_qadr[name]
            d.qpos[q:q + 3] = pos
            d.qpos[q + 3:q + 7] = quat
            d.qvel[self._cup_dadr[name]:self._cup_dadr[name] + 6] = 0.0
        for name, pos in supports.items():
            d.mocap_pos[self._support[name]] = pos
        mujoco.mj_forward(self.model, d)
        self.wait(settle)

    def wait(self, seconds: float) -> None:
        """Let time pass with the commands and the arm held."""
        n = int(round(seconds / self.model.opt.timestep))
        if n > 0:
            mujoco.mj_step(self.model, self.data, nstep=n)

    def cup_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Ground truth: a cup's O frame in the world, position [m] and rotation (scoring)."""
        b = self._cup_body[name]
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    # ----------------------------------------------------------------- pick and release
    def grasp(self) -> ApplyReport:
        """Pick the selected cup where it stands under the open hand: close each tendon
        until it reaches its grasp tension (as `SimHand.grasp`, but without resetting the
        scene or a helper weld: the table and the support hold the cup while the fingers
        close), top the tensions up, lift the arm by `lift` and settle."""
        target = self._close_to_tension()
        self._settle()
        self._top_up_tensions(target)
        pos, _ = self.arm_pose()
        self.move_arm(pos + np.array([0.0, 0.0, self.lift]), speed=0.05)
        settled = self._settle()
        held, message = self._grasp_status()
        if not held:
            raise GraspError(f"{self.held}: no stable fingertip grasp after the pick: "
                             f"{message}")
        self._grasped = True
        return ApplyReport(commands=self.commands, settled=settled, grasp_held=True)

    lift = 0.03   # m: the arm lifts the picked cup off its support before identification

    def release(self, seconds: float = 0.4) -> None:
        """Open the hand: ramp every tendon command to zero over `seconds`, then wait as
        long again (the cup drops the last centimetres into the stack)."""
        start = self._u.copy()
        n = max(1, int(round(seconds / self.model.opt.timestep)))
        for k in range(1, n + 1):
            self._set_ctrl(start * (1 - k / n))
            mujoco.mj_step(self.model, self.data)
        self._u = np.zeros(len(self._slots))
        self.wait(seconds)
        self._grasped = False
