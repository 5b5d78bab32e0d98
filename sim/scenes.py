"""Task scenes beyond a hand holding one object: the marble maze (tasks/maze.py).

`MazeHand` is a `SimHand` whose held object (models/objects/maze_holder.yaml) carries a post
and a maze plate with walls, plus a marble: a free body parked off the plate (welded to the
world) until `place_marble` puts it on the plate, as the paper places the marble after
identification. The maze's walls come from the task as segments in the plate frame (origin
at the plate's top centre, axes those of the object frame O), so that the layout lives with
the task and the sim only builds it.

Ground truth here (marble position, plate pose) is for scoring and `info` only.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Callable, Iterator, Sequence

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from dm_control import mjcf  # noqa: E402

import sim.backend as _backend  # noqa: E402
from sim.backend import SimHand, SimOptions  # noqa: E402
from sim.model import TAG_CARD_THICKNESS, build_scene  # noqa: E402
from vlr.spec import HandSpec, ObjectSpec, load_object  # noqa: E402

__all__ = ["plate_mount", "build_maze_scene", "MazeHand"]

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


@contextlib.contextmanager
def _scene_builder(builder: Callable[..., mjcf.RootElement]) -> Iterator[None]:
    """SimHand composes its scene with `sim.backend.build_scene`; swap in a task's builder
    for the duration of one construction (SimHand takes no scene argument)."""
    original = _backend.build_scene
    _backend.build_scene = builder
    try:
        yield
    finally:
        _backend.build_scene = original


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

        with _scene_builder(builder):
            super().__init__(object=spec, hand=hand, seed=seed, options=options)
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
