"""The real hand as a `vlr` backend (entry point group vlr.backends): its `world.options` and
defaults, without importing the motor bus, so that the settings tree loads where the
`hardware` extra is not installed; opening the hand does import it (and says which extra is
missing if it is)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from vlr.hardware.errors import HardwareError

__all__ = ["HardwareWorldOptions", "BACKEND"]


@dataclass(frozen=True)
class HardwareWorldOptions:
    """The real hand's `world.options` (`vlr.backends`).

    Attributes:
        config: the hardware YAML file (hardware/README.md): ports, motor ids, the camera,
            the object grasped and the hand.
    """

    config: str | None = None


def _open_configured(*, config: str | None = None, **ignored: Any):
    if not config:
        raise HardwareError("the hardware backend needs its config file: --config FILE "
                            "(world.options.config; hardware/README.md)")
    from vlr.hardware.backend import open_hand

    return open_hand(config=config)


def _backend():
    from vlr.backends import Backend

    # The real hand runs at the dataclasses' defaults: rolling contacts, the surface contact
    # prior, 0.5 mm / 1 degree likelihood scales (its model-world gap is not measured), hard
    # plastic stops at 100 N m/rad, the generic grasp guess (give yours:
    # filter.guess_theta_deg).
    return Backend(name="hardware", options=HardwareWorldOptions, open_hand=_open_configured,
                   builds_hand=False)


BACKEND = _backend()
