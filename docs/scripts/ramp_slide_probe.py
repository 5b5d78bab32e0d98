"""One action at several command speeds: where a finger's contact goes on the object, in the
sim and in the motion model (docs/RESULTS.md section 5, session 30: the gelatin box's seed-2
action 3, the open-loop drift's one miss).

A one-off diagnostic, not part of the package. Records `vlr gap`'s random actions on OBJECT
(seed SEED) up to action K with the sim ramping each command change over each RAMP [s]
(`sim.backend.SimOptions.ramp_time`). For action K prints, per ramp: FINGER's contact point
on the object before and after [mm, object frame O: z from the tag into the object], its
normal force and its tangential force's size [N] after, FINGER's joint angles after [deg],
and the object's rotation vector over the action [deg, palm frame]; then the motion model's
prediction of the same action (the friction rung, with session 27's terms: 8 substeps, stops
at 17 N m/rad, exact cylinders) from the truth settled with glued contacts, as `vlr gap`
does. Sim ground truth: this is scoring, never the estimator.

    MUJOCO_GL=egl python docs/scripts/ramp_slide_probe.py gelatin_box 2 3 left \\
        --ramp-time 0.05 0.1 0.5
"""

import argparse
from dataclasses import replace

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from sim.backend import SimHand, SimOptions
from sim.gap import _ALL, GapSettings, _start, record_actions
from sim.pads import SLIDE_FRICTION, TORSION_FRICTION
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel, contact_points
from vlr.motion import MotionConfig, MotionModel, ObjectParams


def _contact(hand: SimHand, slot: str) -> tuple[np.ndarray, float, float]:
    """`slot`'s force-weighted contact point on the object in O [m], and its total normal
    and tangential force [N]."""
    m, d = hand.model, hand.data
    ob = hand._obj_body
    xo, ro = d.xpos[ob], d.xmat[ob].reshape(3, 3)
    pts, fn, ft, f6 = [], 0.0, np.zeros(2), np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if ob not in (b1, b2):
            continue
        if not m.geom(c.geom2 if b1 == ob else c.geom1).name.startswith(slot + "/"):
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        pts.append((ro.T @ (c.pos - xo), f6[0]))
        fn += f6[0]
        ft += f6[1:3]
    if not pts:
        return np.full(3, np.nan), 0.0, 0.0
    w = np.array([f for _, f in pts])
    w = w / w.sum() if w.sum() > 0 else np.full(len(pts), 1 / len(pts))
    return sum(wi * p for wi, (p, _) in zip(w, pts, strict=True)), fn, float(np.linalg.norm(ft))


def _rotvec_deg(r: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(r).as_rotvec() * 180 / np.pi


def _sim(obj: str, seed: int, k: int, slot: str, ramp: float) -> None:
    s = GapSettings(object=obj, seed=seed)
    with SimHand(object=obj, seed=seed, options=SimOptions(ramp_time=ramp)) as hand:
        u = hand.grasp().commands
        rng = np.random.default_rng(seed + 1)               # vlr gap's action stream
        explore = ExplorationRange(s.action_range[0], s.action_range[1],
                                   max(s.band, s.action_range[1]))
        center = u.copy()
        for j in range(1, k + 1):
            if j == k:
                p0, r0 = _contact(hand, slot)[0], hand.scoring_truth().rotation
            u = hand.apply(random_action(rng, u, center, explore)).commands
        p1, fn, ft = _contact(hand, slot)
        t = hand.scoring_truth()
        q = np.degrees(t.theta[hand.slots.index(slot)])
        print(f"sim, ramp {ramp:g} s: {slot} on the object {np.round(p0 * 1e3, 2)} -> "
              f"{np.round(p1 * 1e3, 2)} mm, normal {fn:.2f} N, tangential {ft:.2f} N; "
              f"joints {np.round(q, 2)} deg; object turns "
              f"{np.round(_rotvec_deg(t.rotation @ r0.T), 2)} deg")


def _model(obj: str, seed: int, k: int, slot: str, ramp: float) -> None:
    rec = record_actions(GapSettings(object=obj, seed=seed, actions=k, ramp_time=ramp))
    model = HandModel.from_spec(rec.hand_spec)
    cfg = MotionConfig(terms=_ALL, rolling_substeps=8, limit_stiffness=17.0,
                       exact_cylinder=True, slide_friction=SLIDE_FRICTION,
                       spin_friction=TORSION_FRICTION)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    st = _start(motion, settle, model, rec, k - 1, "settle")
    i = model.names.index(slot)
    p0, r0 = st.anchors[0, i].copy(), st.rot[0].copy()
    motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
    c = contact_points(model, st.theta, st.normals, st.segments)[0, i]
    p1 = st.rot[0].T @ (c - st.pos[0])
    print(f"model, from the truth at ramp {ramp:g} s: {slot} on the object "
          f"{np.round(p0 * 1e3, 2)} -> {np.round(p1 * 1e3, 2)} mm; joints "
          f"{np.round(np.degrees(st.theta[0, i]), 2)} deg; object turns "
          f"{np.round(_rotvec_deg(st.rot[0] @ r0.T), 2)} deg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("object")
    ap.add_argument("seed", type=int)
    ap.add_argument("action", type=int, help="the action to look at (1: the first)")
    ap.add_argument("finger", help="the finger whose contact to follow (thumb, left, right)")
    ap.add_argument("--ramp-time", type=float, nargs="+", default=[0.05, 0.1])
    args = ap.parse_args()
    if args.action < 1:
        ap.error(f"action {args.action}: the first action is 1")
    if args.finger not in ("thumb", "left", "right"):
        ap.error(f"finger {args.finger!r}: expected thumb, left or right")
    bad = [r for r in args.ramp_time if not 0 < r <= 2]
    if bad:
        ap.error(f"--ramp-time {bad}: a ramp [s] must be in (0, 2]")
    for ramp in args.ramp_time:
        _sim(args.object, args.seed, args.action, args.finger, ramp)
        _model(args.object, args.seed, args.action, args.finger, ramp)


if __name__ == "__main__":
    main()
