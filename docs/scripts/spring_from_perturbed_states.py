"""Which thumb spring does the motion model want from true states whose joints are off, as a
filter particle's are? (docs/RESULTS.md section 5, session 35.)

A one-off diagnostic, not part of the package. `vlr gap --fit stiffness:thumb.distal` profiles
the spring from the sim's TRUE states and finds the truth. A particle's joints are never
exactly true. Here each of M draws perturbs every true joint angle by N(0, SD degrees), is
re-anchored to the true pose and settled, and predicts the recorded actions open loop for
each candidate spring (M x P particles in one vectorized solve). Prints, over the draws that
solve, the median and mean of each draw's best spring and how many lie above and below the
truth (0.045 N m/rad on modelo_thumb45).

    MUJOCO_GL=egl python docs/scripts/spring_from_perturbed_states.py SEED SD_DEG [ACTIONS]
"""

import sys
from dataclasses import replace

import numpy as np

from sim.gap import GapSettings, record_actions
from sim.gap_fit import motion_errors
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams, ParticleState

SPRINGS = np.linspace(0.035, 0.060, 11)  # N m/rad
DRAWS = 60
SIGMA = (0.2, 0.4)  # the sim trials' likelihood scales, mm and deg


def spring_row_recording(seed: int, actions: int):
    """The spring row's random actions recorded in the sim (toy block, modelo_thumb45, the
    0.1 s ramp), with the filter's motion model (rolling, stops at 17 N m/rad) on the true
    hand and the settle config of a particle at the grasp: (rec, model, motion, settle).
    Also used by spring_joint_lean.py."""
    rec = record_actions(GapSettings(object="toy_block", hand="modelo_thumb45", seed=seed,
                                     actions=actions, ramp_time=0.1))
    model = HandModel.from_spec(rec.hand_spec)
    cfg = replace(MotionConfig().with_rolling(True), limit_stiffness=17.0)  # the filter's
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    return rec, model, motion, replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)


def main(seed: int, sd_deg: float, actions: int) -> None:
    rec, model, motion, settle = spring_row_recording(seed, actions)
    f, j = model.finger_index("thumb"), model.joint_index("distal")
    p = len(SPRINGS)
    rng = np.random.default_rng(0)
    dth = rng.normal(0.0, np.radians(sd_deg), (DRAWS, model.n_fingers, model.n_joints))
    st = ParticleState.at_truth(model, rec.truths[0]).take(np.zeros(DRAWS * p, dtype=int))
    st.theta += np.repeat(dth, p, axis=0)
    st.stiffness[:, f, j] = np.tile(SPRINGS, DRAWS)
    st.anchor_to_pose(model)
    motion.solve(st, rec.commands[0], settle)
    cost = np.zeros(DRAWS * p)
    for k in range(1, len(rec.commands)):
        pa, ra = st.pos.copy(), st.rot.copy()
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        e_p, e_r = motion_errors(pa, ra, st.pos, st.rot, rec.truths[k - 1], rec.truths[k])
        cost += (e_p * 1e3 / SIGMA[0]) ** 2 + (e_r / SIGMA[1]) ** 2
    cost = np.where(st.valid, cost, np.inf).reshape(DRAWS, p)
    ok = np.isfinite(cost).all(axis=1)
    best = SPRINGS[np.argmin(cost[ok], axis=1)]
    truth = float(rec.truths[0].stiffness[f, j])
    print(f"seed {seed}, joints off by N(0, {sd_deg:g} deg), {len(rec.commands) - 1} actions: "
          f"best spring over {ok.sum()} draws median {np.median(best):.4f} mean "
          f"{best.mean():.4f}; above the truth {np.sum(best > truth + 1e-9)}, below "
          f"{np.sum(best < truth - 1e-9)}, at it {np.sum(np.isclose(best, truth))}")


if __name__ == "__main__":
    main(int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else 20)
