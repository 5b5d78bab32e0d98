"""Gymnasium environments of precise in-hand manipulation (docs/METHOD.md 5-6), registered on
import under the `vlr/` namespace:

    import gymnasium as gym
    import vlr.tasks

    gym.register_envs(vlr.tasks)
    env = gym.make("vlr/Handwriting-v2", backend="sim")

| id (sparse reward; dense: `...Dense-v2`) | task | max_episode_steps |
|---|---|---|
| `vlr/Handwriting-v2` | the POM under the apple traces the waypoints of "SCIENCE" | 588 |
| `vlr/MarbleMaze-v2` | a held maze plate is tilted so that a marble rolls to the goal | 75 |
| `vlr/CupStacking-v2` | the hand on an arm stacks four cups picked at unknown tilts | 80 |

Each task is registered twice, as Gymnasium-Robotics' Fetch and Shadow hand environments are:
the plain id with the sparse reward (-1 until the camera puts the POM within the task's
tolerance of its target, then 0) and a `Dense` id with minus the distance to the target
(`vlr/HandwritingDense-v2`, ...); the two differ in `reward_type` only (tasks/base.py).
`vlr task NAME` runs the dense id (its progress bar shows minus the reward, the distance).

Each episode's step limit is the most moves the task can take at its defaults (every target
given its whole move budget: 49 waypoints x 12, 5 runs x 15, 4 cups x 20), so the limit never
ends a default episode early; give `max_episode_steps` to `make` with other budgets. The
conventions are Gymnasium-Robotics' goal environments (tasks/base.py). The baseline policy is
the VLR Jacobian controller, `tasks.baseline.VLRBaseline`; docs in docs/TASKS.md. The version
suffix changes when an env's interface or behaviour changes.
"""

from __future__ import annotations

from typing import NamedTuple

from gymnasium.envs.registration import register, registry

VERSION = 2
REWARD_TYPES = ("sparse", "dense")


class Registration(NamedTuple):
    """How an id is registered: the class (a string, so that importing `vlr.tasks` stays
    cheap), its step limit, and the reward it is made with."""

    entry_point: str
    max_episode_steps: int
    reward_type: str


def env_id(task: str, reward_type: str = "sparse") -> str:
    """The id of `task` ("Handwriting", "MarbleMaze", "CupStacking") with that reward:
    Fetch's naming, the plain id sparse and a `Dense` suffix dense."""
    if reward_type not in REWARD_TYPES:
        raise ValueError(f"reward_type {reward_type!r}: use one of {REWARD_TYPES}")
    return f"vlr/{task}{'Dense' if reward_type == 'dense' else ''}-v{VERSION}"


# Task -> (entry point, max_episode_steps).
_TASKS = {
    "Handwriting": ("vlr.tasks.handwriting:HandwritingEnv", 49 * 12),
    "MarbleMaze": ("vlr.tasks.maze:MarbleMazeEnv", 5 * 15),
    "CupStacking": ("vlr.tasks.cups:CupStackingEnv", 4 * 20),
}

HANDWRITING = env_id("Handwriting")
MARBLE_MAZE = env_id("MarbleMaze")
CUP_STACKING = env_id("CupStacking")
HANDWRITING_DENSE = env_id("Handwriting", "dense")
MARBLE_MAZE_DENSE = env_id("MarbleMaze", "dense")
CUP_STACKING_DENSE = env_id("CupStacking", "dense")

#: Every registered id, both rewards of each task.
ENVIRONMENTS: dict[str, Registration] = {
    env_id(task, reward): Registration(entry, steps, reward)
    for task, (entry, steps) in _TASKS.items() for reward in REWARD_TYPES}

#: Each sparse id's dense twin.
DENSE: dict[str, str] = {env_id(task): env_id(task, "dense") for task in _TASKS}

for _id, _reg in ENVIRONMENTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_reg.entry_point, max_episode_steps=_reg.max_episode_steps,
                 kwargs={"reward_type": _reg.reward_type})

__all__ = ["ENVIRONMENTS", "DENSE", "REWARD_TYPES", "Registration", "env_id", "HANDWRITING",
           "MARBLE_MAZE", "CUP_STACKING", "HANDWRITING_DENSE", "MARBLE_MAZE_DENSE",
           "CUP_STACKING_DENSE"]
