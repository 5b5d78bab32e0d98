"""Could a filter make the oracle's choice? (issue #5 item 4, session 17)

`vlr crb --candidates` picks each action by the Cramér-Rao floor linearised at the
simulator's TRUE state. A filter knows that state only to within its posterior. This probe
linearises the same floor at the truth and at a nearby state (the truth's sampled dimensions
moved by `--offset` of each one's prior spread, a random direction per trial), follows the
seed's random actions, and at each action ranks the same random candidates by both: the rank
correlation says how much of the oracle's choice survives a linearisation point off the truth
by that much.

    MUJOCO_GL=egl python docs/scripts/oracle_sensitivity.py --object apple --seed 0 --offset 0.1
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.stats import spearmanr

from vlr.explore import ExplorationRange, random_action
from vlr.filter import ParticleFilter
from vlr.hand import report_commands
from vlr.information import InformationTrace, prior_std, truth_vector
from vlr.trial import TrialSettings, identify_config, open_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--object", default="apple")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--actions", type=int, default=15)
    ap.add_argument("--candidates", type=int, default=8)
    ap.add_argument("--offset", type=float, default=0.1,
                    help="the nearby state's offset, in prior spreads (0.1: 1 degree)")
    ap.add_argument("--sigma", type=float, nargs=3, default=(0.2, 0.4, 1.0),
                    metavar=("POS_MM", "ROT_DEG", "TURN_DEG"))
    args = ap.parse_args()
    ts = TrialSettings(backend="sim", object=args.object, seed=args.seed, particles=1000,
                       max_iterations=args.actions, sigma_pos_mm=args.sigma[0],
                       sigma_rot_deg=args.sigma[1], sigma_turn_deg=args.sigma[2],
                       nominal_theta_deg=(-10, 15), prior_spread_deg=10, rolling=True)
    sigma = (args.sigma[0] * 1e-3, math.radians(args.sigma[1]), math.radians(args.sigma[2]))
    world = open_world(ts)
    try:
        cfg = identify_config(ts, world.model)
        pfs = [ParticleFilter(world.model, world.obj, cfg.filter) for _ in range(2)]
        u = report_commands(world.world.grasp())
        truth = world.truth()
        x = truth_vector(pfs[0], truth)
        rng = np.random.default_rng(ts.seed + 1)
        off = np.random.default_rng(1000 + ts.seed).standard_normal(x.size)
        off *= args.offset * prior_std(pfs[1]) / np.sqrt((off ** 2).mean())
        traces = [InformationTrace(pfs[0], x, truth.position, truth.rotation, u),
                  InformationTrace(pfs[1], x + off, truth.position, truth.rotation, u)]
        explore = ExplorationRange(cfg.action_range[0], cfg.action_range[1],
                                   max(cfg.action_band, cfg.action_range[1]))
        center = u.copy()
        rhos, agree = [], 0
        for k in range(1, args.actions + 1):
            cands = [random_action(rng, u, center, explore) for _ in range(args.candidates)]
            w = np.array([[b.mean_width_deg if b is not None else np.nan
                           for b in (t.preview(u + d, *sigma) for d in cands)]
                          for t in traces])
            ok = np.isfinite(w).all(axis=0)
            rho = spearmanr(w[0, ok], w[1, ok]).statistic if ok.sum() > 2 else math.nan
            same = int(np.nanargmin(w[0]) == np.nanargmin(w[1]))
            rhos.append(rho)
            agree += same
            now = traces[0].bound(*sigma[:2], sigma_turn=sigma[2]).mean_width_deg
            print(f"action {k:2d}: floor at the truth {now:5.2f}; "
                  f"rank correlation {rho:+.2f}; same best {bool(same)}", flush=True)
            report = world.world.apply(random_action(rng, u, center, explore))
            if not getattr(report, "grasp_held", True):
                print("grasp lost")
                break
            u = report_commands(report)
            for t in traces:
                t.act(u)
    finally:
        world.close()
    print(f"\n{args.object}, seed {args.seed}, offset {args.offset}: median rank correlation "
          f"{np.nanmedian(rhos):+.2f}; the same best candidate in {agree} of {len(rhos)}")


if __name__ == "__main__":
    main()
