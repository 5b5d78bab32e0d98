"""Hand, finger and object specifications: the nominal knowledge shared by sim and estimator.

Frames and sign conventions (one place, used by `models/`, `sim/` and `vlr/` alike):

* Palm frame P: origin at the centre of the palm's top surface, +z up towards the grasped
  object, +y from the thumb towards the two opposing fingers, x = y cross z.
* Finger frame F_i: origin on finger i's proximal joint axis, z_F = z_P (up), y_F horizontal
  and pointing inwards (the direction the finger flexes to), x_F = y_F cross z_F. The mount
  gives the origin in P and the yaw of y_F about z_P (measured from +x_P).
* Both joints of a finger rotate about -x_F, so a POSITIVE angle flexes the finger inwards.
  A joint angle of 0 means the link points straight up (along z_F); the proximal link spans
  from F's origin to the distal joint, `proximal_length` along its own z.
* Distal frame D: at the distal joint, rotated by (theta_p + theta_d) about -x_F. The pad is a
  sphere of radius `pad_radius` whose centre is `pad_center` (x, y, z) in D; a contact point
  is pad_center + pad_radius * n for a unit normal n in D.
* Tendon (Eq. 7 with series compliance, docs/METHOD.md 8.2): the tendon length taken up by
  flexion from the open stops is s = r_p (theta_p - lo_p) + r_d (theta_d - lo_d). The
  command u >= 0 is the spool's pull from the calibrated open-hand zero. The line is taut
  when u > s, with tension k_t (u - s); it cannot push.
* Springs (Eq. 6): torque -k (theta - rest). The rest angle lies beyond the open stop
  (rest < lo), so the spring preloads the joint against its stop, as on the Model O.

Lengths are metres, angles radians, masses kilograms, stiffnesses N m/rad and N/m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import models

__all__ = [
    "SpecError",
    "FingerSpec",
    "FingerMount",
    "HandSpec",
    "ObjectSpec",
    "load_finger",
    "load_hand",
    "load_object",
    "available_hands",
    "available_objects",
    "available_fingers",
    "load_yaml_mapping",
]


class SpecError(ValueError):
    """A spec file or name is invalid; the message names the bad value and the file."""


@dataclass(frozen=True)
class FingerSpec:
    """One finger module (docs/METHOD.md 1): two spring-loaded hinges and one tendon.

    Attributes (units in brackets):
        name: finger type, e.g. "modelo", "nf1".
        proximal_length: proximal joint axis to distal joint axis [m].
        distal_length: distal joint axis to the fingertip end (for drawing) [m].
        pad_center: pad sphere centre in the distal frame D [m], (x, y, z).
        pad_radius: pad sphere radius [m].
        pulley_radii: (r_p, r_d), the tendon's moment arms [m] (Eq. 7).
        stiffness: (k_p, k_d) torsional spring rates [N m/rad] (Eq. 6).
        rest_angles: (rest_p, rest_d) spring rest angles [rad], beyond the open stops.
        limits: ((lo_p, hi_p), (lo_d, hi_d)) joint ranges [rad]; lo is the open stop.
        link_masses: (m_p, m_d) [kg].
        link_coms: proximal and distal centres of mass, each (x, y, z) in its link frame [m].
        link_width: finger width along x_F [m], for collision and drawing.
        visual_meshes / collision_meshes: optional STL paths (proximal, distal) for the sim;
            None means the builder's primitive shapes.
    """

    name: str
    proximal_length: float
    distal_length: float
    pad_center: tuple[float, float, float]
    pad_radius: float
    pulley_radii: tuple[float, float]
    stiffness: tuple[float, float]
    rest_angles: tuple[float, float]
    limits: tuple[tuple[float, float], tuple[float, float]]
    link_masses: tuple[float, float]
    link_coms: tuple[tuple[float, float, float], tuple[float, float, float]]
    link_width: float = 0.018
    visual_meshes: tuple[str | None, str | None] = (None, None)
    collision_meshes: tuple[str | None, str | None] = (None, None)

    def __post_init__(self) -> None:
        _require(self.proximal_length > 0, f"finger {self.name}: proximal_length "
                 f"{self.proximal_length} must be > 0")
        _require(self.pad_radius > 0, f"finger {self.name}: pad_radius {self.pad_radius} "
                 "must be > 0")
        for label, pair in (("pulley_radii", self.pulley_radii), ("stiffness", self.stiffness),
                            ("link_masses", self.link_masses)):
            _require(all(v > 0 for v in pair), f"finger {self.name}: {label} {pair} must be > 0")
        for j, (lo, hi) in enumerate(self.limits):
            _require(lo < hi, f"finger {self.name}: joint {j} limits ({lo}, {hi}) need lo < hi")
            _require(self.rest_angles[j] <= lo, f"finger {self.name}: rest angle "
                     f"{self.rest_angles[j]} must be at or beyond the open stop {lo}")

    @property
    def open_angles(self) -> np.ndarray:
        """Joint angles at the open stops (lo_p, lo_d) [rad]."""
        return np.array([self.limits[0][0], self.limits[1][0]])

    def tendon_takeup(self, theta: np.ndarray) -> np.ndarray:
        """Tendon length consumed by flexion from the open stops, s(theta) (Eq. 7) [m].

        `theta` has shape (..., 2); the result has shape (...).
        """
        r = np.asarray(self.pulley_radii)
        return (np.asarray(theta) - self.open_angles) @ r


@dataclass(frozen=True)
class FingerMount:
    """Where a finger sits on the palm: a slot name, its base position and yaw."""

    slot: str
    position: tuple[float, float, float]
    yaw: float
    finger: FingerSpec

    def rotation(self) -> np.ndarray:
        """Rotation matrix R_PF whose columns are x_F, y_F, z_F in the palm frame."""
        y = np.array([math.cos(self.yaw), math.sin(self.yaw), 0.0])
        z = np.array([0.0, 0.0, 1.0])
        x = np.cross(y, z)
        return np.column_stack([x, y, z])


@dataclass(frozen=True)
class HandSpec:
    """A hand: its fingers on palm slots and the tendon-drive compliance.

    `tendon_stiffness` is the series stiffness of servo plus tendon line [N/m]
    (docs/METHOD.md 8.2; models/README.md documents the default).
    """

    name: str
    mounts: tuple[FingerMount, ...]
    tendon_stiffness: float
    spread: float = 0.0
    palm_radius: float = 0.055
    palm_thickness: float = 0.02

    def __post_init__(self) -> None:
        _require(len(self.mounts) >= 1, f"hand {self.name}: needs at least one finger")
        _require(self.tendon_stiffness > 0, f"hand {self.name}: tendon_stiffness "
                 f"{self.tendon_stiffness} must be > 0")
        slots = [m.slot for m in self.mounts]
        _require(len(set(slots)) == len(slots), f"hand {self.name}: duplicate slots {slots}")

    @property
    def finger_names(self) -> tuple[str, ...]:
        return tuple(m.slot for m in self.mounts)

    @property
    def n_fingers(self) -> int:
        return len(self.mounts)

    def mount(self, slot: str) -> FingerMount:
        for m in self.mounts:
            if m.slot == slot:
                return m
        raise SpecError(f"hand {self.name} has no finger slot {slot!r}; "
                        f"slots are {list(self.finger_names)}")


@dataclass(frozen=True)
class ObjectSpec:
    """A graspable object with an AprilTag on its bottom face.

    The object frame O has its origin at the tag centre, the point of manipulation (POM),
    z pointing into the object (up, when held), so the tag faces -z_O towards the camera.

    Attributes:
        name: object name.
        shape: "sphere" | "box" | "cylinder" | "mesh".
        size: shape parameters [m] (sphere: (radius,); box: half-extents (x, y, z);
            cylinder: (radius, half-height)); for "mesh", the bounding half-extents.
        mass: [kg].
        com: centre of mass in O [m].
        tag_id: AprilTag 36h11 id.
        tag_size: side of the tag's black square [m] (what pose estimation needs).
        mesh: optional STL path for shape "mesh".
        grasp_height: height of the POM above the palm frame origin when placed for a grasp [m].
        friction: sliding friction coefficient of the object surface.
        ycb: YCB object id, if the object mimics one.
    """

    name: str
    shape: str
    size: tuple[float, ...]
    mass: float
    com: tuple[float, float, float]
    tag_id: int
    tag_size: float
    grasp_height: float
    mesh: str | None = None
    friction: float = 1.0
    ycb: int | None = None
    rgba: tuple[float, float, float, float] = (0.8, 0.2, 0.2, 1.0)
    extras: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _require(self.shape in ("sphere", "box", "cylinder", "mesh"),
                 f"object {self.name}: unknown shape {self.shape!r} "
                 "(sphere, box, cylinder or mesh)")
        _require(self.mass > 0, f"object {self.name}: mass {self.mass} must be > 0")
        _require(0 <= self.tag_id < 587, f"object {self.name}: tag_id {self.tag_id} is not a "
                 "tag36h11 id (0..586)")
        _require(self.tag_size > 0, f"object {self.name}: tag_size {self.tag_size} must be > 0")
        _require(all(s > 0 for s in self.size), f"object {self.name}: size {self.size} "
                 "must be > 0")


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise SpecError(message)


# --------------------------------------------------------------------------- YAML loading

def load_yaml_mapping(path: str | Path, what: str,
                      error: type[Exception] = SpecError) -> dict[str, Any]:
    """The mapping in YAML file `path`, or `error` naming `what` ("spec file", ...) and the
    path: missing, unreadable, not YAML, or not a mapping. Shared by every YAML loader."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{what} {path} {'is not a file' if path.exists() else 'does not exist'}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise error(f"{what} {path} is not valid YAML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{what} {path} cannot be read: {exc}") from None
    if not isinstance(data, dict):
        raise error(f"{what} {path} must hold a mapping, got {type(data).__name__}")
    return data


