"""One settings tree for an identification, and the one loader that reads it.

The tree (`Settings`) nests the components' own frozen dataclasses, each field with its unit:

    seed                       seeds the world, the filter and the actions
    world.*                    `WorldSettings`: backend, object, hand, true_hand, options
    filter.*                   `vlr.filter.FilterConfig`: the estimator (pf or ukf), particles,
                               unknowns, priors, the grasp prior, jitter and tempering
    filter.ukf.*               `vlr.filter.UnscentedConfig`: the unscented Kalman filter
                               (`vlr.ukf`)
    filter.motion.*            `vlr.motion.MotionConfig`: the motion model (Eq. 6-9)
    filter.observation.*       `vlr.observation.ObservationConfig`: the likelihood (Eq. 5)
    filter.object.*            `vlr.filter.ObjectBelief`: the object the filter believes
    loop.*                     `vlr.identify.LoopConfig`: actions and stopping (Algorithm 1)
    loop.active.*              `vlr.active.ActiveExploration`

`load_settings` builds a tree from the dataclasses' defaults, then the backend's own defaults
(`vlr.backends.Backend.defaults`: what was measured best on that world), then the caller's
layers in order: mappings, nested (`{filter: {particles: 6000}}`) or dotted
(`{"filter.particles": 6000}`), the form of a sweep file's settings and of `vlr identify
--set filter.particles=6000`. Every value is checked against its field's annotation; a
misspelt key, a wrong type or a value a component refuses is one `UserError` naming the key.
`world.options` is the backend's (`Backend.options`) and is checked against its dataclass.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from vlr.active import ActiveExploration  # noqa: F401  (the tree's annotations name it)
from vlr.errors import UserError
from vlr.filter import FilterConfig
from vlr.identify import LoopConfig

__all__ = ["WorldSettings", "Settings", "load_settings", "apply_layer", "build_dataclass",
           "flatten", "parse_assignment", "settings_help", "read_yaml_mapping",
           "DEFAULT_BACKEND"]

DEFAULT_BACKEND = "sim"


@dataclass(frozen=True)
class WorldSettings:
    """Where the identification runs.

    Attributes:
        backend: a backend registered under the `vlr.backends` entry points (`vlr.backends`):
            the simulator ("sim"), the real hand ("hardware") or the filter's own model as
            the world ("synthetic").
        object: an object name or spec file (models/README.md).
        hand: the hand the user believes in: the filter's model.
        true_hand: the hand the world is built with when it differs from `hand` (replaced
            fingers or springs the filter identifies as unknowns); None: `hand`. Only a
            world that builds its hand can take one (not the real hand).
        options: the backend's own settings (`vlr.backends.Backend.options`), e.g. the sim's
            `ramp_time`, the real hand's `config` file.
    """

    backend: str = DEFAULT_BACKEND
    object: str = "apple"
    hand: str = "modelo"
    true_hand: str | None = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Settings:
    """Everything that defines one identification (module docstring)."""

    seed: int = 0
    world: WorldSettings = field(default_factory=WorldSettings)
    filter: FilterConfig = field(default_factory=FilterConfig)
    loop: LoopConfig = field(default_factory=LoopConfig)

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ValueError(f"{self.seed} must be >= 0")

    def flat(self) -> dict[str, Any]:
        """The tree as {dotted key: value} (JSON-ready: tuples as lists)."""
        return flatten(self)

    def with_(self, **dotted: Any) -> Settings:
        """This tree with some keys replaced: `s.with_(**{"filter.particles": 600})`."""
        return apply_layer(self, dotted)


# --------------------------------------------------------------------------- the loader

def load_settings(*layers: Mapping[str, Any] | None, backend_defaults: bool = True) -> Settings:
    """The settings tree (module docstring): the dataclass defaults, then the backend's
    defaults (unless `backend_defaults` is False), then each layer in order, then the caps
    of `VLR_SMOKE` when it is set (`vlr.smoke`)."""
    from vlr import smoke
    from vlr.backends import get_backend

    layers = tuple(layer for layer in layers if layer)
    settings = Settings()
    name = DEFAULT_BACKEND
    for layer in layers:
        name = _backend_named(layer, name)
    backend = get_backend(name)
    if backend_defaults:
        settings = apply_layer(settings, backend.defaults, f"the {name} backend's default ")
    for layer in layers:
        settings = apply_layer(settings, layer)
    settings = apply_layer(settings, smoke.settings_layer(settings.flat()), "VLR_SMOKE's ")
    return backend.check(settings)


def _backend_named(layer: Mapping[str, Any], default: str) -> str:
    """The backend a layer names (world.backend, nested or dotted), else `default`."""
    if "world.backend" in layer:
        value = layer["world.backend"]
    elif isinstance(layer.get("world"), Mapping) and "backend" in layer["world"]:
        value = layer["world"]["backend"]
    else:
        return default
    if not isinstance(value, str):
        raise UserError(f"world.backend {value!r} must be a backend's name")
    return value


def apply_layer(obj: Any, layer: Mapping[str, Any], where: str = "") -> Any:
    """`obj` (a dataclass instance) with the keys of `layer` replaced, nested or dotted;
    each value checked against its field's annotation (module docstring)."""
    changes: dict[str, Any] = {}
    hints = _hints(type(obj))
    names = {f.name for f in dataclasses.fields(obj)}
    for key, value in _split(layer, where):
        head, _, rest = key.partition(".")
        path = f"{where}{head}"
        if head not in names:
            raise UserError(f"unknown setting {path!r}; {_accepts(type(obj), where)}")
        current = changes.get(head, getattr(obj, head))
        kind = hints[head]
        if dataclasses.is_dataclass(kind):
            if rest:
                value = {rest: value}
            if not isinstance(value, Mapping):
                raise UserError(f"{path}: {value!r} is not a mapping of its settings; "
                                f"{_accepts(kind, path + '.')}")
            changes[head] = apply_layer(current, value, path + ".")
        elif rest:
            if typing.get_origin(kind) is not dict:
                raise UserError(f"unknown setting {path}.{rest!r}: {path} is "
                                f"{_describe(kind)}, with no sub-keys")
            changes[head] = {**current, rest: value}
        else:
            changes[head] = convert(value, kind, path)
    if not changes:
        return obj
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError) as exc:
        keys = ", ".join(f"{where}{k}" for k in changes)
        raise UserError(f"{keys}: {exc}") from None


