"""Backends: the worlds an identification runs in, plugged in through entry points.

A backend registers a `Backend` under the `vlr.backends` entry-point group (pyproject.toml):
the simulator (`sim`), the real hand (`hardware`) and the filter's own model as the world
(`synthetic`). Each brings what only it knows: its defaults of the settings tree (what was
measured best on that world, docs/DECISIONS.md), the dataclass of its own `world.options`,
and how to open it. `vlr` itself holds no backend's name or default.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

from vlr.errors import UserError

if TYPE_CHECKING:
    from vlr.settings import Settings
    from vlr.world import World

__all__ = ["Backend", "BACKEND_GROUP", "get_backend", "backend_names", "open_hand"]

BACKEND_GROUP = "vlr.backends"


@dataclass(frozen=True)
class Backend:
    """One world an identification can run in.

    Attributes:
        name: the name it is registered under (`world.backend`).
        options: the dataclass of its `world.options` (its own settings).
        defaults: {dotted key: value} of the settings tree this world runs best at.
        open_hand: object=, hand=, seed= and the options' fields as keyword arguments ->
            a `vlr.hand.Hand`, for a backend of hands; the world around it is
            `vlr.world.hand_world`'s.
        open_world: (settings, options, model, obj, nominal, hand_spec, object_spec) -> a
            `vlr.world.World`, for a world of its own (the synthetic one).
        builds_hand: the world is built from a hand spec, so it can take a `true_hand`
            other than the filter's (not the real hand: it is what it is).
    """

    name: str
    options: type
    defaults: Mapping[str, Any] = field(default_factory=dict)
    open_hand: Callable[..., Any] | None = None
    open_world: Callable[..., World] | None = None
    builds_hand: bool = True

    def world_options(self, settings: Settings) -> Any:
        """`settings.world.options` as this backend's options dataclass."""
        from vlr.settings import build_dataclass

        return build_dataclass(self.options, settings.world.options, "world.options.")

    def check(self, settings: Settings) -> Settings:
        """`settings` with `world.options` completed by this backend's defaults (so that a
        result records every option in effect), or a UserError naming the bad key."""
        options = dataclasses.asdict(self.world_options(settings))
        if settings.world.true_hand and not self.builds_hand:
            raise UserError(f"world.true_hand {settings.world.true_hand!r}: the {self.name} "
                            "hand is what it is; leave it out")
        return dataclasses.replace(
            settings, world=dataclasses.replace(settings.world, options=options))


def backend_names() -> list[str]:
    return sorted(ep.name for ep in entry_points(group=BACKEND_GROUP))


@cache
def get_backend(name: str) -> Backend:
    """The backend registered under `name`, or a UserError naming the known ones."""
    found = {ep.name: ep for ep in entry_points(group=BACKEND_GROUP)}
    if name not in found:
        raise UserError(f"world.backend {name!r}: unknown; available: "
                        f"{', '.join(sorted(found))}")
    backend = found[name].load()
    if not isinstance(backend, Backend):
        raise TypeError(f"entry point {name!r} of {BACKEND_GROUP} is not a vlr Backend")
    return backend


def open_hand(name: str, **options: Any):
    """A `vlr.hand.Hand` of the backend `name` (sim, hardware), opened with its factory's
    keyword arguments (e.g. object, hand, seed for the sim; config for the real hand)."""
    backend = get_backend(name)
    if backend.open_hand is None:
        raise UserError(f"the {name} backend has no hand to open")
    return backend.open_hand(**options)
