"""Per action: the object's turn and each finger's joint moves, the sim's against the motion
model's (docs/RESULTS.md section 5, session 29: the apple's push actions).

A one-off diagnostic, not part of the package. `vlr gap`'s random actions on OBJECT (seed
SEED), each predicted by the friction rung (spin memory on when the torsional friction is)
restarted from the sim's contact loads (`vlr gap --start sim-loads`), with the model's joint
stops at K_LIM N m/rad and the pads' torsional friction MU_T [m] (the sim's 0.001 by
default; 0 drops it). Prints the command change [mm], the object's rotation vector over the
action [deg, palm frame], true and predicted, and each finger's (proximal, distal) joint
moves [deg], true / predicted. Sim ground truth: this is scoring, never the estimator.

    MUJOCO_GL=egl python docs/scripts/push_split_probe.py apple 0 --limit-stiffness 17
    MUJOCO_GL=egl python docs/scripts/push_split_probe.py apple 0 --limit-stiffness 17 \\
        --spin-friction 0
"""

import argparse
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from sim.gap import _ALL, GapSettings, _pose, _start, record_actions
from sim.pads import TORSION_FRICTION
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("object", nargs="?", default="apple")
    ap.add_argument("seed", type=int, nargs="?", default=0)
    ap.add_argument("--actions", type=int, default=30)
    ap.add_argument("--limit-stiffness", type=float, default=MotionConfig.limit_stiffness)
    ap.add_argument("--spin-friction", type=float, default=TORSION_FRICTION)
    a = ap.parse_args()
    if not a.limit_stiffness > 0 or not 0 <= a.spin_friction <= 0.01 or a.actions < 1:
        ap.error("--limit-stiffness must be > 0, --spin-friction in [0, 0.01] m, "
                 "--actions >= 1")
    memory = a.spin_friction > 0
    s = GapSettings(object=a.object, seed=a.seed, actions=a.actions, start="sim-loads",
                    limit_stiffness=a.limit_stiffness, spin_friction=a.spin_friction,
                    spin_memory=memory)
    rec = record_actions(s)
    model = HandModel.from_spec(rec.hand_spec)
    cfg = replace(MotionConfig(terms=_ALL, limit_stiffness=a.limit_stiffness),
                  slide_friction=s.slide_friction, spin_friction=a.spin_friction,
                  spin_memory=memory)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    print(f"{a.object}, seed {a.seed}, from the sim's loads, stops {a.limit_stiffness:g} "
          f"N m/rad, torsional friction {a.spin_friction * 1e3:g} mm")
    for k in range(len(rec.commands) - 1):
        t0, t1 = rec.truths[k], rec.truths[k + 1]
        st = _start(motion, settle, model, rec, k, "sim-loads")
        _, r0 = _pose(st)
        th0 = st.theta[0].copy()
        motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        _, r1 = _pose(st)
        w_true = np.degrees(Rotation.from_matrix(t1.rotation @ t0.rotation.T).as_rotvec())
        w_pred = np.degrees(Rotation.from_matrix(r1 @ r0.T).as_rotvec())
        du = (rec.commands[k + 1] - rec.commands[k]) * 1e3
        joints = " ".join(
            f"{np.round(np.degrees(t1.theta[i] - t0.theta[i]), 1)}/"
            f"{np.round(np.degrees(st.theta[0, i] - th0[i]), 1)}" for i in range(len(du)))
        print(f"action {k + 1:2d}: du {np.round(du, 2)} mm, turn true {np.round(w_true, 2)} "
              f"model {np.round(w_pred, 2)} (error {np.linalg.norm(w_true - w_pred):.2f}); "
              f"joints true/model {joints}")


if __name__ == "__main__":
    main()
