"""Whether the filter's joint lean is the motion model's own drift (docs/RESULTS.md section 5,
session 38).

A one-off diagnostic, not part of the package. The known hand's posterior medians lean the
same way on every seed of an object (the flat screwdriver's: left proximal about -2, left
distal +2, right proximal +1, right distal -2 degrees at 10,000 particles;
`spring_lean.py runs/sweep-...`). Records `vlr gap`'s random actions in the sim at the 0.1 s
move, then carries one particle from the true grasp open loop through them with every term
of the model the filter runs (rolling, the pads' friction, the stops at 17, exact
cylinders, 8 substeps), never refreshed from the truth, and prints each joint's signed
error [deg] (model minus truth) after chosen actions. If the model's own path leans the
joints as the filter's medians do, the lean is the model's; if not, the estimator's.

    MUJOCO_GL=egl python docs/scripts/open_loop_joints.py flat_screwdriver --seeds 0-4 \
        [--actions 20] [--at 5 10 20]
"""

import argparse
from dataclasses import replace

import numpy as np

from sim.gap import _ALL, GapSettings, _start, record_actions
from vlr.errors import UserError
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams
from vlr.sweep import parse_seeds


def joint_path(obj: str, seed: int, actions: int) -> tuple[list[str], np.ndarray]:
    """Joint names and the model's signed joint error [deg] after each action, (actions, J);
    NaN once the particle's solve fails."""
    s = GapSettings(object=obj, seed=seed, actions=actions, ramp_time=0.1, rolling_substeps=8,
                    limit_stiffness=17.0, exact_cylinder=True)
    rec = record_actions(s)
    model = HandModel.from_spec(rec.hand_spec)
    cfg = MotionConfig(terms=_ALL, rolling_substeps=8, limit_stiffness=17.0,
                       exact_cylinder=True, slide_friction=1.0, spin_friction=0.001)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    st = _start(motion, settle, model, rec, 0, "settle")
    names = [f"{f}.{j}" for f in model.names for j in range(model.n_joints)]
    out = np.full((len(rec.commands) - 1, len(names)), np.nan)
    for k in range(1, len(rec.commands)):
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        if not st.valid[0]:
            break
        out[k - 1] = np.degrees(st.theta[0] - rec.truths[k].theta).ravel()
    return names, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("object")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--at", type=int, nargs="+", default=[5, 10, 20])
    args = ap.parse_args()
    try:
        seeds = parse_seeds(args.seeds)
    except UserError as e:
        ap.error(str(e))
    if any(not 1 <= a <= args.actions for a in args.at):
        ap.error(f"--at {args.at}: each must be in [1, --actions {args.actions}]")
    paths = []
    for seed in seeds:
        names, path = joint_path(args.object, seed, args.actions)
        paths.append(path)
        for a in args.at:
            print(f"{args.object} seed {seed} after {a}: " + ", ".join(
                f"{n} {v:+.2f}" for n, v in zip(names, path[a - 1], strict=True)), flush=True)
    mean = np.nanmean(np.array(paths), axis=0)
    for a in args.at:
        print(f"{args.object} mean over seeds after {a}: " + ", ".join(
            f"{n} {v:+.2f}" for n, v in zip(names, mean[a - 1], strict=True)))


if __name__ == "__main__":
    main()
