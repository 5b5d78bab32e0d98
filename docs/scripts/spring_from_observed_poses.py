"""The thumb spring the motion model wants against the poses the CAMERA reads, beside the
true ones (docs/RESULTS.md section 5, session 35).

A one-off diagnostic, not part of the package. `vlr gap --fit` profiles an unknown against
the sim's true POM motions. The filter sees the poses the perception pipeline reads from the
rendered frames instead. This records the toy block's random actions (modelo_thumb45, the
0.1 s ramp, `vlr identify`'s action stream for SEED), reads the tag after each, and prints
the observed displacement's scale against the true one, the static offset, and each
candidate spring's cost (the filter's model, each action from the true state) against the
true and the observed motions.

    MUJOCO_GL=egl python docs/scripts/spring_from_observed_poses.py SEED [ACTIONS]
"""

import sys
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from sim.backend import SimHand, SimOptions
from sim.gap_fit import motion_errors
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams, ParticleState
from vlr.perception.pipeline import observe

SPRINGS = np.linspace(0.030, 0.065, 15)  # N m/rad
SIGMA = (0.2, 0.4)  # the sim trials' likelihood scales, mm and deg


def main(seed: int, actions: int) -> None:
    with SimHand(object="toy_block", hand="modelo_thumb45", seed=seed,
                 options=SimOptions(ramp_time=0.1)) as hand:
        spec = hand.object_spec

        def look():
            o = observe(hand.grab_frame().image, hand.calibration, spec.tag_id,
                        spec.tag_size)
            return SimpleNamespace(position=o.position, rotation=o.rotation)

        grasp = hand.grasp()
        commands, truths, seen = [grasp.commands], [hand.scoring_truth()], [look()]
        rng = np.random.default_rng(seed + 1)  # vlr identify's action stream
        explore = ExplorationRange(0.2e-3, 0.4e-3, 0.4e-3)
        for _ in range(actions):
            report = hand.apply(random_action(rng, commands[-1], commands[0], explore))
            commands.append(report.commands)
            truths.append(hand.scoring_truth())
            seen.append(look())
        hand_spec, object_spec = hand.true_spec, hand.object_spec
    d_seen = np.array([o.position - seen[0].position for o in seen])
    d_true = np.array([t.position - truths[0].position for t in truths])
    scale = float((d_seen * d_true).sum() / (d_true * d_true).sum())
    offset = np.abs(seen[0].position - truths[0].position).max() * 1e3
    print(f"seed {seed}: observed/true displacement {scale:.4f}, static offset {offset:.4f} mm")
    model = HandModel.from_spec(hand_spec)
    cfg = replace(MotionConfig().with_rolling(True), limit_stiffness=17.0)  # the filter's
    motion = MotionModel(model, ObjectParams.from_spec(object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    f, j = model.finger_index("thumb"), model.joint_index("distal")
    p = len(SPRINGS)
    cost_true, cost_seen = np.zeros(p), np.zeros(p)
    for k in range(actions):
        st = ParticleState.at_truth(model, truths[k]).take(np.zeros(p, dtype=int))
        st.stiffness[:, f, j] = SPRINGS
        motion.solve(st, commands[k], settle)
        p0, r0 = st.pos.copy(), st.rot.copy()
        motion.solve(st, commands[k + 1], u_from=commands[k])
        for cost, a, b in ((cost_true, truths[k], truths[k + 1]), (cost_seen, seen[k],
                                                                   seen[k + 1])):
            e_p, e_r = motion_errors(p0, r0, st.pos, st.rot, a, b)
            cost += (e_p * 1e3 / SIGMA[0]) ** 2 + (e_r / SIGMA[1]) ** 2
    for k, ct, cs in zip(SPRINGS, cost_true, cost_seen, strict=True):
        print(f"  spring {k:.4f}: cost against the truth {ct:8.1f}, against the camera {cs:8.1f}")
    print(f"best against the truth {SPRINGS[cost_true.argmin()]:.4f}, against the camera "
          f"{SPRINGS[cost_seen.argmin()]:.4f}")


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 40)
