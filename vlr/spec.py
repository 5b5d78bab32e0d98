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

import difflib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from vlr import models

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
    "safe_load_yaml",
    "yaml_error_line",
    "DuplicateKeyError",
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
        _require(self.palm_radius > 0 and self.palm_thickness > 0, f"hand {self.name}: "
                 f"palm_radius {self.palm_radius} and palm_thickness {self.palm_thickness} "
                 "must be > 0")
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

class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A YAML mapping gives one key twice: PyYAML keeps the last value without a word, and
    a user who wrote `particles:` twice meant one of them."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """`yaml.SafeLoader` that refuses a mapping with a duplicated key (DuplicateKeyError,
    naming the key and both lines). Merge keys (`<<: *base`) may still be overridden."""

    def construct_mapping(self, node: yaml.Node, deep: bool = False) -> dict:
        if isinstance(node, yaml.MappingNode):
            first_line: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    seen = first_line.get(key)
                except TypeError:  # an unhashable key; SafeLoader refuses it itself
                    continue
                line = key_node.start_mark.line + 1
                if seen is not None:
                    raise DuplicateKeyError(
                        None, None, f"duplicate key {key!r} on line {line} (first on line "
                        f"{seen})", key_node.start_mark)
                first_line[key] = line
        return super().construct_mapping(node, deep=deep)


def safe_load_yaml(text: str) -> Any:
    """`yaml.safe_load` of a user's YAML, refusing a duplicated key (DuplicateKeyError):
    every settings file, sweep file, spec and hardware config is read through it."""
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader)


def yaml_error_line(exc: yaml.YAMLError) -> str:
    """`exc` on one line: PyYAML's own text spans several (the marks, a snippet)."""
    if isinstance(exc, DuplicateKeyError):
        return str(exc.problem)
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        what = " ".join(str(t) for t in (exc.context, exc.problem) if t)
        if mark is not None:
            what += f" (line {mark.line + 1}, column {mark.column + 1})"
        return what
    return " ".join(str(exc).split())


