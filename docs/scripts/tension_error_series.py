"""How the model's tension error behaves over a trial: noise, or a bias that lasts? (issue #5)

The likelihood's tension term (`vlr.observation`, sigma_tension) treats each reading's error as
independent from one action to the next. If instead the model's error is a bias that lasts
many actions, ten readings do not know ten times what one does, and a filter that multiplies
their likelihoods becomes surer than it should: one way its intervals end under their
Cramér-Rao floor with the truth outside (docs/RESULTS.md 5, "How good a tension sensor").

Per action this records, per finger, the model's equilibrium tension at the simulator's TRUE
state and command against the sim's reading (the static error, what a particle at the truth
would be weighed by), and along the model's own path from the grasp's truth (a particle
carrying its own state), then fits each finger's series with a first-order autoregression
e_t = rho e_{t-1} + w_t: its lag-one correlation rho, its standard deviation and that of its
innovations w. Ground truth is read to measure the model, never given to a filter.

    MUJOCO_GL=egl python docs/scripts/tension_error_series.py --objects apple wine_glass \
        gelatin_box flat_screwdriver --seeds 5 6 7 --actions 30 [--json FILE]
"""

from __future__ import annotations

import argparse

import numpy as np

from vlr.explore import ExplorationRange, random_action
from vlr.filter import ParticleFilter
from vlr.hand import report_commands
from vlr.information import init_motion_config
from vlr.io import write_json_atomic
from vlr.motion import ParticleState
from vlr.trial import TrialSettings, identify_config, open_world

GUESS = {"flat_screwdriver": (-10, 70, -10, 15, -10, 15)}


def series(obj: str, seed: int, actions: int) -> dict[str, list]:
    """The static and own-path tension errors [N], (actions + 1, N) each, and the fingers."""
    ts = TrialSettings(backend="sim", object=obj, seed=seed, particles=10,
                       max_iterations=actions, nominal_theta_deg=GUESS.get(obj, (-10, 15)),
                       prior_spread_deg=10, rolling=True)
    world = open_world(ts)
    try:
        cfg = identify_config(ts, world.model)
        pf = ParticleFilter(world.model, world.obj, cfg.filter)
        hand = world.world
        u = report_commands(hand.grasp())
        rng = np.random.default_rng(seed + 1)   # the trial's own actions (`vlr.identify`)
        explore = ExplorationRange(cfg.action_range[0], cfg.action_range[1],
                                   max(cfg.action_band, cfg.action_range[1]))
        center = u.copy()
        path = ParticleState.at_truth(pf.model, world.truth())
        pf.motion.solve(path, u, init_motion_config(pf))
        static, own = [], []
        for k in range(actions + 1):
            if k:
                report = hand.apply(random_action(rng, u, center, explore))
                if not getattr(report, "grasp_held", True):
                    break
                u_new = report_commands(report)
                pf.motion.solve(path, u_new, u_from=u)
                u = u_new
            sim_t = hand.static_tensions()
            at = ParticleState.at_truth(pf.model, world.truth())
            pf.motion.solve(at, u, init_motion_config(pf))
            static.append((pf.motion.tensions(at, u)[0] - sim_t).tolist())
            own.append((pf.motion.tensions(path, u)[0] - sim_t).tolist())
        return {"static": static, "own": own, "fingers": list(pf.model.names)}
    finally:
        world.close()


def ar1(e: np.ndarray) -> dict[str, float]:
    """Lag-one fit of a series (T,): rho, the series' SD, the innovations' SD."""
    e = np.asarray(e, dtype=float)
    a, b = e[1:], e[:-1]
    rho = float((a * b).sum() / max((b * b).sum(), 1e-300))
    return {"rho": rho, "sd": float(np.sqrt((e * e).mean())),
            "innovation_sd": float(np.sqrt(((a - rho * b) ** 2).mean()))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--objects", nargs="+", default=["apple"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[5])
    ap.add_argument("--actions", type=int, default=30)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    out = {}
    print("object seed kind finger: rho, RMS [N], innovation SD [N]")
    for obj in args.objects:
        for seed in args.seeds:
            s = series(obj, seed, args.actions)
            out[f"{obj}/{seed}"] = s
            for kind in ("static", "own"):
                e = np.array(s[kind])
                for i, f in enumerate(s["fingers"]):
                    r = ar1(e[:, i])
                    print(f"{obj} {seed} {kind:6s} {f:5s}: {r['rho']:+.2f} {r['sd']:.3f} "
                          f"{r['innovation_sd']:.3f}", flush=True)
    for kind in ("static", "own"):
        for i, f in enumerate(next(iter(out.values()))["fingers"]):
            fits = [ar1(np.array(s[kind])[:, i]) for s in out.values()]
            print(f"pooled {kind:6s} {f:5s}: rho median {np.median([x['rho'] for x in fits]):+.2f}"
                  f", RMS median {np.median([x['sd'] for x in fits]):.3f} N, innovation SD "
                  f"median {np.median([x['innovation_sd'] for x in fits]):.3f} N")
    if args.json:
        write_json_atomic(args.json, out)


if __name__ == "__main__":
    main()