def build_dataclass(cls: type, mapping: Mapping[str, Any] | None, where: str = "") -> Any:
    """An instance of the dataclass `cls` from its defaults and `mapping`, checked as
    `apply_layer` checks (e.g. a backend's `world.options`)."""
    return apply_layer(cls(), mapping or {}, where)


def _split(layer: Mapping[str, Any], where: str) -> Iterator[tuple[str, Any]]:
    if not isinstance(layer, Mapping):
        raise UserError(f"{where or 'settings'}: {layer!r} is not a mapping of settings")
    for key, value in layer.items():
        if not isinstance(key, str) or not key or any(not p for p in key.split(".")):
            raise UserError(f"setting {where}{key!r}: a key is a dotted name, e.g. "
                            "filter.particles")
        yield key, value


def _hints(cls: type) -> dict[str, Any]:
    import sys

    module = sys.modules[cls.__module__]
    return typing.get_type_hints(cls, vars(module))


def _accepts(cls: type, where: str) -> str:
    keys = ", ".join(f"{where}{f.name}" for f in dataclasses.fields(cls))
    return f"known: {keys}"


def convert(value: Any, kind: Any, path: str) -> Any:
    """`value` as the annotation `kind` wants it (int, float, bool, str, Literal, optional,
    tuples, dicts), or a UserError naming `path`."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        others = [a for a in args if a is not type(None)]
        errors = []
        for a in others:
            try:
                return convert(value, a, path)
            except UserError as exc:
                errors.append(exc)
        raise UserError(f"{path}: {value!r} is not {_describe(kind)}")
    if kind is Any:
        return value
    if origin is Literal:
        if value not in args:
            raise UserError(f"{path}: {value!r} is not one of {', '.join(map(str, args))}")
        return value
    if kind is bool:
        if not isinstance(value, bool):
            raise UserError(f"{path}: {value!r} is not true or false")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise UserError(f"{path}: {value!r} is not an integer")
        return int(value)
    if kind is float:
        if isinstance(value, str):
            # YAML 1.1 (PyYAML) reads 1e5, unlike 1.0e+5, as a string.
            try:
                value = float(value)
            except ValueError:
                raise UserError(f"{path}: {value!r} is not a number") from None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise UserError(f"{path}: {value!r} is not a number")
        if math.isnan(value):
            raise UserError(f"{path}: {value!r} is not a number")
        return float(value)
    if kind is str:
        if not isinstance(value, str) or not value:
            raise UserError(f"{path}: {value!r} is not a name")
        return value
    if origin is tuple:
        if isinstance(value, str) and args[:1] == (str,):
            value = [value]
        if not isinstance(value, list | tuple):
            raise UserError(f"{path}: {value!r} is not {_describe(kind)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(v, args[0], path) for v in value)
        if len(value) != len(args):
            raise UserError(f"{path}: {value!r} is not {_describe(kind)}")
        return tuple(convert(v, a, path) for v, a in zip(value, args, strict=True))
    if origin is dict:
        if not isinstance(value, Mapping):
            raise UserError(f"{path}: {value!r} is not {_describe(kind)}")
        k_kind, v_kind = args
        return {convert(k, k_kind, path): convert(v, v_kind, f"{path}.{k}")
                for k, v in value.items()}
    raise TypeError(f"{path}: the loader cannot read a {kind!r}")


def _describe(kind: Any) -> str:
    """What an annotation accepts, in words."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        parts = [_describe(a) for a in args if a is not type(None)]
        return " or ".join(parts) + (" or none" if type(None) in args else "")
    if origin is Literal:
        return "one of " + ", ".join(map(str, args))
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        return f"a list of {len(args)} {_plural(args[0])}"
    if origin is dict:
        return "a mapping"
    return {bool: "true or false", int: "an integer", float: "a number", str: "a name",
            Any: "anything"}.get(kind, getattr(kind, "__name__", str(kind)))


