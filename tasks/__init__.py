"""Gymnasium environments of precise in-hand manipulation (docs/METHOD.md 5-6), registered on
import under the `vlr/` namespace:

    import gymnasium, tasks
    env = gymnasium.make("vlr/Handwriting-v0", backend="sim")

| id | task |
|---|---|
| `vlr/Handwriting-v0` | the POM under the apple traces the waypoints of "SCIENCE" |
| `vlr/MarbleMaze-v0` | a held maze plate is tilted so that a marble rolls to the goal |
| `vlr/CupStacking-v0` | the hand on an arm stacks four cups picked at unknown tilts |

The baseline policy is the VLR Jacobian controller, `tasks.baseline.VLRBaseline`; docs in
docs/TASKS.md. The version
suffix changes when an env's behaviour changes.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

HANDWRITING = "vlr/Handwriting-v0"
MARBLE_MAZE = "vlr/MarbleMaze-v0"
CUP_STACKING = "vlr/CupStacking-v0"

# One table: id -> entry point (a string, so that importing `tasks` stays cheap).
ENVIRONMENTS: dict[str, str] = {
    HANDWRITING: "tasks.handwriting:HandwritingEnv",
    MARBLE_MAZE: "tasks.maze:MarbleMazeEnv",
    CUP_STACKING: "tasks.cups:CupStackingEnv",
}

for _id, _entry in ENVIRONMENTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_entry, disable_env_checker=True)

__all__ = ["ENVIRONMENTS", "HANDWRITING", "MARBLE_MAZE", "CUP_STACKING"]