def _read_yaml(path: Path) -> dict[str, Any]:
    return load_yaml_mapping(path, "spec file")


def _get(data: dict[str, Any], key: str, path: Path, kind: type | tuple = (int, float),
         length: int | None = None) -> Any:
    if key not in data:
        raise SpecError(f"{path}: missing key {key!r}")
    value = data[key]
    if length is None:
        if not isinstance(value, kind) or isinstance(value, bool):
            noun = {str: "a string", int: "an integer"}.get(kind, "a number")
            raise SpecError(f"{path}: {key} = {value!r} must be {noun}")
        if isinstance(value, (int, float)) and not math.isfinite(value):
            raise SpecError(f"{path}: {key} = {value!r} must be finite")
        return value
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise SpecError(f"{path}: {key} = {value!r} must be a list of {length}")
    return value


def _opt_number(data: dict[str, Any], key: str, default: float, path: Path) -> float:
    """An optional finite number (`default` when absent)."""
    return float(_get(data, key, path)) if key in data else default


def _opt_mapping(data: dict[str, Any], key: str, path: Path) -> dict[str, Any]:
    """An optional mapping ({} when absent or empty)."""
    value = data.get(key) or {}
    if not isinstance(value, dict):
        raise SpecError(f"{path}: {key} = {value!r} must be a mapping")
    return value


