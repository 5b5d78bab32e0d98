"""Does the filter's own likelihood prefer the truth, in the sim? (issue #5, coverage)

A filter whose intervals end off the truth either lost the truth's neighbourhood (a search
failure: the truth would still score well) or its model prefers other states (model bias:
the truth scores worse than the particles it kept). This runs one `vlr identify` trial in the
sim and carries beside the filter one particle started at the simulator's true grasp (own
path: moved by the filter's motion model with the same commands, never refreshed from the
truth), weighed by the filter's likelihood on the same camera frames and tension readings.
Per iteration it prints that particle's log-likelihood and its rank among the filter's
particles after their motion step (the fraction scoring higher), the running sums of the
planted particle's and of the filter's best particle's log-likelihood, and the planted
particle's and the filter's joint errors. Ground truth starts the planted particle and scores;
the filter never sees it.

    MUJOCO_GL=egl python docs/scripts/planted_sim.py --object wine_glass --seed 1 \
        --particles 10000 --actions 20 [--sigma-tension 0.5] [--anneal-stages N] [--jitter-h H] \
        [--contact-spread-deg DEG] [--contact-prior pad|surface]
"""

from __future__ import annotations

import argparse

import numpy as np

from vlr.identify import identify
from vlr.information import init_motion_config
from vlr.motion import ParticleState
from vlr.trial import TrialSettings, identify_config, open_world

GUESS = {"flat_screwdriver": (-10, 70, -10, 15, -10, 15)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--object", default="wine_glass")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--sigma-tension", type=float, default=0.0)
    ap.add_argument("--anneal-stages", type=int, default=1)
    ap.add_argument("--jitter-h", type=float, default=None)
    ap.add_argument("--contact-spread-deg", type=float, default=None)
    ap.add_argument("--contact-prior", choices=("pad", "surface"), default=None)
    args = ap.parse_args()
    ts = TrialSettings(backend="sim", object=args.object, seed=args.seed,
                       particles=args.particles, max_iterations=args.actions,
                       min_iterations=args.actions, sigma_pos_mm=0.2, sigma_rot_deg=0.4,
                       sigma_turn_deg=1.0, sigma_tension_n=args.sigma_tension,
                       nominal_theta_deg=GUESS.get(args.object, (-10, 15)),
                       prior_spread_deg=10, rolling=True, anneal_stages=args.anneal_stages,
                       jitter_h=args.jitter_h, contact_spread_deg=args.contact_spread_deg,
                       contact_prior=args.contact_prior)
    w = open_world(ts)
    rows: list[str] = []
    planted: dict = {}
    try:
        cfg = identify_config(ts, w.model)
        truths: list = []

        def scorer():
            truths.append(w.truth())
            return truths[-1]

        def watch(pf, rec) -> None:
            if not planted:  # after `initialize`: plant the grasp's truth, then wrap the weights
                st = ParticleState.at_truth(pf.model, truths[0])
                pf.motion.solve(st, pf.command, init_motion_config(pf))
                planted.update(state=st, command=pf.command.copy(), sum=0.0, best=0.0)
                inner = pf._log_likelihood

                def weighed(state, observation):
                    ll = inner(state, observation)
                    p = planted["state"]
                    pf.motion.solve(p, pf.command, u_from=planted["command"])
                    planted["command"] = pf.command.copy()
                    lp = float(inner(p, observation)[0])
                    planted["sum"] += lp
                    planted["best"] += float(ll[np.isfinite(ll)].max())
                    planted["last"] = (lp, float(np.mean(ll > lp)))
                    return ll

                pf._log_likelihood = weighed
                return
            lp, rank = planted["last"]
            t = np.degrees(truths[-1].theta.ravel())
            e_p = np.degrees(planted["state"].theta[0].ravel()) - t
            n = len(t)
            e_f = np.degrees(rec.posterior.mean[:n]) - t
            rows.append(f"{rec.iteration:3d} {lp:8.2f} {rank:6.3f} {planted['sum']:9.1f} "
                        f"{planted['best']:9.1f} | "
                        + " ".join(f"{x:+5.2f}" for x in e_p) + " | "
                        + " ".join(f"{x:+5.2f}" for x in e_f))
            print(rows[-1], flush=True)

        print("iteration | planted log-lik, rank (share of particles above) | running sums: "
              "planted, filter's best | planted particle's joint errors [deg] | filter's")
        identify(w.world, w.observer, w.model, w.obj, w.nominal, cfg, truth=scorer,
                 watch=watch)
    finally:
        w.close()


if __name__ == "__main__":
    main()
