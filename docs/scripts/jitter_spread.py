"""Does the filter's jitter keep the posterior's spread? (issue #5, coverage)

The Liu-West kernel (`ParticleFilter._kernel`) is built to keep the particle covariance: it
shrinks towards the mean by sqrt(1 - h^2) and adds h^2 of the covariance back. But each
jittered particle is then settled to equilibrium at the current command and re-anchored
(`ParticleFilter._project`), and the settle may take back part of what the kernel added. If
it does, every iteration narrows the joint angles' intervals by more than the observations
say, which is one way a filter's intervals end under their Cramér-Rao floor.

For each iteration this prints, per joint angle averaged: the 95% interval after resampling
(the posterior), after the jitter and settle, and after the next action's motion step (the
next prior). Ground truth is not used.

    MUJOCO_GL=egl python docs/scripts/jitter_spread.py --object gelatin_box --seed 0 \
        --particles 10000 --actions 12 [--sigma-tension 0.5] [--jitter-h 0.4]
"""

from __future__ import annotations

import argparse

import numpy as np

from vlr.trial import TrialSettings, identify_trial


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--object", default="gelatin_box")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--actions", type=int, default=12)
    ap.add_argument("--sigma-tension", type=float, default=0.0)
    ap.add_argument("--jitter-h", type=float, default=None)
    args = ap.parse_args()
    settings = TrialSettings(backend="sim", object=args.object, seed=args.seed,
                             particles=args.particles, max_iterations=args.actions,
                             sigma_tension_n=args.sigma_tension, jitter_h=args.jitter_h,
                             min_iterations=args.actions)
    rows: list[dict] = []

    def width(x: np.ndarray) -> np.ndarray:
        q = np.quantile(x, [0.025, 0.975], axis=0)
        return np.degrees(q[1] - q[0])

    def watch(pf, rec) -> None:
        n_th = pf.model.n_fingers * pf.model.n_joints
        post = rec.posterior or rec.prior
        x = pf.pack(pf.state)[:, :n_th]
        rows.append({"it": rec.iteration,
                     "prior": np.degrees(rec.prior.high[:n_th] - rec.prior.low[:n_th]),
                     "post": np.degrees(post.high[:n_th] - post.low[:n_th]),
                     "jittered": width(x), "ess": rec.ess, "beta": rec.beta})

    run = identify_trial(settings, watch=watch)
    print(f"{args.object} seed {args.seed}, {args.particles} particles, tension "
          f"{args.sigma_tension} N, h {args.jitter_h or 'default'}")
    print("iteration | ESS | beta | mean 95% width [deg]: prior, posterior, after jitter+settle"
          " | jittered / posterior | next prior / jittered")
    for r, nxt in zip(rows, [*rows[1:], None], strict=True):
        nx = "" if nxt is None else f"{nxt['prior'].mean() / r['jittered'].mean():.2f}"
        print(f"{r['it']:3d} | {r['ess']:8.0f} | {r['beta']:.3f} | {r['prior'].mean():6.2f} "
              f"{r['post'].mean():6.2f} {r['jittered'].mean():6.2f} | "
              f"{r['jittered'].mean() / r['post'].mean():.2f} | {nx}")
    s = run.summary
    print("final: converged", s.get("converged"), "coverage", s.get("coverage"),
          "proximal error", s.get("errors", {}).get("proximal_deg_mean"))


if __name__ == "__main__":
    main()
