"""Compose the MuJoCo model of the Model O, its fingers and an object with `dm_control.mjcf`.

A finger is a module built from a `FingerSpec` and attached to a palm slot (one builder, never
copy-pasted fingers); the object carries its AprilTag on a thin card under its bottom face.
Every tuned number has its source in models/README.md.

Naming grammar (dm_control.mjcf's scopes): `<slot>/proximal`, `<slot>/distal` (bodies and
joints), `<slot>/pad` (fingertip pad geom), `<slot>/tendon`, `<slot>_tendon_act`;
`object/object`, `object/tag`. The MJCF files of models/mjcf/ write them without `/`
(`thumb_proximal`; models/make_mjcf.py `clean_name`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf
from vlr.models.make_tags import TEXTURE_PER_BLACK, tag_path, write_tag
from vlr.sim.pads import ROLL_FRICTION, SLIDE_FRICTION, TORSION_FRICTION

from vlr.spec import FingerSpec, HandSpec, ObjectSpec, SpecError

# Contact model for stable fingertip grasps (docs/METHOD.md 8.2, models/README.md "Contacts").
TIMESTEP = 0.001            # s; solref is clamped to 2 steps, so 4 ms needs <= 2 ms
SOLREF = (0.004, 1.0)       # stiff contacts, critically damped
IMPRATIO = 10.0             # elliptic cones, frictional stiffness ~ normal
NOSLIP_ITERATIONS = 10

TENDON_DAMPING = 40.0       # N s/m on the tendon actuator: servo velocity loop, see README
TENDON_FORCE_MAX = 60.0     # N; XM430 stall torque 4.1 N m on a 10 mm spool is ~400 N, the
                            # line's working load is far lower; 60 N bounds the model
# The servo's accepted tendon pull [m] from the open-hand zero: the sim's commands
# (sim/backend.py COMMAND_RANGE, -2 to 40 mm) with a margin, so no command is ever clamped.
TENDON_PULL_RANGE = (-0.005, 0.045)
JOINT_DAMPING = 0.002       # N m s/rad: bushing friction
JOINT_ARMATURE = 1e-5       # kg m^2: keeps the light links well conditioned at 1 ms

PALM_COLOR = (0.25, 0.25, 0.28, 1.0)
FINGER_COLOR = (0.55, 0.55, 0.60, 1.0)
PAD_COLOR = (0.15, 0.15, 0.15, 1.0)
TAG_CARD_THICKNESS = 0.002  # m

# The palm camera (models/README.md "Camera"): a 640x480 USB board camera.
CAMERA_FOVY_DEG = 60.0
CAMERA_HEIGHT = -0.004      # m below the palm surface, behind a window


@dataclass(frozen=True)
class BuiltModel:
    """A compiled model and the MJCF text it came from."""

    model: mujoco.MjModel
    xml: str
    assets: dict[str, bytes]


def _pad_geom_kwargs() -> dict:
    return dict(condim=4, friction=[SLIDE_FRICTION, TORSION_FRICTION, ROLL_FRICTION],
                solref=list(SOLREF), priority=1)


def build_finger(spec: FingerSpec, slot: str) -> mjcf.RootElement:
    """One finger module (proximal and distal links, springs, limits, tendon, actuator).

    Joints rotate about -x (positive = flexion towards +y, the palm centre), matching
    vlr/spec.py. Springs: stiffness k with springref at the rest angle beyond the open stop,
    so the joint is preloaded against its stop (Eq. 6). The fixed tendon's length is
    -(r_p q_p + r_d q_d) (Eq. 7); the actuator is a position servo on it whose gain is the
    series compliance k_t and which can only pull (force range [-F, 0]).
    """
    root = mjcf.RootElement(model=slot)
    (lo_p, hi_p), (lo_d, hi_d) = spec.limits
    w = spec.link_width
    half_t = 0.006  # link half thickness along y
    prox = root.worldbody.add("body", name="proximal")
    prox.add("joint", name="proximal", type="hinge", axis=[-1, 0, 0], range=[lo_p, hi_p],
             limited=True, stiffness=spec.stiffness[0], springref=spec.rest_angles[0],
             damping=JOINT_DAMPING, armature=JOINT_ARMATURE, solreflimit=list(SOLREF))
    prox.add("inertial", pos=list(spec.link_coms[0]), mass=spec.link_masses[0],
             diaginertia=_box_inertia(spec.link_masses[0], w, 2 * half_t,
                                      spec.proximal_length))
    lp = spec.proximal_length
    _link_geoms(prox, spec, 0, "proximal_link", [0, 0, lp / 2], [w / 2, half_t, lp / 2 - 0.004])

    dist = prox.add("body", name="distal", pos=[0, 0, lp])
    dist.add("joint", name="distal", type="hinge", axis=[-1, 0, 0], range=[lo_d, hi_d],
             limited=True, stiffness=spec.stiffness[1], springref=spec.rest_angles[1],
             damping=JOINT_DAMPING, armature=JOINT_ARMATURE, solreflimit=list(SOLREF))
    dist.add("inertial", pos=list(spec.link_coms[1]), mass=spec.link_masses[1],
             diaginertia=_box_inertia(spec.link_masses[1], w, 2 * half_t, spec.distal_length))
    pc = np.asarray(spec.pad_center)
    # The distal link body stops short of the pad sphere so only the smooth pad touches.
    link_top = max(pc[2] - spec.pad_radius * 0.6, 0.008)
    _link_geoms(dist, spec, 1, "distal_link", [0, -0.002, link_top / 2],
                [w / 2, half_t, link_top / 2])
    dist.add("geom", name="pad", type="sphere", size=[spec.pad_radius], pos=list(pc),
             rgba=PAD_COLOR, group=3, mass=0, **_pad_geom_kwargs())
    if not spec.visual_meshes[1]:  # a distal mesh draws its own pad
        dist.add("geom", name="pad_visual", type="sphere", size=[spec.pad_radius],
                 pos=list(pc), rgba=PAD_COLOR, contype=0, conaffinity=0, group=2, mass=0)
    dist.add("site", name="pad_center", pos=list(pc), size=[0.001])
    prox.add("site", name="distal_joint", pos=[0, 0, lp], size=[0.001])

    tendon = root.tendon.add("fixed", name="tendon")
    tendon.add("joint", joint="proximal", coef=-spec.pulley_radii[0])
    tendon.add("joint", joint="distal", coef=-spec.pulley_radii[1])
    return root


def _link_geoms(body, spec: FingerSpec, idx: int, name: str, pos, half) -> None:
    visual = spec.visual_meshes[idx]
    collision = spec.collision_meshes[idx]
    root = body.root
    if visual:
        mesh = root.asset.add("mesh", name=f"{name}_vis", file=_mesh_file(visual))
        body.add("geom", name=f"{name}_visual", type="mesh", mesh=mesh, rgba=FINGER_COLOR,
                 contype=0, conaffinity=0, group=2, mass=0)
    else:
        body.add("geom", name=f"{name}_visual", type="box", pos=pos, size=half,
                 rgba=FINGER_COLOR, contype=0, conaffinity=0, group=2, mass=0)
    if collision:
        mesh = root.asset.add("mesh", name=f"{name}_col", file=_mesh_file(collision))
        body.add("geom", name=name, type="mesh", mesh=mesh, group=3, mass=0,
                 rgba=FINGER_COLOR, **_pad_geom_kwargs())
    else:
        body.add("geom", name=name, type="box", pos=pos, size=half, group=3, mass=0,
                 rgba=FINGER_COLOR, **_pad_geom_kwargs())


def _mesh_file(path: str):
    p = Path(path)
    if not p.is_file():
        raise SpecError(f"mesh file {p} does not exist")
    return mjcf.Asset(contents=p.read_bytes(), extension=p.suffix)


def _box_inertia(m: float, x: float, y: float, z: float) -> list[float]:
    return [m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12]


def open_tendon_length(spec: FingerSpec) -> float:
    """The fixed tendon's length [m] with both joints on their open stops: the zero of the
    spool's pull."""
    return -float(np.dot(spec.pulley_radii, spec.open_angles))


