"""Would a tendon-tension reading make convergence in 15 actions possible? (issue #5,
session 17)

The filter observes the POM pose only (the paper's camera). A Dynamixel reports its present
current, so the real hand could also read each tendon's tension; the sim has it
(`SimHand.static_tensions`, the series spring's k_t x stretch, what a current reading
settles to) and the filter's model predicts it (`MotionModel.tensions`, Eq. 7 compliant).
This probe bounds the filter with tension observations of scale sigma_T [N] added to the
pose's (`vlr.information.InformationTrace.bound(..., sigma_tension=)`, the same central
differences, of the tensions) along the seed's random actions, and prints the floor of the
mean 95% joint interval after each budget at the pose likelihood alone and with tensions at
several sigma_T. Beside it, the model's tension error against the sim's from the true state,
per action (the same restart from the truth as `vlr gap`'s per-action measure, glued
contacts re-settled): the floor only holds for a sigma_T above that. And the static gap: the
model's equilibrium tension at the true state against the sim's, whose mean a filter would
see as a bias; and the tension error along the model's own path from the grasp's truth (a
particle carries its own state).

    MUJOCO_GL=egl python docs/scripts/tension_floor.py --object apple --seed 0
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from vlr.explore import ExplorationRange, random_action
from vlr.filter import ParticleFilter
from vlr.hand import report_commands
from vlr.information import InformationTrace, init_motion_config, truth_vector
from vlr.motion import ParticleState
from vlr.trial import TrialSettings, identify_config, open_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--object", default="apple")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--actions", type=int, default=15)
    ap.add_argument("--sigma-t", type=float, nargs="+", default=(0.1, 0.3, 1.0),
                    metavar="N", help="tension scales [N]")
    ap.add_argument("--sigma", type=float, nargs=3, default=(0.2, 0.4, 1.0),
                    metavar=("POS_MM", "ROT_DEG", "TURN_DEG"))
    args = ap.parse_args()
    nominal = (-10, 70, -10, 15, -10, 15) if args.object == "flat_screwdriver" else (-10, 15)
    ts = TrialSettings(backend="sim", object=args.object, seed=args.seed, particles=1000,
                       max_iterations=args.actions, sigma_pos_mm=args.sigma[0],
                       sigma_rot_deg=args.sigma[1], sigma_turn_deg=args.sigma[2],
                       nominal_theta_deg=nominal, prior_spread_deg=10, rolling=True)
    sigma = (args.sigma[0] * 1e-3, math.radians(args.sigma[1]), math.radians(args.sigma[2]))
    world = open_world(ts)
    try:
        cfg = identify_config(ts, world.model)
        pf = ParticleFilter(world.model, world.obj, cfg.filter)
        hand = world.world
        u = report_commands(hand.grasp())
        truth = world.truth()
        trace = InformationTrace(pf, truth_vector(pf, truth), truth.position, truth.rotation,
                                 u)

        def floor(sigma_t: float) -> float:
            """The mean 95% joint interval's floor [deg] now, tensions at sigma_t [N]."""
            return trace.bound(*sigma[:2], sigma_turn=sigma[2],
                               sigma_tension=sigma_t).mean_width_deg
        rng = np.random.default_rng(ts.seed + 1)
        explore = ExplorationRange(cfg.action_range[0], cfg.action_range[1],
                                   max(cfg.action_band, cfg.action_range[1]))
        center = u.copy()
        gap, change, static, own = [], [], [], []
        # The model carrying its own state from the grasp's truth (as a particle does).
        path = ParticleState.at_truth(pf.model, truth)
        pf.motion.solve(path, u, init_motion_config(pf))
        print(f"{args.object}, seed {args.seed}: floor of the mean 95% joint interval [deg]; "
              f"pose at {args.sigma[0]} mm / {args.sigma[1]} deg + {args.sigma[2]} deg turn")
        print(f"{'actions':>7s} {'pose only':>10s}"
              + "".join(f" {'+ T ' + format(s, 'g') + ' N':>10s}" for s in args.sigma_t))
        for k in range(1, args.actions + 1):
            # The model's tension change over this action from the true state, against the
            # sim's (the restart of `vlr gap`'s per-action measure).
            t_before = hand.static_tensions()
            st = ParticleState.at_truth(pf.model, world.truth())
            pf.motion.solve(st, u, init_motion_config(pf))
            m_before = pf.motion.tensions(st, u)[0]
            static.append(m_before - t_before)
            delta = random_action(rng, u, center, explore)
            report = hand.apply(delta)
            if not getattr(report, "grasp_held", True):
                print(f"grasp lost at action {k}")
                break
            u_new = report_commands(report)
            pf.motion.solve(st, u_new, u_from=u)
            t_after = hand.static_tensions()
            gap.append((pf.motion.tensions(st, u_new)[0] - m_before) - (t_after - t_before))
            pf.motion.solve(path, u_new, u_from=u)
            own.append(pf.motion.tensions(path, u_new)[0] - t_after)
            change.append(t_after - t_before)
            u = u_new
            trace.act(u)
            print(f"{k:7d} {floor(0.0):10.2f}"
                  + "".join(f" {floor(s):10.2f}" for s in args.sigma_t),
                  flush=True)
    finally:
        world.close()
    g, c, z = np.array(gap), np.array(change), np.array(static)
    print(f"tension change per action, sim: RMS {np.sqrt((c ** 2).mean()):.3f} N; the "
          f"model's error on it: RMS {np.sqrt((g ** 2).mean()):.3f} N "
          f"(per finger {np.round(np.sqrt((g ** 2).mean(axis=0)), 3)}); the model's static "
          f"tension at the true state against the sim's: mean {np.round(z.mean(axis=0), 3)}, "
          f"SD {np.round(z.std(axis=0), 3)} N per finger; along the model's own path from "
          f"the grasp: RMS {np.round(np.sqrt((np.array(own) ** 2).mean(axis=0)), 3)} N")


if __name__ == "__main__":
    main()
