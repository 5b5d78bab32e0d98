"""VLR core: hardware-agnostic kinematics, motion and observation models, particle filter,
controller, AprilTag perception and the `vlr` CLI. Imports neither `sim` nor `hardware`.

The main job from Python (`vlr.run`):

    from vlr import load_settings, run_identification

    run = run_identification(load_settings({"filter.particles": 6000}))
"""

from __future__ import annotations

__all__ = ["Settings", "load_settings", "run_identification", "Identification"]

_LAZY = {"Settings": "vlr.settings", "load_settings": "vlr.settings",
         "run_identification": "vlr.run", "Identification": "vlr.run"}


def __getattr__(name: str):
    # Imported on first use, so that `vlr --help` and the hardware tools start fast.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'vlr' has no attribute {name!r}")