def tendon_ctrlrange(spec: FingerSpec) -> tuple[float, float]:
    """The tendon actuator's control range [m of tendon length]: a control is a length target,
    the open-hand length less the spool's pull, so the range is that length less
    `TENDON_PULL_RANGE`."""
    l_open = open_tendon_length(spec)
    return l_open - TENDON_PULL_RANGE[1], l_open - TENDON_PULL_RANGE[0]


def build_palm(hand: HandSpec, width: int = 640, height: int = 480,
               fovy_deg: float = CAMERA_FOVY_DEG) -> mjcf.RootElement:
    """The palm body with a finger slot site per mount, the palm camera and its light."""
    root = mjcf.RootElement(model=hand.name)
    root.compiler.angle = "radian"
    root.option.timestep = TIMESTEP
    root.option.integrator = "implicitfast"
    root.option.cone = "elliptic"
    root.option.impratio = IMPRATIO
    root.option.noslip_iterations = NOSLIP_ITERATIONS
    root.visual.__getattr__("global").offwidth = max(width, 640)
    root.visual.__getattr__("global").offheight = max(height, 480)
    root.visual.quality.shadowsize = 0
    root.visual.headlight.ambient = [0.3, 0.3, 0.3]
    root.visual.headlight.diffuse = [0.4, 0.4, 0.4]
    root.visual.headlight.specular = [0.0, 0.0, 0.0]

    palm = root.worldbody.add("body", name="palm", pos=[0, 0, 0])
    r, t = hand.palm_radius, hand.palm_thickness
    palm.add("geom", name="palm", type="cylinder", size=[r, t / 2], pos=[0, 0, -t / 2],
             rgba=PALM_COLOR, group=2, condim=3, solref=list(SOLREF))
    # The camera looks up (+z_palm). A MuJoCo camera looks along its own -z, so rotate by pi
    # about x; vlr.camera converts this frame to OpenCV's, in one place.
    palm.add("camera", name="palm_camera", pos=[0, 0, CAMERA_HEIGHT], quat=[0, 1, 0, 0],
             fovy=fovy_deg)
    # A ring light in the palm around the camera; no shadows, for speed and a readable tag.
    palm.add("light", name="palm_light", pos=[0, 0, -0.02], dir=[0, 0, 1], directional=False,
             castshadow=False, diffuse=[0.7, 0.7, 0.7], specular=[0, 0, 0],
             attenuation=[1, 0, 0], cutoff=80, exponent=1)
    for m in hand.mounts:
        yaw = m.yaw
        if m.slot == "left":
            yaw -= hand.spread
        elif m.slot == "right":
            yaw += hand.spread
        # Finger frame F: y_F (inward) at `yaw` from +x_P, so F is the palm rotated by
        # (yaw - pi/2) about z.
        a = yaw - math.pi / 2
        palm.add("site", name=f"{m.slot}_slot", pos=list(m.position),
                 quat=[math.cos(a / 2), 0, 0, math.sin(a / 2)], size=[0.002])
    return root


