"""Does the filter's model see a grasp-losing action coming? (docs/RESULTS.md section 5,
"Active exploration", the gelatin box's seed 0.)

A one-off probe, not part of the package. On the trial's grasp (the sim, rendered frames,
the filter initialised from the grasp's image as `vlr identify` does), it draws the first
active step's candidate actions (the same stream as `vlr identify --exploration active`),
predicts each on a subset of the particles and prints each contact's predicted normal force
(`MotionModel.normal_forces`: 0 where the pad sphere parts from the object's local sphere)
beside what the sim does with that action from the same grasp (`ApplyReport.grasp_held`,
read only to score the prediction).

    MUJOCO_GL=egl python docs/scripts/grasp_loss_probe.py --object gelatin_box --seed 0
"""

import argparse

import numpy as np

from vlr.explore import ExplorationRange, random_action
from vlr.filter import ParticleFilter
from vlr.surface import surface_normals
from vlr.trial import TrialSettings, identify_config, open_world


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--object", default="gelatin_box")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--particles", type=int, default=3000)
    p.add_argument("--candidates", type=int, default=8)
    p.add_argument("--subset", type=int, default=256)
    args = p.parse_args()
    if args.particles < 10 or args.candidates < 1 or args.subset < 2:
        p.error("need --particles >= 10, --candidates >= 1, --subset >= 2")
    ts = TrialSettings(backend="sim", object=args.object, seed=args.seed,
                       particles=args.particles, max_iterations=1, rolling=True,
                       nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0,
                       sigma_pos_mm=0.35, sigma_rot_deg=0.7)
    world = open_world(ts)
    try:
        cfg = identify_config(ts, world.model)
        pf = ParticleFilter(world.model, world.obj, cfg.filter)
        u = np.asarray(world.world.grasp().commands, float)
        obs = None
        while obs is None:
            obs = world.observer()
        pf.initialize(obs, u, world.nominal.theta, world.nominal.contact)
        rng = np.random.default_rng(args.seed + 1)  # vlr identify's action stream
        explore = ExplorationRange(cfg.action_range[0], cfg.action_range[1],
                                   max(cfg.action_band, cfg.action_range[1]))
        cands = [random_action(rng, u, u, explore) for _ in range(args.candidates)]
        valid = np.flatnonzero(pf.state.valid)
        idx = rng.choice(valid, size=min(args.subset, len(valid)), replace=False)
        base = pf.state.take(idx)
        names = world.model.names
        print(f"{args.object}, seed {args.seed}: predicted normal force per finger [N], "
              "median and 5th percentile over the subset, and the sim's outcome")
        m0 = surface_normals(pf.model, base.theta, base.normals, base.rot)
        f0 = pf.motion.normal_forces(base, pf.motion.rolling_frames(base, m0))
        print("before the action: " + "  ".join(
            f"{n} {a:5.2f}" for n, a in zip(names, np.median(f0, axis=0), strict=True)))
        for k, delta in enumerate(cands):
            st = base.copy()
            pf.motion.solve(st, u + delta, u_from=u)
            ok = st.valid
            m = surface_normals(pf.model, st.theta, st.normals, st.rot)
            f = pf.motion.normal_forces(st, pf.motion.rolling_frames(st, m))[ok]
            med, low = np.median(f, axis=0), np.percentile(f, 5, axis=0)
            outcome = _sim_outcome(ts, delta)
            cols = "  ".join(f"{n} {a:5.2f}/{b:5.2f}" for n, a, b in zip(names, med, low,
                                                                        strict=True))
            print(f"candidate {k} {np.round(delta * 1e3, 2)} mm: {cols}  solved "
                  f"{ok.mean():.2f}  sim: {outcome}")
    finally:
        world.close()


def _sim_outcome(ts: TrialSettings, delta: np.ndarray) -> str:
    """The sim from the same grasp with this one action (scoring only)."""
    from sim.backend import SimHand

    with SimHand(object=ts.object, hand=ts.hand, seed=ts.seed) as hand:
        hand.grasp()
        report = hand.apply(delta)
        return "held" if report.grasp_held else report.message


if __name__ == "__main__":
    main()