def _plural(kind: Any) -> str:
    """`_describe` of a list's items: "numbers", not "a numbers"."""
    text = _describe(kind)
    for article in ("a ", "an "):
        if text.startswith(article):
            return text[len(article):] + "s"
    return text


def flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """{dotted key: value} of a dataclass tree (JSON-ready: tuples as lists)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = prefix + f.name
        if dataclasses.is_dataclass(value):
            out.update(flatten(value, key + "."))
        else:
            out[key] = _plain(value)
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def parse_assignment(text: str) -> tuple[str, Any]:
    """KEY=VALUE of `--set`: the value read as YAML (0.2, true, [1, 2], none), so that
    `--set` and a sweep file read alike."""
    import yaml

    from vlr.spec import DuplicateKeyError, safe_load_yaml, yaml_error_line

    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise UserError(f"--set {text!r}: use KEY=VALUE, e.g. filter.particles=6000")
    try:
        value = safe_load_yaml(raw) if raw.strip() else None
    except DuplicateKeyError as exc:
        raise UserError(f"--set {text!r}: {yaml_error_line(exc)}") from None
    except yaml.YAMLError:
        value = raw
    if isinstance(value, str) and value.lower() == "none":
        value = None
    return key, value


def settings_help(settings: Settings | None = None) -> str:
    """Every key of the tree with its value in `settings` (default: the dataclasses')."""
    flat = flatten(settings or Settings())
    width = max(len(k) for k in flat)
    return "\n".join(f"  {k:<{width}}  {v!r}" for k, v in flat.items())


def read_yaml_mapping(path, what: str) -> dict:
    """The YAML mapping in `path` (a settings or sweep file), or one UserError naming `what`
    and the file: missing, a folder, not UTF-8, not YAML, a key given twice, or not a
    mapping (`vlr.spec.load_yaml_mapping`, the reader of every user's YAML)."""
    from pathlib import Path

    from vlr.spec import load_yaml_mapping

    if not Path(path).exists():
        raise UserError(f"{what} {str(path)!r}: no such file")
    return load_yaml_mapping(path, what, UserError)