def build_object(obj: ObjectSpec) -> mjcf.RootElement:
    """The object body (frame O: origin at the tag centre, z into the object) and its tag."""
    root = mjcf.RootElement(model="object")
    body = root.worldbody.add("body", name="object")
    fr = [obj.friction, TORSION_FRICTION, ROLL_FRICTION]
    col = dict(condim=4, friction=fr, solref=list(SOLREF), rgba=list(obj.rgba), group=2)
    c = TAG_CARD_THICKNESS
    ext = obj.extras
    if obj.shape == "sphere":
        body.add("geom", name="body", type="sphere", size=[obj.size[0]],
                 pos=[0, 0, c + obj.size[0]], **col)
    elif obj.shape == "box":
        hx, hy, hz = obj.size
        body.add("geom", name="body", type="box", size=[hx, hy, hz], pos=[0, 0, c + hz], **col)
    elif obj.shape == "cylinder" and ext.get("horizontal"):
        rad, half = obj.size
        body.add("geom", name="body", type="cylinder", size=[rad, half],
                 pos=[0, 0, c + rad], quat=[math.sqrt(0.5), 0, math.sqrt(0.5), 0], **col)
        if "shaft_length" in ext:  # the screwdriver's shaft beyond the handle, along +x_O
            sl, sr = ext["shaft_length"], ext["shaft_radius"]
            body.add("geom", name="shaft", type="capsule", size=[sr, sl / 2],
                     pos=[half + sl / 2, 0, c + rad],
                     quat=[math.sqrt(0.5), 0, math.sqrt(0.5), 0], **col)
    elif obj.shape == "cylinder" and ext.get("upright"):
        _upright_cup(body, obj, col)
    elif obj.shape == "cylinder":
        rad, half = obj.size
        body.add("geom", name="body", type="cylinder", size=[rad, half],
                 pos=[0, 0, c + half], **col)
        if "stem_length" in ext:  # the wine glass, held upside down: stem and foot above
            sl = ext["stem_length"]
            body.add("geom", name="stem", type="cylinder", size=[ext["stem_radius"], sl / 2],
                     pos=[0, 0, c + 2 * half + sl / 2], **col)
            body.add("geom", name="foot", type="cylinder",
                     size=[ext["foot_radius"], ext["foot_thickness"] / 2],
                     pos=[0, 0, c + 2 * half + sl], **col)
    else:  # mesh
        if not obj.mesh:
            raise SpecError(f"object {obj.name}: shape 'mesh' needs a mesh file")
        mesh = root.asset.add("mesh", name="body", file=_mesh_file(obj.mesh))
        body.add("geom", name="body", type="mesh", mesh=mesh, **col)
    # Geom masses from the spec: body geoms share the mass; the centre of mass is explicit.
    body.add("inertial", pos=list(obj.com), mass=obj.mass,
             diaginertia=_object_inertia(obj))
    for g in body.find_all("geom"):
        g.mass = 0 if g.mass is None else g.mass
    _add_tag(root, body, obj)
    return root


