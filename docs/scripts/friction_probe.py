"""Why the motion model needed the pads' friction, and what it costs (docs/RESULTS.md
section 5, "The pads' friction").

A one-off diagnostic, not part of the package. Three probes on the apple, seed 0, with
`vlr gap`'s random actions (sim ground truth: this is scoring, never the estimator):

* `cone`: the sim's pad contacts after each action, each one's tangential force and spin
  torque against its cone (MuJoCo's elliptic cone: (f / mu)^2 + (tau / mu_t)^2 <= N^2).
* `glued`: the motion model without friction, predicted open loop from the first true
  state: each contact's normal force and the tangential force its penalty holds.
* `cost`: 1000 copies of the first true state (joints jittered by 0.6 degrees), three
  actions, rolling with and without friction: time, Newton iterations and failures.

    MUJOCO_GL=egl python docs/scripts/friction_probe.py cone
    MUJOCO_GL=egl python docs/scripts/friction_probe.py glued
    MUJOCO_GL=egl python docs/scripts/friction_probe.py cost
"""

import sys
import time
from dataclasses import replace

import mujoco
import numpy as np

from sim.backend import SimHand
from sim.gap import GapSettings, _state, record_actions
from sim.pads import SLIDE_FRICTION, TORSION_FRICTION
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel, contact_points
from vlr.motion import MotionConfig, MotionModel, ObjectParams
from vlr.surface import surface_normals

ROLL = MotionConfig().with_rolling()
FRICTION = replace(ROLL, slide_friction=SLIDE_FRICTION, spin_friction=TORSION_FRICTION)
SETTLE = dict(jump_theta=1.0, jump_pos=0.05, max_iter=200)


def cone(actions: int = 12) -> None:
    at_cone = total = 0
    with SimHand(object="apple", seed=0) as hand:
        c0 = hand.grasp().commands
        rng = np.random.default_rng(1)  # vlr gap's action stream
        explore = ExplorationRange(0.2e-3, 0.4e-3, 0.4e-3)
        u, m, d, f = c0.copy(), hand.model, hand.data, np.zeros(6)
        for k in range(1, actions + 1):
            u = hand.apply(random_action(rng, u, c0, explore)).commands
            print(f"after action {k}")
            for i in range(d.ncon):
                c = d.contact[i]
                if hand._obj_body not in (m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]):
                    continue
                other = c.geom2 if m.geom_bodyid[c.geom1] == hand._obj_body else c.geom1
                mujoco.mj_contactForce(m, d, i, f)
                n, ft, tau = f[0], np.hypot(f[1], f[2]), abs(f[3])
                load = np.hypot(ft / SLIDE_FRICTION, tau / TORSION_FRICTION) / n
                total += 1
                at_cone += load > 0.98
                print(f"  {m.geom(other).name:12s} N {n:5.2f} N, f_t {ft:5.2f} N, "
                      f"tau {tau * 1e3:5.2f} mN m, cone load {load:4.2f}")
    print(f"{at_cone} of {total} pad contacts at their cone (load > 0.98)")


def glued(actions: int = 6) -> None:
    rec = record_actions(GapSettings(object="apple", actions=actions))
    model = HandModel.from_spec(rec.hand_spec)
    mm = MotionModel(model, ObjectParams.from_spec(rec.object_spec), ROLL)
    st = _state(model, rec.truths[0])
    mm.solve(st, rec.commands[0], replace(ROLL, **SETTLE))
    for k in range(len(rec.commands)):
        if k:
            mm.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        m = surface_normals(model, st.theta, st.normals, st.rot)
        c = np.einsum("pba,pnb->pna", st.rot,
                      contact_points(model, st.theta, st.normals, st.segments)
                      - st.pos[:, None])
        dv = c - st.anchors
        t = np.linalg.norm(dv - np.sum(dv * m, -1, keepdims=True) * m, axis=-1)[0]
        n = mm.normal_forces(st, mm.rolling_frames(st, m))[0]
        print(f"action {k}: normal {np.round(n, 2)} N, tangential "
              f"{np.round(ROLL.contact_stiffness * t, 2)} N")


def cost(particles: int = 1000) -> None:
    rec = record_actions(GapSettings(object="apple", actions=4))
    model = HandModel.from_spec(rec.hand_spec)
    obj = ObjectParams.from_spec(rec.object_spec)
    for name, cfg in (("rolling", ROLL), ("rolling + friction", FRICTION)):
        mm = MotionModel(model, obj, cfg)
        one = _state(model, rec.truths[0])
        mm.solve(one, rec.commands[0], replace(cfg, **SETTLE))
        st = one.take(np.zeros(particles, dtype=int))
        st.theta += np.random.default_rng(0).normal(0, 0.01, st.theta.shape)
        mm.solve(st, rec.commands[0], replace(cfg, **SETTLE))
        for k in range(1, 4):
            t0 = time.perf_counter()
            status, it = mm.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
            print(f"{name}, action {k}: {time.perf_counter() - t0:.2f} s, Newton iterations "
                  f"median {np.median(it):.0f}, failed {int((status != 0).sum())}")


if __name__ == "__main__":
    {"cone": cone, "glued": glued, "cost": cost}[sys.argv[1]]()
