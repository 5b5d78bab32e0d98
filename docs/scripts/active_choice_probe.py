"""How good is active exploration's choice among its candidates? (issue #5 item 4, session 17)

Runs one closed-loop `vlr identify` trial with active exploration (the variance criterion,
`vlr.active`) and, at every choice, scores each of the filter's candidates two ways:

* the filter's own score, the expected joint spread over its particle subset;
* the oracle's: the Cramér-Rao floor of the mean 95% joint interval after that candidate,
  linearised at the simulator's TRUE state along the actions actually taken
  (`vlr.information.InformationTrace.preview`, what `vlr crb --candidates` picks by).

Prints per choice the rank correlation of the two, the oracle's floor after the filter's pick
against the best and the median candidate, and at the end their medians. The truth is read
for the oracle only; the filter chooses exactly as `vlr identify` does (checked: the probe's
pick equals `choose_action`'s).

    MUJOCO_GL=egl python docs/scripts/active_choice_probe.py --object apple --seed 0
"""

from __future__ import annotations

import argparse
import copy
import math
from dataclasses import replace

import numpy as np
from scipy.stats import spearmanr

import vlr.identify as identify_module
from vlr.active import expected_joint_sd
from vlr.explore import random_action
from vlr.filter import ParticleFilter
from vlr.information import InformationTrace, truth_vector
from vlr.observation import grasp_turn
from vlr.trial import TrialSettings, identify_config, identify_trial


def candidate_scores(pf, rng, commands, center, explore, settings):
    """(candidates, filter scores, weakest median normal force) drawn and scored exactly as
    `vlr.active.choose_action` does (same random draws)."""
    from vlr.active import _normal_forces

    cands = [random_action(rng, commands, center, explore) for _ in range(settings.candidates)]
    valid = np.flatnonzero(pf.state.valid)
    idx = rng.choice(valid, size=min(settings.subset, len(valid)), replace=False)
    base = pf.state.take(idx)
    obs = pf.config.observation
    scores, forces = [], []
    for delta in cands:
        st = base.copy()
        pf.motion.solve(st, commands + delta, u_from=commands)
        ok = st.valid
        forces.append(float(np.median(_normal_forces(pf, st)[ok], axis=0).min())
                      if settings.min_normal_force > 0 and ok.any() else math.inf)
        turn = (grasp_turn(st.pos[ok], st.rot[ok], st.anchors[ok], obs.opposed).mean(axis=0)
                if obs.sigma_turn > 0 and ok.any() else None)
        scores.append(-expected_joint_sd(st.theta[ok], st.pos[ok], st.rot[ok], obs.sigma_pos,
                                         obs.sigma_rot, turn, obs.sigma_turn))
    return cands, np.array(scores), np.array(forces)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--object", default="apple")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--actions", type=int, default=15)
    ap.add_argument("--subset", type=int, default=None,
                    help="particles per candidate (default: vlr.active's 256)")
    ap.add_argument("--sigma", type=float, nargs=3, default=(0.2, 0.4, 1.0),
                    metavar=("POS_MM", "ROT_DEG", "TURN_DEG"))
    args = ap.parse_args()
    ts = TrialSettings(backend="sim", object=args.object, seed=args.seed,
                       particles=args.particles, max_iterations=args.actions,
                       sigma_pos_mm=args.sigma[0], sigma_rot_deg=args.sigma[1],
                       sigma_turn_deg=args.sigma[2], nominal_theta_deg=(-10, 15),
                       prior_spread_deg=10, rolling=True, exploration="active",
                       active_criterion="variance", active_min_force_n=0.05)
    sigma = (args.sigma[0] * 1e-3, math.radians(args.sigma[1]), math.radians(args.sigma[2]))
    held: dict = {}
    real_choose = identify_module.choose_action
    rows = []

    def through(w):
        held["world"] = w
        return w.observer

    def probe(pf, rng, commands, center, explore, settings):
        if args.subset:
            settings = replace(settings, subset=args.subset)
        w = held["world"]
        if "trace" not in held:
            cfg = identify_config(ts, w.model)
            twin = ParticleFilter(w.model, w.obj, cfg.filter)
            truth = w.truth()
            held["trace"] = InformationTrace(twin, truth_vector(twin, truth), truth.position,
                                             truth.rotation, commands, 0.02)
            held["u"] = commands.copy()
        trace = held["trace"]
        if not np.allclose(commands, held["u"]):
            trace.act(commands)
            held["u"] = commands.copy()
        cands, scores, forces = candidate_scores(pf, copy.deepcopy(rng), commands, center,
                                                 explore, settings)
        pick = real_choose(pf, rng, commands, center, explore, settings)
        floors = []
        for d in cands:
            b = trace.preview(commands + d, *sigma)
            floors.append(b.mean_width_deg if b is not None else math.nan)
        floors = np.array(floors)
        k = next(i for i, d in enumerate(cands) if np.allclose(d, pick))
        ok = np.isfinite(floors)
        rho = spearmanr(scores[ok], -floors[ok]).statistic if ok.sum() > 2 else math.nan
        now = trace.bound(*sigma[:2], sigma_turn=sigma[2]).mean_width_deg
        rows.append((now, floors[k], np.nanmin(floors), np.nanmedian(floors), rho))
        screened = int((forces < settings.min_normal_force).sum())
        print(f"choice {len(rows):2d}: floor now {now:5.2f}; after the pick {floors[k]:5.2f}, "
              f"best {np.nanmin(floors):5.2f}, median {np.nanmedian(floors):5.2f}; "
              f"rank correlation {rho:+.2f}; screened {screened}",
              flush=True)
        return pick

    identify_module.choose_action = probe
    try:
        summary = identify_trial(ts, observe_through=through).summary
    finally:
        identify_module.choose_action = real_choose
    r = np.array(rows)
    gain = (r[:, 0] - r[:, 1]) / np.maximum(r[:, 0] - r[:, 2], 1e-9)
    gain_median = (r[:, 0] - r[:, 3]) / np.maximum(r[:, 0] - r[:, 2], 1e-9)
    print(f"\n{args.object}, seed {args.seed}, {len(rows)} choices: median rank correlation "
          f"{np.nanmedian(r[:, 4]):+.2f}; the pick's narrowing over the best's, median "
          f"{np.median(gain):.2f} (a median candidate's {np.median(gain_median):.2f}); "
          f"proximal error "
          f"{summary['errors']['proximal_deg_mean']:.2f} "
          f"deg, interval {summary['ci_deg_by_iteration'][-1]:.2f}")


if __name__ == "__main__":
    main()