def _vec(value: Any, n: int, where: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SpecError(f"{where} = {value!r} must be a list of {n} numbers")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SpecError(f"{where} = {value!r} must hold finite numbers")
        out.append(float(v))
    return tuple(out)


def _resolve_mesh(entry: Any, base: Path, where: str) -> str | None:
    if entry is None:
        return None
    if not isinstance(entry, str):
        raise SpecError(f"{where}: mesh {entry!r} must be a file path")
    p = Path(entry)
    if not p.is_absolute():
        p = (base / p).resolve()
    if not p.is_file():
        raise SpecError(f"{where}: mesh file {p} does not exist")
    return str(p)


def finger_from_dict(data: dict[str, Any], path: Path) -> FingerSpec:
    """Build a FingerSpec from a parsed YAML mapping (see models/README.md for the format)."""
    base = path.parent
    where = str(path)
    limits = _get(data, "limits", path, length=2)
    meshes = _opt_mapping(data, "meshes", path)
    try:
        return FingerSpec(
            name=str(data.get("name", path.stem)),
            proximal_length=float(_get(data, "proximal_length", path)),
            distal_length=float(_get(data, "distal_length", path)),
            pad_center=_vec(_get(data, "pad_center", path, length=3), 3, f"{where}: pad_center"),
            pad_radius=float(_get(data, "pad_radius", path)),
            pulley_radii=_vec(_get(data, "pulley_radii", path, length=2), 2,
                              f"{where}: pulley_radii"),
            stiffness=_vec(_get(data, "stiffness", path, length=2), 2, f"{where}: stiffness"),
            rest_angles=_vec(_get(data, "rest_angles", path, length=2), 2,
                             f"{where}: rest_angles"),
            limits=(_vec(limits[0], 2, f"{where}: limits[0]"),
                    _vec(limits[1], 2, f"{where}: limits[1]")),
            link_masses=_vec(_get(data, "link_masses", path, length=2), 2,
                             f"{where}: link_masses"),
            link_coms=(_vec(_get(data, "link_coms", path, length=2)[0], 3,
                            f"{where}: link_coms[0]"),
                       _vec(data["link_coms"][1], 3, f"{where}: link_coms[1]")),
            link_width=_opt_number(data, "link_width", 0.018, path),
            visual_meshes=(_resolve_mesh(meshes.get("proximal_visual"), base, where),
                           _resolve_mesh(meshes.get("distal_visual"), base, where)),
            collision_meshes=(_resolve_mesh(meshes.get("proximal_collision"), base, where),
                              _resolve_mesh(meshes.get("distal_collision"), base, where)),
        )
    except SpecError as exc:
        if str(path) in str(exc):
            raise
        raise SpecError(f"{path}: {exc}") from None


def _named_or_path(name_or_path: str | Path, folder: str, kind: str,
                   available: list[str]) -> Path:
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        if not p.is_file():
            raise SpecError(f"{kind} spec file {p} does not exist")
        return p
    candidate = models.ROOT / folder / f"{name_or_path}.yaml"
    if not candidate.is_file():
        raise SpecError(f"unknown {kind} {str(name_or_path)!r}; known: {', '.join(available)} "
                        f"(or pass a path to a .yaml spec file)")
    return candidate


def available_fingers() -> list[str]:
    return sorted(p.stem for p in (models.ROOT / "fingers").glob("*.yaml"))


def available_hands() -> list[str]:
    return sorted(p.stem for p in (models.ROOT / "hands").glob("*.yaml"))


def available_objects() -> list[str]:
    return sorted(p.stem for p in (models.ROOT / "objects").glob("*.yaml"))


def load_finger(name_or_path: str | Path) -> FingerSpec:
    """Load a finger by name (models/fingers/NAME.yaml) or from a YAML file path."""
    path = _named_or_path(name_or_path, "fingers", "finger", available_fingers())
    return finger_from_dict(_read_yaml(path), path)


def load_hand(name_or_path: str | Path) -> HandSpec:
    """Load a hand by name (models/hands/NAME.yaml) or from a YAML file path.

    Each slot names a finger by name or by a path relative to the hand file, or defines it
    inline (a mapping in the finger format).
    """
    path = _named_or_path(name_or_path, "hands", "hand", available_hands())
    data = _read_yaml(path)
    slots = data.get("slots")
    if not isinstance(slots, list) or not slots:
        raise SpecError(f"{path}: 'slots' must be a non-empty list of finger mounts")
    mounts = []
    for i, s in enumerate(slots):
        if not isinstance(s, dict):
            raise SpecError(f"{path}: slots[{i}] must be a mapping")
        for key in ("slot", "position", "yaw", "finger"):
            if key not in s:
                raise SpecError(f"{path}: slots[{i}] is missing {key!r}")
        finger_ref = s["finger"]
        if isinstance(finger_ref, dict):
            finger = finger_from_dict(finger_ref, path)
        else:
            ref = Path(str(finger_ref))
            if ref.suffix in (".yaml", ".yml") and not ref.is_absolute():
                ref = path.parent / ref
            finger = load_finger(ref if ref.suffix else str(finger_ref))
        yaw = s["yaw"]
        if isinstance(yaw, bool) or not isinstance(yaw, (int, float)) or not math.isfinite(yaw):
            raise SpecError(f"{path}: slots[{i}].yaw = {yaw!r} must be a finite number")
        mounts.append(FingerMount(slot=str(s["slot"]),
                                  position=_vec(s["position"], 3, f"{path}: slots[{i}].position"),
                                  yaw=float(yaw), finger=finger))
    spec = HandSpec(name=str(data.get("name", path.stem)), mounts=tuple(mounts),
                    tendon_stiffness=float(_get(data, "tendon_stiffness", path)),
                    spread=_opt_number(data, "spread", 0.0, path))
    return spec


def load_object(name_or_path: str | Path) -> ObjectSpec:
    """Load an object by name (models/objects/NAME.yaml) or from a YAML file path."""
    path = _named_or_path(name_or_path, "objects", "object", available_objects())
    data = _read_yaml(path)
    size = data.get("size")
    if not isinstance(size, (list, tuple)) or not size:
        raise SpecError(f"{path}: size = {size!r} must be a non-empty list of numbers")
    mesh = _resolve_mesh(data.get("mesh"), path.parent, str(path))
    try:
        return ObjectSpec(
            name=str(data.get("name", path.stem)),
            shape=str(_get(data, "shape", path, kind=str)),
            size=_vec(size, len(size), f"{path}: size"),
            mass=float(_get(data, "mass", path)),
            com=_vec(_get(data, "com", path, length=3), 3, f"{path}: com"),
            tag_id=int(_get(data, "tag_id", path, kind=int)),
            tag_size=float(_get(data, "tag_size", path)),
            grasp_height=float(_get(data, "grasp_height", path)),
            mesh=mesh,
            friction=_opt_number(data, "friction", 1.0, path),
            ycb=data.get("ycb"),
            rgba=_vec(data.get("rgba", [0.8, 0.2, 0.2, 1.0]), 4, f"{path}: rgba"),
            extras=dict(_opt_mapping(data, "extras", path)),
        )
    except SpecError as exc:
        raise SpecError(f"{path}: {exc}") from None


def with_finger(hand: HandSpec, slot: str, finger: FingerSpec) -> HandSpec:
    """A copy of `hand` with the finger in `slot` replaced."""
    hand.mount(slot)
    mounts = tuple(replace(m, finger=finger) if m.slot == slot else m for m in hand.mounts)
    return replace(hand, mounts=mounts)
