"""Does the motion model itself want the joints and the thumb spring off the truth together?
(docs/RESULTS.md section 5, session 37.)

A one-off diagnostic, not part of the package. The spring row's trials end with the joints'
posterior medians off the truth in one pattern, whatever the guess (the proximal joints
about 1 degree more extended, the distal ones about 1 degree more flexed), and the thumb's
distal spring about 6% stiff. `vlr gap --fit` varies the spring alone at the true joints and
finds the truth. Here the true grasp's joints are moved together along that pattern, d =
(-1, +1) degree per (proximal, distal) of every finger, times a in OFFSETS, each with every
candidate spring (one vectorized solve); each particle is re-anchored to the true pose,
settled at the grasp's command as the filter's particles are, and predicts the recorded
actions open loop. Its cost is minus twice the filter's likelihood with the turn term
(`sim.gap_fit.likelihood_cost`). Prints the cost over (a, spring) against the truth's
(a = 0, 0.045), each row's best spring and the settled joints' offset along d.

    MUJOCO_GL=egl python docs/scripts/spring_joint_lean.py SEED [ACTIONS]
"""

import math
import sys

import numpy as np
from spring_from_perturbed_states import spring_row_recording  # docs/scripts, beside this

from sim.gap_fit import likelihood_cost
from vlr.motion import ParticleState
from vlr.observation import ObservationModel

SPRINGS = np.linspace(0.039, 0.057, 13)  # N m/rad
OFFSETS = np.array([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0])  # degrees along d


def main(seed: int, actions: int) -> None:
    rec, model, motion, settle = spring_row_recording(seed, actions)
    obs = ObservationModel(sigma_pos=0.2e-3, sigma_rot=math.radians(0.4),
                           sigma_turn=math.radians(1.0), opposed=model.finger_index("thumb"))
    f, j = model.finger_index("thumb"), model.joint_index("distal")
    n_a, n_k = len(OFFSETS), len(SPRINGS)
    d = np.tile(np.radians([-1.0, 1.0]), (model.n_fingers, 1))
    st = ParticleState.at_truth(model, rec.truths[0]).take(np.zeros(n_a * n_k, dtype=int))
    theta0 = st.theta[0].copy()
    st.theta += np.repeat(OFFSETS, n_k)[:, None, None] * d[None]
    st.stiffness[:, f, j] = np.tile(SPRINGS, n_a)
    st.anchor_to_pose(model)
    motion.solve(st, rec.commands[0], settle)
    # Each candidate's settled offset along d, in the units of a (degrees along d).
    along = (st.theta - theta0).reshape(len(st.theta), -1) @ d.ravel() / (d.ravel() @ d.ravel())
    cost = np.zeros(n_a * n_k)
    for k in range(1, len(rec.commands)):
        pa, ra = st.pos.copy(), st.rot.copy()
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        cost += likelihood_cost(st, pa, ra, rec.truths[k - 1], rec.truths[k], obs)
    cost = np.where(st.valid, cost, np.nan).reshape(n_a, n_k)
    k_true = float(rec.truths[0].stiffness[f, j])
    ref = cost[int(np.argmin(np.abs(OFFSETS))), int(np.argmin(np.abs(SPRINGS - k_true)))]
    print(f"seed {seed}, {len(rec.commands) - 1} actions; cost minus the truth's "
          f"({ref:.1f}); rows: joints moved a degrees along d, settled offset in brackets")
    print("a [deg]       " + " ".join(f"{k:7.4f}" for k in SPRINGS) + "   best")
    for i, a in enumerate(OFFSETS):
        row = cost[i] - ref
        best = SPRINGS[np.nanargmin(cost[i])] if np.isfinite(cost[i]).any() else math.nan
        print(f"{a:5.1f} ({np.mean(along.reshape(n_a, n_k)[i]):5.2f}) "
              + " ".join(f"{c:7.1f}" for c in row) + f"   {best:.4f}")
    i, k = np.unravel_index(np.nanargmin(cost), cost.shape)
    print(f"least cost at a = {OFFSETS[i]:g} degrees, spring {SPRINGS[k]:.4f}: "
          f"{cost[i, k] - ref:+.1f} against the truth")


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 40)
