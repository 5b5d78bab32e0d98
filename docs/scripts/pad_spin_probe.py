"""Where the object's turn in its grip goes wrong: each pad's spin and roll against the
object per action, the sim's against the motion model's (docs/RESULTS.md section 5,
session 26).

A one-off diagnostic, not part of the package. `vlr gap`'s random actions on OBJECT (seed
SEED); each action is predicted as `vlr gap` does (from the truth re-settled, glued, then
the command change with the pads' friction). Per action and finger: the relative rotation
of the object against the distal link over the action, split into the spin about the
contact normal and the roll about the tangent plane, the sim's (from its true joint angles
and object pose) and the model's; the sim's normal force, spin torque and cone load after
the action (MuJoCo's elliptic cone: (f / mu)^2 + (tau / mu_t)^2 <= N^2) and the model's
normal force. Sim ground truth: this is scoring, never the estimator.

    MUJOCO_GL=egl python docs/scripts/pad_spin_probe.py apple 0 30
"""

import math
import sys
from dataclasses import replace

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from sim.backend import SimHand
from sim.gap import GapSettings, _angle_deg, _state
from sim.pads import SLIDE_FRICTION, TORSION_FRICTION
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams
from vlr.observation import rotation_error
from vlr.surface import _distal_rotations

FRICTION = replace(MotionConfig().with_rolling(), slide_friction=SLIDE_FRICTION,
                   spin_friction=TORSION_FRICTION)
SETTLE = replace(FRICTION, jump_theta=1.0, jump_pos=0.05, max_iter=200)


def pad_loads(hand: SimHand) -> dict[str, tuple[float, float, float]]:
    """Per finger: the sim's pad normal force [N], spin torque [N mm] (signed about the
    contact frame's normal) and cone load (1: on the cone)."""
    m, d, f = hand.model, hand.data, np.zeros(6)
    out = {}
    for i in range(d.ncon):
        c = d.contact[i]
        if hand._obj_body not in (m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]):
            continue
        other = c.geom2 if m.geom_bodyid[c.geom1] == hand._obj_body else c.geom1
        name = m.geom(other).name
        if not name.endswith("/pad"):
            continue
        mujoco.mj_contactForce(m, d, i, f)
        load = np.hypot(np.hypot(f[1], f[2]) / SLIDE_FRICTION, f[3] / TORSION_FRICTION) / f[0]
        out[name.split("/")[0]] = (float(f[0]), float(f[3] * 1e3), float(load))
    return out


def spin_roll(model: HandModel, theta0, rot0, theta1, rot1, normals1) -> np.ndarray:
    """(N, 2) per finger: the object's rotation against the distal link over the action,
    its component about the pad normal (spin) and the rest (roll) [deg]."""
    rd0 = _distal_rotations(model, theta0[None])[0]
    rd1 = _distal_rotations(model, theta1[None])[0]
    out = []
    for i in range(model.n_fingers):
        rel = (rd1[i].T @ rot1) @ (rd0[i].T @ rot0).T  # in D after the action
        w = Rotation.from_matrix(rel).as_rotvec()
        n = normals1[i] / np.linalg.norm(normals1[i])
        spin = float(w @ n)
        out.append((math.degrees(spin), math.degrees(float(np.linalg.norm(w - spin * n)))))
    return np.array(out)


def record(obj: str, seed: int, actions: int = 30):
    """`vlr gap`'s random actions in the sim: the hand's and the object's specs, the finger
    slots, the commands, the true state after each, and the sim's pad loads (`pad_loads`)
    and pad forces on the object (`true_loads_probe.pad_forces`) with it."""
    from true_loads_probe import pad_forces

    s = GapSettings(object=obj, seed=seed, actions=actions)
    with SimHand(object=obj, seed=seed) as hand:
        commands = [hand.grasp().commands]
        truths, loads, forces = [hand.scoring_truth()], [pad_loads(hand)], [pad_forces(hand)]
        rng = np.random.default_rng(seed + 1)
        explore = ExplorationRange(s.action_range[0], s.action_range[1], s.band)
        for _ in range(actions):
            r = hand.apply(random_action(rng, commands[-1], commands[0], explore))
            if not r.grasp_held:
                break
            commands.append(r.commands)
            truths.append(hand.scoring_truth())
            loads.append(pad_loads(hand))
            forces.append(pad_forces(hand))
        return (hand.true_spec, hand.object_spec, hand.slots, commands, truths, loads,
                np.array(forces))