def _object_inertia(obj: ObjectSpec) -> list[float]:
    m = obj.mass
    if obj.shape == "sphere":
        i = 0.4 * m * obj.size[0] ** 2
        return [i, i, i]
    s = np.asarray(obj.size[:3] if len(obj.size) >= 3 else
                   (obj.size[0], obj.size[0], obj.size[1]))
    return _box_inertia(m, *(2 * s))


# How far an upright cup's wall boxes stop above its outer bottom face [m] (`_upright_cup`).
WALL_CLEARANCE = 2e-4


def cup_dimensions(obj: ObjectSpec) -> dict[str, float]:
    """An upright cup's dimensions [m] (`_upright_cup`): rim and bottom outer radii, outer
    height, wall and bottom thickness, taper [rad], and heights along -z_O from O (the tag
    face, on the inside bottom): `floor` (the outer bottom face, at +`floor_depth` along
    z_O) and `rim` (the rim, at -`rim_height` along z_O)."""
    e = obj.extras
    rim_r, half = obj.size
    taper = math.radians(float(e.get("taper_deg", 6.0)))
    height = 2 * half
    bottom = float(e.get("bottom", 0.0025))
    wall = float(e.get("wall", 0.002))
    floor_depth = TAG_CARD_THICKNESS + bottom
    bottom_r = rim_r - height * math.tan(taper)
    if not (0 <= taper < math.radians(45) and wall > 0 and bottom > 0
            and bottom_r > 2 * wall and height > 2 * floor_depth):
        raise SpecError(f"object {obj.name}: an upright cup needs 0 <= taper_deg < 45, wall and "
                        f"bottom > 0, a bottom radius over twice the wall (here "
                        f"{bottom_r * 1e3:.1f} mm) and a height over twice the floor "
                        f"(taper_deg {e.get('taper_deg', 6.0)!r}, wall {wall!r}, "
                        f"bottom {bottom!r}, size {list(obj.size)})")
    return {"rim_radius": rim_r, "bottom_radius": bottom_r,
            "height": height, "wall": wall, "bottom": bottom,
            "taper": taper, "floor_depth": floor_depth, "rim_height": height - floor_depth}


def _upright_cup(body, obj: ObjectSpec, col: dict, segments: int = 24) -> None:
    """An open cup standing on its bottom, the tag on the INSIDE bottom seen through the
    opening: a bottom disc and a ring of wall boxes (MuJoCo collides convex hulls) that rise
    towards -z_O (the camera) and flare out by `extras.taper_deg`, so that cups nest and a
    cup dropped into a larger one slides to its axis. `size`: (rim outer radius, half the
    outer height)."""
    d = cup_dimensions(obj)
    rb, rt, h, w, t = (d["bottom_radius"], d["rim_radius"], d["height"], d["wall"],
                       d["taper"])
    z0 = d["floor_depth"]                        # the outer bottom face, along +z_O
    body.add("geom", name="bottom", type="cylinder", size=[rb, d["bottom"] / 2],
             pos=[0, 0, z0 - d["bottom"] / 2], **col)
    # Each wall segment: a box leaning out by the taper, its outer face on the cone. Its
    # width is the rim's chord (a little over): the ring is closed at the rim, and below it
    # the boxes overlap outward only (an extended edge of a convex polygon lies outside it).
    seg_half = rt * math.tan(math.pi / segments) * 1.02
    # A box leaning out by t reaches (w/2) sin t below the outer bottom face: its bottom end
    # is cut back to WALL_CLEARANCE above it, so that a level cup touches a table or a
    # larger cup's floor with its bottom disc alone, not with 48 wall corners as well (they
    # were three quarters of a cup scene's step).
    cut = (0.5 * w * math.sin(t) + WALL_CLEARANCE) / math.cos(t)
    length = h / math.cos(t) - cut
    r_mid = 0.5 * (rb + rt) - 0.5 * w / math.cos(t) + 0.5 * cut * math.sin(t)
    q_tilt = (math.cos(-t / 2), 0.0, math.sin(-t / 2), 0.0)   # about y: the top leans out
    for k in range(segments):
        a = 2 * math.pi * k / segments
        q = np.zeros(4)
        mujoco.mju_mulQuat(q, np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]),
                           np.array(q_tilt))
        body.add("geom", name=f"wall{k}", type="box", size=[w / 2, seg_half, length / 2],
                 pos=[r_mid * math.cos(a), r_mid * math.sin(a),
                      z0 - h / 2 - 0.5 * cut * math.cos(t)],
                 quat=q.tolist(), **col)


