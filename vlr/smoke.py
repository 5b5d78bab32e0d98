"""`VLR_SMOKE=1`: every command on its own default path, at a smoke test's size.

The commands the README and the docs show are run as written by `tests/test_doc_commands.py`,
with this one environment variable set and no other change: no flag the example lacks. With
it set, each size a command would spend minutes on is capped where the command reads it:

- the settings tree (`vlr.settings.load_settings`): `filter.particles` at most `PARTICLES`,
  the loop's actions (`loop.max_iterations`, `loop.min_iterations`) at most `ACTIONS`, the
  model check's burn-in and minimum actions within them (a verdict, not "undecided");
- seeds (`vlr.sweep.parse_seeds`): the first one only; a sweep's trials: the first `TRIALS`,
  and as many are enough for `vlr model-check-calibrate` (one decided trial an object);
- a task's episode: at most `TASK_MOVES` moves; `vlr bench`: particle counts at most
  `BENCH_PARTICLES`, one timed iteration each; `vlr gap` and `vlr crb`: `ACTIONS` actions.

The code path is the default one; only the sizes shrink. Numbers printed under it are not
results.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TypeVar

ENV = "VLR_SMOKE"
PARTICLES = 200
ACTIONS = 2
TRIALS = 2
TASK_MOVES = 3
BENCH_PARTICLES = 2_000

T = TypeVar("T")


def active() -> bool:
    """Whether `VLR_SMOKE` is set to something other than "", "0" or "false"."""
    return os.environ.get(ENV, "").strip().lower() not in ("", "0", "false", "no")


def cap(value: int, limit: int) -> int:
    """`value`, at most `limit` when smoke-sized."""
    return min(int(value), limit) if active() else int(value)


def first(items: Sequence[T], count: int = 1) -> list[T]:
    """The first `count` of `items` when smoke-sized, else all of them."""
    return list(items[:count]) if active() else list(items)


def settings_layer(flat: dict) -> dict:
    """The layer that caps a settings tree's sizes (`flat`: its dotted keys and values)."""
    if not active():
        return {}
    layer = {}
    if flat.get("filter.particles", 0) > PARTICLES:
        layer["filter.particles"] = PARTICLES
    for key in ("loop.min_iterations", "loop.max_iterations"):   # min first: min <= max
        if flat.get(key, 0) > ACTIONS:
            layer[key] = ACTIONS
    burn_in = flat.get("filter.model_check.burn_in", 0)
    min_actions = flat.get("filter.model_check.min_actions", 1)
    if burn_in + min_actions > ACTIONS:
        layer["filter.model_check.burn_in"] = 0
        layer["filter.model_check.min_actions"] = min(min_actions, ACTIONS)
    return layer