def main(obj: str = "apple", seed: int = 0, actions: int = 30) -> None:
    true_spec, obj_spec, slots, commands, truths, loads, _ = record(obj, seed, actions)
    model = HandModel.from_spec(true_spec)
    mm = MotionModel(model, ObjectParams.from_spec(obj_spec), FRICTION)
    print(f"{obj}, seed {seed}; per finger: spin sim/model, roll sim/model [deg]; sim N [N], "
          "tau [N mm], cone load; model N [N]")
    print(f"fingers {slots}")
    rows = []
    for k in range(len(commands) - 1):
        t0, t1 = truths[k], truths[k + 1]
        st = _state(model, t0)
        mm.solve(st, commands[k], SETTLE)
        th0, r0 = st.theta[0].copy(), st.rot[0].copy()
        mm.solve(st, commands[k + 1], u_from=commands[k])
        if not st.valid[0]:
            print(f"action {k + 1:2d}: the model's solve failed (left out, as vlr gap does)")
            continue
        e_r = rotation_error((st.rot[0] @ r0.T) @ (t1.rotation @ t0.rotation.T).T, np.eye(3))
        true_turn = _angle_deg(t1.rotation @ t0.rotation.T)
        sim = spin_roll(model, t0.theta, t0.rotation, t1.theta, t1.rotation, t1.normals)
        mod = spin_roll(model, th0, r0, st.theta[0], st.rot[0], st.normals[0])
        n_model = mm.normal_forces(st, mm.rolling_frames(st))[0]
        ratio = math.degrees(np.linalg.norm(e_r)) / true_turn if true_turn > 0 else math.nan
        print(f"action {k + 1:2d}: turn {true_turn:5.2f} deg, error "
              f"{math.degrees(np.linalg.norm(e_r)):4.2f} (ratio {ratio:4.2f}), error axis "
              f"(palm x y z) {np.round(np.degrees(e_r), 2)}")
        for i, slot in enumerate(slots):
            n, tau, load = loads[k + 1].get(slot, (math.nan, math.nan, math.nan))
            print(f"   {slot:6s} spin {sim[i, 0]:6.2f} / {mod[i, 0]:6.2f}   roll "
                  f"{sim[i, 1]:5.2f} / {mod[i, 1]:5.2f}   sim N {n:5.2f} tau {tau:6.3f} "
                  f"load {load:4.2f}   model N {n_model[i]:5.2f}")
        rows.append((ratio, *np.degrees(e_r), *(sim[:, 0] - mod[:, 0])))
    r = np.array(rows)
    print("RMS spin error (sim - model) per finger [deg]:",
          np.round(np.sqrt(np.nanmean(r[:, 4:] ** 2, axis=0)), 3),
          f"; mean orientation ratio {np.nanmean(r[:, 0]):.3f}")
    # An error that one action makes and the next takes back alternates in sign: a state
    # the sim carries from action to action and a restarted model does not.
    print("orientation error RMS about the palm's x y z [deg]:",
          np.round(np.sqrt(np.mean(r[:, 1:4] ** 2, axis=0)), 3),
          "; lag-1 autocorrelation about x, y:",
          [round(float(np.corrcoef(r[:-1, 1 + a], r[1:, 1 + a])[0, 1]), 2) for a in (0, 1)])


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "apple",
         int(sys.argv[2]) if len(sys.argv) > 2 else 0,
         int(sys.argv[3]) if len(sys.argv) > 3 else 30)
