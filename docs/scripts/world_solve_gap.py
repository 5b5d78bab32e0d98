"""The synthetic world's own model-world gap: a filter particle started at the world's truth
against the world's next state, action by action (docs/RESULTS.md section 5, session 42).

A one-off diagnostic, not part of the package. The synthetic world is meant to have no gap
(its truth is a motion-model state). It has one wherever the world solves an action other
than the way a particle does (`vlr.synthetic.SyntheticConfig.solve`): this prints, for each
random action, the particle's solve status and Newton iterations and its POM position [mm]
and orientation [deg] error against the world, next to the world's own motion.

    python docs/scripts/world_solve_gap.py --seed 0 --grasp-deg -10 15 --solve loose
"""

import argparse

import numpy as np

from vlr.errors import UserError
from vlr.kinematics import HandModel
from vlr.motion import MotionModel, ObjectParams
from vlr.observation import rotation_angle
from vlr.spec import SpecError, load_hand, load_object
from vlr.synthetic import WORLD_SOLVES, SyntheticConfig, SyntheticWorld, random_action
from vlr.trial import TrialSettings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--object", default="toy_block")
    ap.add_argument("--hand", default="modelo_thumb45")
    ap.add_argument("--grasp-deg", type=float, nargs="+", default=None,
                    help="the world's grasp guess [deg] (default: the generic one)")
    ap.add_argument("--solve", choices=WORLD_SOLVES, default="model")
    ap.add_argument("--actions", type=int, default=40)
    ap.add_argument("--action-seed", type=int, default=100)
    args = ap.parse_args()
    motion = TrialSettings(backend="synthetic", rolling=True, limit_stiffness=17.0,
                           object=args.object).motion_config()
    extra = {} if args.grasp_deg is None else {
        "grasp_theta": tuple(np.radians(args.grasp_deg))}
    world = SyntheticWorld(HandModel.from_spec(load_hand(args.hand)),
                           ObjectParams.from_spec(load_object(args.object)),
                           SyntheticConfig(seed=args.seed, motion=motion, solve=args.solve,
                                           **extra))
    model = MotionModel(world.model, world.motion.obj, motion)
    world.grasp()
    rng = np.random.default_rng(args.action_seed)
    gaps = []
    for t in range(1, args.actions + 1):
        particle, u, before = world.state.copy(), world.commands, world.state.copy()
        delta = random_action(rng, world.model.n_fingers)
        status, iters = model.solve(particle, u + delta, u_from=u)
        world.apply(delta)
        truth = world.state
        gap_mm = float(np.linalg.norm(particle.pos[0] - truth.pos[0]) * 1e3)
        gap_deg = float(np.degrees(rotation_angle(particle.rot, truth.rot)[0]))
        move_mm = float(np.linalg.norm(truth.pos[0] - before.pos[0]) * 1e3)
        move_deg = float(np.degrees(rotation_angle(before.rot, truth.rot)[0]))
        gaps.append(gap_mm)
        print(f"action {t:2d}  status {status[0]}  iterations {iters[0]:4d}  gap {gap_mm:.4f} mm "
              f"{gap_deg:.4f} deg  motion {move_mm:.3f} mm {move_deg:.3f} deg")
    g = np.array(gaps)
    print(f"{args.solve}: {int((g > 0.1).sum())} of {len(g)} actions over 0.1 mm, "
          f"largest {g.max():.3f} mm")


if __name__ == "__main__":
    try:
        main()
    except (UserError, SpecError, ValueError) as exc:  # a bad hand, object or grasp guess
        raise SystemExit(f"error: {exc}") from None
