"""How far the sim's object keeps moving after an action has settled (docs/RESULTS.md section
5, "What remains is in orientation").

A one-off diagnostic, not part of the package. MuJoCo's friction is a soft constraint: under
a steady tangential load a contact creeps. If the object kept turning after `settle()`, the
"true motion" of an action would depend on when the frame is taken, and no static model
could match it. Makes `vlr gap`'s first actions (seed 0's stream) and, after each, steps the
sim on for SECONDS at the same command; prints the action's motion and the creep.

    MUJOCO_GL=egl python docs/scripts/creep_probe.py [OBJECT] [SECONDS] [ACTIONS]
"""

import sys

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from sim.backend import SimHand
from sim.gap import GapSettings
from vlr.explore import ExplorationRange, random_action


def pose(hand: SimHand) -> tuple[np.ndarray, np.ndarray]:
    t = hand.truth()
    return t.pom_position.copy(), t.pom_rotation.copy()


def change(a, b) -> tuple[float, float]:
    """Position [mm] and rotation angle [deg] from pose a to pose b."""
    return (float(np.linalg.norm(b[0] - a[0]) * 1e3),
            float(np.degrees(Rotation.from_matrix(a[1].T @ b[1]).magnitude())))


def main() -> None:
    obj = sys.argv[1] if len(sys.argv) > 1 else "apple"
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    actions = int(sys.argv[3]) if len(sys.argv) > 3 else 10
    s = GapSettings(object=obj, actions=actions)
    with SimHand(object=obj, hand="modelo", seed=0) as hand:
        commands = [hand.grasp().commands]
        rng = np.random.default_rng(s.seed + 1)       # vlr gap's action stream
        explore = ExplorationRange(s.action_range[0], s.action_range[1],
                                   max(s.band, s.action_range[1]))
        center, before = commands[0].copy(), pose(hand)
        ratios = []
        for k in range(1, actions + 1):
            report = hand.apply(random_action(rng, commands[-1], center, explore))
            commands.append(report.commands)
            settled = pose(hand)
            for _ in range(int(seconds / hand.model.opt.timestep)):
                mujoco.mj_step(hand.model, hand.data)
            later = pose(hand)
            motion, creep = change(before, settled), change(settled, later)
            ratios.append((creep[0] / motion[0], creep[1] / motion[1]))
            print(f"{obj} action {k:2d} (settled: {report.settled}): motion {motion[0]:.3f} mm "
                  f"{motion[1]:.3f} deg; creep in {seconds:g} s {creep[0]:.4f} mm "
                  f"{creep[1]:.4f} deg ({ratios[-1][0]:.3f} / {ratios[-1][1]:.3f} of it)")
            before = later
        med = np.median(ratios, axis=0)
        print(f"{obj}: median creep over the motion {med[0]:.3f} / {med[1]:.3f}")


if __name__ == "__main__":
    main()
