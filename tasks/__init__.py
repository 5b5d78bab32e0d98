"""Gymnasium environments of precise in-hand manipulation (docs/METHOD.md 5-6), registered on
import under the `vlr/` namespace:

    import gymnasium as gym
    import vlr.tasks

    gym.register_envs(vlr.tasks)
    env = gym.make("vlr/Handwriting-v1", backend="sim")

| id | task | max_episode_steps |
|---|---|---|
| `vlr/Handwriting-v1` | the POM under the apple traces the waypoints of "SCIENCE" | 588 |
| `vlr/MarbleMaze-v1` | a held maze plate is tilted so that a marble rolls to the goal | 75 |
| `vlr/CupStacking-v1` | the hand on an arm stacks four cups picked at unknown tilts | 80 |

Each episode's step limit is the most moves the task can take at its defaults (every target
given its whole move budget: 49 waypoints x 12, 5 runs x 15, 4 cups x 20), so the limit never
ends a default episode early; give `max_episode_steps` to `make` with other budgets. The
conventions are Gymnasium-Robotics' goal environments (tasks/base.py). The baseline policy is
the VLR Jacobian controller, `tasks.baseline.VLRBaseline`; docs in docs/TASKS.md. The version
suffix changes when an env's interface or behaviour changes.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

HANDWRITING = "vlr/Handwriting-v1"
MARBLE_MAZE = "vlr/MarbleMaze-v1"
CUP_STACKING = "vlr/CupStacking-v1"

# One table: id -> (entry point, max_episode_steps); entry points are strings, so that
# importing `vlr.tasks` stays cheap.
ENVIRONMENTS: dict[str, tuple[str, int]] = {
    HANDWRITING: ("vlr.tasks.handwriting:HandwritingEnv", 49 * 12),
    MARBLE_MAZE: ("vlr.tasks.maze:MarbleMazeEnv", 5 * 15),
    CUP_STACKING: ("vlr.tasks.cups:CupStackingEnv", 4 * 20),
}

for _id, (_entry, _steps) in ENVIRONMENTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_entry, max_episode_steps=_steps)

__all__ = ["ENVIRONMENTS", "HANDWRITING", "MARBLE_MAZE", "CUP_STACKING"]
