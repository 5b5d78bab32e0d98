"""Where the rolling model's per-action error points: the principal direction of the 6x6
covariance of its pose errors (position [mm], rotation vector [deg]) over `vlr gap`'s
actions, its share of the variance, and the angle between its rotation axis and the grasp's
turn axis (thumb to the other contacts, `vlr.observation.grasp_turn`). docs/RESULTS.md 5,
"The turn, measured and given its own scale". A one-off diagnostic that reads the sim's
truth; not part of the package.

    MUJOCO_GL=egl python docs/scripts/turn_axis.py [OBJECT ...] [--seed S] [--actions N]
        [--slide-friction MU] [--spin-friction MU_T] [--spin-stiffness K]
"""

import argparse
import math
from dataclasses import replace

import numpy as np

from sim.gap import _ALL, GapSettings, _pose, _state, record_actions
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams
from vlr.observation import grasp_turn, rotation_error


def principal_direction(obj: str, seed: int, actions: int) -> dict:
    rec = record_actions(GapSettings(object=obj, seed=seed, actions=actions))
    model = HandModel.from_spec(rec.hand_spec)
    cfg = MotionConfig(terms=_ALL)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    thumb = model.finger_index("thumb")
    errors, axes = [], []
    for k in range(len(rec.commands) - 1):
        t0, t1 = rec.truths[k], rec.truths[k + 1]
        st = _state(model, t0)
        motion.solve(st, rec.commands[k], settle)
        p0, r0 = _pose(st)
        axes.append(grasp_turn(st.pos, st.rot, st.anchors, thumb)[0, 3:])
        motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        if not st.valid[0]:
            continue
        p1, r1 = _pose(st)
        e_p = (p1 - p0) - (t1.position - t0.position)
        e_r = rotation_error((r1 @ r0.T) @ (t1.rotation @ t0.rotation.T).T, np.eye(3))
        errors.append(np.concatenate([e_p * 1e3, np.degrees(e_r)]))
    ev, vec = np.linalg.eigh(np.cov(np.array(errors).T))
    w = vec[3:, -1] / np.linalg.norm(vec[3:, -1])
    a = np.mean(axes, axis=0)
    a /= np.linalg.norm(a)
    return {"object": obj, "share": float(ev[-1] / ev.sum()),
            "axis": w, "angle_to_thumb_axis_deg": math.degrees(math.acos(min(1.0, abs(w @ a))))}


def own_path_split(obj: str, seed: int, actions: int, **motion: float) -> np.ndarray:
    """RMS over the actions of the open-loop model's absolute pose error against the sim:
    position [mm], orientation [deg], its turn [deg], the rest's position [mm] and
    orientation [deg]. `motion`: `MotionConfig` settings over the rolling model's (the pads'
    friction, their spin stiffness)."""
    rec = record_actions(GapSettings(object=obj, seed=seed, actions=actions))
    model = HandModel.from_spec(rec.hand_spec)
    cfg = replace(MotionConfig(terms=_ALL), **motion)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    thumb = model.finger_index("thumb")
    st = _state(model, rec.truths[0])
    motion.solve(st, rec.commands[0], replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200))
    rows = []
    for k in range(1, len(rec.commands)):
        v = grasp_turn(st.pos, st.rot, st.anchors, thumb)[0]
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        if not st.valid[0]:
            break
        p, r = _pose(st)
        e_p = p - rec.truths[k].position
        e_r = rotation_error(r, rec.truths[k].rotation)
        turn = float(e_r @ v[3:])
        rows.append([np.linalg.norm(e_p) * 1e3, math.degrees(np.linalg.norm(e_r)),
                     math.degrees(turn), np.linalg.norm(e_p - turn * v[:3]) * 1e3,
                     math.degrees(np.linalg.norm(e_r - turn * v[3:]))])
    return np.sqrt(np.mean(np.square(rows), axis=0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("objects", nargs="*", default=["apple", "wine_glass", "toy_block",
                                                   "flat_screwdriver", "gelatin_box"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--actions", type=int, default=30)
    ap.add_argument("--slide-friction", type=float, default=None,
                    help="the own path again with this sliding friction (inf: none slides)")
    ap.add_argument("--spin-friction", type=float, default=0.0,
                    help="... and this torsional friction [m] (the sim's: 0.001)")
    ap.add_argument("--spin-stiffness", type=float, default=0.0,
                    help="... or an elastic spin [N m/rad]")
    args = ap.parse_args()
    motion = {k: v for k, v in (("slide_friction", args.slide_friction),
                                ("spin_friction", args.spin_friction),
                                ("spin_stiffness", args.spin_stiffness)) if v}
    for obj in args.objects:
        r = principal_direction(obj, args.seed, args.actions)
        print(f"{obj:18s} share of the error variance {r['share']:.3f}, rotation axis "
              f"{np.round(r['axis'], 3)}, {r['angle_to_thumb_axis_deg']:.1f} deg from the "
              "thumb's axis")
        e = own_path_split(obj, args.seed, args.actions)
        print(f"{'':18s} own path: error {e[0]:.3f} mm / {e[1]:.3f} deg, its turn {e[2]:.3f} "
              f"deg, the rest {e[3]:.3f} mm / {e[4]:.3f} deg (RMS)")
        if motion:
            e = own_path_split(obj, args.seed, args.actions, **motion)
            print(f"{'':18s} with {motion}: error {e[0]:.3f} mm / {e[1]:.3f} deg, its turn "
                  f"{e[2]:.3f} deg, the rest {e[3]:.3f} mm / {e[4]:.3f} deg (RMS)")


if __name__ == "__main__":
    main()