def load_yaml_mapping(path: str | Path, what: str,
                      error: type[Exception] = SpecError) -> dict[str, Any]:
    """The mapping in YAML file `path`, or `error` naming `what` ("spec file", ...) and the
    path: missing, a folder, unreadable, not UTF-8, not YAML, a key given twice, or not a
    mapping. Shared by every YAML loader."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{what} {path} {'is not a file' if path.exists() else 'does not exist'}")
    try:
        data = safe_load_yaml(path.read_text(encoding="utf-8"))
    except DuplicateKeyError as exc:
        raise error(f"{what} {path}: {yaml_error_line(exc)}") from None
    except yaml.YAMLError as exc:
        raise error(f"{what} {path} is not valid YAML: {yaml_error_line(exc)}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path} is not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise error(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    if not isinstance(data, dict):
        raise error(f"{what} {path} must hold a mapping, got {type(data).__name__}")
    return data


def _read_yaml(path: Path) -> dict[str, Any]:
    return load_yaml_mapping(path, "spec file")


# The keys each mapping of a spec file accepts (models/README.md describes them).
_FINGER_KEYS = ("name", "proximal_length", "distal_length", "pad_center", "pad_radius",
                "pulley_radii", "stiffness", "rest_angles", "limits", "link_masses",
                "link_coms", "link_width", "meshes")
_MESH_KEYS = ("proximal_visual", "distal_visual", "proximal_collision", "distal_collision")
_HAND_KEYS = ("name", "tendon_stiffness", "spread", "palm_radius", "palm_thickness", "slots")
_SLOT_KEYS = ("slot", "position", "yaw", "finger")
_OBJECT_KEYS = ("name", "ycb", "shape", "size", "mass", "com", "tag_id", "tag_size",
                "grasp_height", "friction", "rgba", "mesh", "extras")
# An object's `extras` are read by the scene builders (sim/model.py, sim/scenes.py), most
# with a default, so they are declared here too: a misspelt one would silently build the
# default shape. A new builder that reads a new extra adds it here.
_EXTRA_FLAGS = ("upright", "horizontal")
_EXTRA_NUMBERS = ("taper_deg", "wall", "bottom",                        # nesting cups
                  "shaft_radius", "shaft_length",                       # screwdriver
                  "stem_radius", "stem_length", "foot_radius", "foot_thickness",  # glass
                  "post_radius", "post_height", "plate_half", "plate_thickness",  # maze
                  "wall_height", "wall_thickness", "plate_tilt_deg", "marble_radius",
                  "marble_mass", "handle_mass", "post_mass", "plate_mass")
# Shape -> (number of `size` entries, what they are), as sim/model.py builds each shape.
_SIZES = {"sphere": (1, "radius"), "cylinder": (2, "radius, half-height"),
          "box": (3, "half-extents x, y, z"), "mesh": (3, "bounding half-extents x, y, z")}
_MISSING: Any = object()


def _is_number(value: Any) -> bool:
    # YAML's true/false are ints to Python; in a spec they are never meant as numbers.
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class _Section:
    """One mapping of a spec file, with the keys it accepts declared up front.

    Every mapping of a finger, hand or object file (and their meshes, slots, extras) is read
    through this class, so that each refuses an unknown key or a value of the wrong type the
    same way: with one line naming the file, the key (dotted for nested keys, e.g.
    `slots[0].finger.pad_center`) and what is accepted there.
    """

    def __init__(self, data: Any, path: Path, where: str, accepted: Sequence[str]) -> None:
        self.path, self.where, self.accepted = path, where, tuple(accepted)
        if not isinstance(data, dict):
            self.fail(where or "the file", data, "must be a mapping")
        self.data: dict[Any, Any] = data
        # Keys before values: a misspelt required key is then named as misspelt, with the
        # key it resembles, rather than the correct one reported missing.
        for key in data:
            if key not in self.accepted:
                self._unknown(str(key))

    def key(self, name: str) -> str:
        """The dotted key of `name` in this section."""
        return f"{self.where}.{name}" if self.where else name

    def fail(self, key: str, value: Any, why: str) -> NoReturn:
        raise SpecError(f"{self.path}: {key} = {value!r} {why}")

    def _unknown(self, name: str) -> NoReturn:
        close = difflib.get_close_matches(name, self.accepted, n=1)
        hint = f" (did you mean {self.key(close[0])!r}?)" if close else ""
        scope = f" in {self.where}" if self.where else ""
        raise SpecError(f"{self.path}: unknown key {self.key(name)!r}{hint}; "
                        f"accepted{scope}: {', '.join(sorted(self.accepted))}")

    def value(self, name: str, default: Any = _MISSING) -> Any:
        """The raw value of `name`, `default` when absent (required when no default)."""
        if name not in self.data:
            if default is _MISSING:
                raise SpecError(f"{self.path}: missing key {self.key(name)!r}")
            return default
        return self.data[name]

    def number(self, name: str, default: Any = _MISSING) -> float:
        """A finite number."""
        value = self.value(name, default)
        if not _is_number(value):
            self.fail(self.key(name), value, "must be a number")
        if not math.isfinite(value):
            self.fail(self.key(name), value, "must be finite")
        return float(value)

    def integer(self, name: str, default: Any = _MISSING, allow_none: bool = False) -> int | None:
        """An integer (or None, if `allow_none` and the key is absent or null)."""
        value = self.value(name, default)
        if value is None and allow_none:
            return None
        if not isinstance(value, int) or isinstance(value, bool):
            self.fail(self.key(name), value, "must be an integer")
        return value

    def string(self, name: str, default: Any = _MISSING, choices: Sequence[str] = ()) -> str:
        """A non-empty string, one of `choices` when given."""
        value = self.value(name, default)
        if not isinstance(value, str) or not value:
            self.fail(self.key(name), value, "must be a non-empty string")
        if choices and value not in choices:
            self.fail(self.key(name), value, f"must be one of {', '.join(choices)}")
        return value

    def flag(self, name: str, default: Any = _MISSING) -> bool:
        """true or false."""
        value = self.value(name, default)
        if not isinstance(value, bool):
            self.fail(self.key(name), value, "must be true or false")
        return value

    def numbers(self, name: str, n: int, default: Any = _MISSING,
                what: str = "") -> tuple[float, ...]:
        """A list of `n` finite numbers; `what` says what they are, for the message."""
        return _numbers(self.value(name, default), n, self.path, self.key(name), what)

    def pairs(self, name: str, count: int, n: int) -> tuple[tuple[float, ...], ...]:
        """A list of `count` lists of `n` finite numbers (joint limits, link centres)."""
        value = self.value(name)
        if not isinstance(value, (list, tuple)) or len(value) != count:
            self.fail(self.key(name), value, f"must be a list of {count} lists of {n} numbers")
        return tuple(_numbers(v, n, self.path, f"{self.key(name)}[{j}]")
                     for j, v in enumerate(value))

    def section(self, name: str, accepted: Sequence[str]) -> _Section:
        """An optional nested mapping (empty when absent or null)."""
        value = self.value(name, None)
        return _Section({} if value is None else value, self.path, self.key(name), accepted)

    def mesh(self, name: str) -> str | None:
        """An optional mesh file path, relative to the spec file; absolute when resolved."""
        entry = self.value(name, None)
        if entry is None:
            return None
        if not isinstance(entry, str) or not entry:
            self.fail(self.key(name), entry, "must be a file path")
        p = Path(entry)
        if not p.is_absolute():
            p = (self.path.parent / p).resolve()
        if not p.is_file():
            raise SpecError(f"{self.path}: {self.key(name)} = {entry!r}: mesh file {p} does "
                            "not exist")
        return str(p)


def _numbers(value: Any, n: int, path: Path, key: str, what: str = "") -> tuple[float, ...]:
    """`value` as `n` finite floats, or a SpecError naming `path` and `key`."""
    if (not isinstance(value, (list, tuple)) or len(value) != n
            or not all(_is_number(v) for v in value)):
        noun = "number" if n == 1 else "numbers"
        raise SpecError(f"{path}: {key} = {value!r} must be a list of {n} {noun}"
                        + (f" ({what})" if what else ""))
    if not all(math.isfinite(v) for v in value):
        raise SpecError(f"{path}: {key} = {value!r} must hold finite numbers")
    return tuple(float(v) for v in value)


def finger_from_dict(data: dict[str, Any], path: Path, where: str = "") -> FingerSpec:
    """Build a FingerSpec from a parsed YAML mapping (see models/README.md for the format).

    `where` is the mapping's dotted key in `path` ("" for a finger file, e.g. `slots[0].finger`
    for a finger defined inline in a hand file), for the messages.
    """
    s = _Section(data, path, where, _FINGER_KEYS)
    meshes = s.section("meshes", _MESH_KEYS)
    limits = s.pairs("limits", 2, 2)
    link_coms = s.pairs("link_coms", 2, 3)
    try:
        return FingerSpec(
            name=s.string("name", path.stem),
            proximal_length=s.number("proximal_length"),
            distal_length=s.number("distal_length"),
            pad_center=s.numbers("pad_center", 3, what="x, y, z"),
            pad_radius=s.number("pad_radius"),
            pulley_radii=s.numbers("pulley_radii", 2, what="r_p, r_d"),
            stiffness=s.numbers("stiffness", 2, what="k_p, k_d"),
            rest_angles=s.numbers("rest_angles", 2, what="proximal, distal"),
            limits=(limits[0], limits[1]),
            link_masses=s.numbers("link_masses", 2, what="proximal, distal"),
            link_coms=(link_coms[0], link_coms[1]),
            link_width=s.number("link_width", 0.018),
            visual_meshes=(meshes.mesh("proximal_visual"), meshes.mesh("distal_visual")),
            collision_meshes=(meshes.mesh("proximal_collision"),
                              meshes.mesh("distal_collision")),
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


def _slot_finger(s: _Section, hand_path: Path) -> FingerSpec:
    """The finger of one hand slot: a name, a path relative to the hand file, or inline."""
    ref = s.value("finger")
    if isinstance(ref, dict):
        return finger_from_dict(ref, hand_path, s.key("finger"))
    if not isinstance(ref, str) or not ref:
        s.fail(s.key("finger"), ref, "must be a finger name, a path to a .yaml finger file "
               "or a finger mapping")
    p = Path(ref)
    if p.suffix in (".yaml", ".yml") and not p.is_absolute():
        p = hand_path.parent / p
    try:
        return load_finger(p if p.suffix else ref)
    except SpecError as exc:
        # Name the hand file's key too: the finger file may be shared by several hands.
        raise SpecError(f"{hand_path}: {s.key('finger')} = {ref!r}: {exc}") from None


def load_hand(name_or_path: str | Path) -> HandSpec:
    """Load a hand by name (models/hands/NAME.yaml) or from a YAML file path.

    Each slot names a finger by name or by a path relative to the hand file, or defines it
    inline (a mapping in the finger format).
    """
    path = _named_or_path(name_or_path, "hands", "hand", available_hands())
    top = _Section(_read_yaml(path), path, "", _HAND_KEYS)
    slots = top.value("slots")
    if not isinstance(slots, list) or not slots:
        top.fail("slots", slots, "must be a non-empty list of finger mounts")
    mounts = []
    for i, data in enumerate(slots):
        s = _Section(data, path, f"slots[{i}]", _SLOT_KEYS)
        mounts.append(FingerMount(slot=s.string("slot"),
                                  position=s.numbers("position", 3, what="x, y, z"),
                                  yaw=s.number("yaw"), finger=_slot_finger(s, path)))
    try:
        return HandSpec(name=top.string("name", path.stem), mounts=tuple(mounts),
                        tendon_stiffness=top.number("tendon_stiffness"),
                        spread=top.number("spread", 0.0),
                        palm_radius=top.number("palm_radius", HandSpec.palm_radius),
                        palm_thickness=top.number("palm_thickness", HandSpec.palm_thickness))
    except SpecError as exc:
        if str(path) in str(exc):
            raise
        raise SpecError(f"{path}: {exc}") from None


def _extras(s: _Section) -> dict[str, Any]:
    """An object's `extras`: declared flags and numbers, in the file's order."""
    return {k: s.flag(k) if k in _EXTRA_FLAGS else s.number(k) for k in s.data}


def load_object(name_or_path: str | Path) -> ObjectSpec:
    """Load an object by name (models/objects/NAME.yaml) or from a YAML file path."""
    path = _named_or_path(name_or_path, "objects", "object", available_objects())
    s = _Section(_read_yaml(path), path, "", _OBJECT_KEYS)
    shape = s.string("shape", choices=tuple(_SIZES))
    n_size, size_what = _SIZES[shape]
    try:
        return ObjectSpec(
            name=s.string("name", path.stem),
            shape=shape,
            size=s.numbers("size", n_size, what=f"{shape}: {size_what}"),
            mass=s.number("mass"),
            com=s.numbers("com", 3, what="x, y, z"),
            tag_id=s.integer("tag_id"),
            tag_size=s.number("tag_size"),
            grasp_height=s.number("grasp_height"),
            mesh=s.mesh("mesh"),
            friction=s.number("friction", 1.0),
            ycb=s.integer("ycb", None, allow_none=True),
            rgba=s.numbers("rgba", 4, default=[0.8, 0.2, 0.2, 1.0], what="r, g, b, a"),
            extras=_extras(s.section("extras", _EXTRA_FLAGS + _EXTRA_NUMBERS)),
        )
    except SpecError as exc:
        if str(path) in str(exc):
            raise
        raise SpecError(f"{path}: {exc}") from None


def with_finger(hand: HandSpec, slot: str, finger: FingerSpec) -> HandSpec:
    """A copy of `hand` with the finger in `slot` replaced."""
    hand.mount(slot)
    mounts = tuple(replace(m, finger=finger) if m.slot == slot else m for m in hand.mounts)
    return replace(hand, mounts=mounts)
