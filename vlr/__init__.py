"""VLR core: hardware-agnostic kinematics, motion and observation models, particle filter,
controller, AprilTag perception and the `vlr` CLI.

The one import namespace: the folders sim/, hardware/, tasks/ and models/ install as
`vlr.sim`, `vlr.hardware`, `vlr.tasks` and `vlr.models` (pyproject.toml). The core imports
neither `vlr.sim` nor `vlr.hardware`: they plug in through entry points.

The main job from Python (`vlr.run`):

    from vlr import load_settings, run_identification

    run = run_identification(load_settings({"filter.particles": 6000}))
"""

from __future__ import annotations

import os as _os
import sys as _sys

# numba's threading layer: a fork-safe one (TBB where its library loads, else numba's own
# work queue, as fast here). The default picks GNU OpenMP, which aborts a process forked
# after a parallel kernel ran: gymnasium's AsyncVectorEnv and Stable-Baselines3 fork their
# workers by default. A user's NUMBA_THREADING_LAYER is kept.
# And Mesa's llvmpipe (the sim's headless rendering) on the caller's thread: its own threads,
# which a fork does not copy, hang a child forked after a frame was rendered (`vlr.sim.backend`).
_os.environ.setdefault("LP_NUM_THREADS", "0")
if "NUMBA_THREADING_LAYER" not in _os.environ:
    _os.environ["NUMBA_THREADING_LAYER"] = "forksafe"
    if "numba" in _sys.modules:   # numba has read its environment already
        _sys.modules["numba"].config.THREADING_LAYER = "forksafe"

__all__ = ["Settings", "load_settings", "run_identification", "Identification"]

_LAZY = {"Settings": "vlr.settings", "load_settings": "vlr.settings",
         "run_identification": "vlr.run", "Identification": "vlr.run"}


def __getattr__(name: str):
    # Imported on first use, so that `vlr --help` and the hardware tools start fast.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'vlr' has no attribute {name!r}")