def _add_tag(root: mjcf.RootElement, body, obj: ObjectSpec) -> None:
    """The AprilTag card: its +z face looks at the camera.

    A 2D texture on a box's -z face shows mirrored, so the thin tag geom is rotated by pi
    about x: its +z face then looks down (-z_O) at the camera, unmirrored. The texture is
    the tag with its white border; the black square is `tag_size` (models/make_tags.py).
    """
    png = tag_path(obj.tag_id)
    if not png.is_file():
        write_tag(obj.tag_id)
    tex = root.asset.add("texture", name="tag", type="2d",
                         file=mjcf.Asset(contents=png.read_bytes(), extension=".png"))
    mat = root.asset.add("material", name="tag", texture=tex, specular=0, shininess=0,
                         reflectance=0, rgba=[1, 1, 1, 1])
    side = obj.tag_size * TEXTURE_PER_BLACK
    c = TAG_CARD_THICKNESS
    body.add("geom", name="tag", type="box", size=[side / 2, side / 2, c / 2],
             pos=[0, 0, c / 2], quat=[0, 1, 0, 0], material=mat, condim=3,
             solref=list(SOLREF), group=2, mass=0)
    body.add("site", name="pom", pos=[0, 0, 0], size=[0.001])


def build_hand(hand: HandSpec, *, width: int = 640, height: int = 480,
               fovy_deg: float = CAMERA_FOVY_DEG) -> mjcf.RootElement:
    """Palm + fingers on their slots + tendon actuators (no object)."""
    root = build_palm(hand, width, height, fovy_deg)
    root.worldbody.add("light", name="top_light", pos=[0, 0, 0.6], dir=[0, 0, -1],
                       directional=True, castshadow=False, diffuse=[0.5, 0.5, 0.5])
    root.worldbody.add("camera", name="scene_camera", pos=[0.22, -0.22, 0.2],
                       xyaxes=[0.707, 0.707, 0, -0.35, 0.35, 0.87], fovy=45)
    for m in hand.mounts:
        finger = build_finger(m.finger, m.slot)
        site = root.find("site", f"{m.slot}_slot")
        site.attach(finger)
        root.actuator.add("position", name=f"{m.slot}_tendon_act", tendon=f"{m.slot}/tendon",
                          kp=hand.tendon_stiffness, kv=TENDON_DAMPING,
                          forcerange=[-TENDON_FORCE_MAX, 0], forcelimited=True,
                          ctrlrange=list(tendon_ctrlrange(m.finger)), ctrllimited=True)
    return root


def build_scene(hand: HandSpec, obj: ObjectSpec, *, width: int = 640, height: int = 480,
                fovy_deg: float = CAMERA_FOVY_DEG) -> mjcf.RootElement:
    """Palm + fingers on their slots + the object with a helper weld for grasping."""
    root = build_hand(hand, width=width, height=height, fovy_deg=fovy_deg)
    objroot = build_object(obj)
    frame = root.worldbody.attach(objroot)
    frame.pos = [0, 0, obj.grasp_height]
    frame.add("freejoint", name="object_free")  # a free joint must sit on the top-level frame
    # The helper constraint that holds the object while the hand closes (reset only).
    root.equality.add("weld", name="object_hold", body1="object/object", body2="palm",
                      solref=[0.01, 1])
    return root


def compile_scene(root: mjcf.RootElement) -> BuiltModel:
    """Compile with mujoco.MjModel (dm_control.mjcf only composes, METHOD: known facts)."""
    xml = root.to_xml_string()
    assets = root.get_assets()
    try:
        model = mujoco.MjModel.from_xml_string(xml, assets)
    except ValueError as exc:
        raise SpecError(f"the model does not compile: {exc}") from None
    return BuiltModel(model=model, xml=xml, assets=assets)


@lru_cache(maxsize=16)
def _cached(hand_key: str, obj_key: str, width: int, height: int, fovy: float) -> BuiltModel:
    from vlr.spec import load_hand, load_object

    return compile_scene(build_scene(load_hand(hand_key), load_object(obj_key),
                                     width=width, height=height, fovy_deg=fovy))


def load_scene(hand: str, obj: str, *, width: int = 640, height: int = 480,
               fovy_deg: float = CAMERA_FOVY_DEG) -> BuiltModel:
    """Build (cached) the scene of a named hand and object."""
    return _cached(str(hand), str(obj), width, height, float(fovy_deg))
